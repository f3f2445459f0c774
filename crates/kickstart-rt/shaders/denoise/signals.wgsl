// The signal set a denoise pass is compiled for (see denoise/common.wgsl): how many signals and
// of which kinds (DN_KIND_* values), as constants.

#param DN_SIGNALS
#param DN_KIND0
#param DN_KIND1

const DN_SIGNALS: u32 = {{DN_SIGNALS}}u;
const DN_KIND0: u32 = {{DN_KIND0}}u;
const DN_KIND1: u32 = {{DN_KIND1}}u;
