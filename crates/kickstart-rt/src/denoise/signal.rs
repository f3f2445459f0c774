//! The signals a denoising context filters: their kinds (`DN_KIND_*` of the shaders) and the
//! signal set every pass is compiled for (constant signal loops, folded kind switches, the
//! record layout: 16 bytes for radiance, 8 for occlusion and shadows).

use crate::tasks::SignalType;

const RECORD_RGBA_WGSL: &str = include_str!("../../shaders/denoise_record_rgba.wgsl");
const RECORD_SCALAR_WGSL: &str = include_str!("../../shaders/denoise_record_scalar.wgsl");

/// Signal kinds of the shaders (`DN_KIND_*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) enum Kind {
    Specular = 0,
    Diffuse = 1,
    Occlusion = 2,
    Shadow = 3,
    MultiShadow = 4,
}

impl Kind {
    /// One value per pixel (stored in the 8-byte scalar record).
    fn scalar(self) -> bool {
        matches!(self, Kind::Occlusion | Kind::Shadow | Kind::MultiShadow)
    }
}

/// The signals a context filters together; every pass is compiled per signal set (constant loop
/// bounds, folded kind switches, the record layout).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) struct SignalSet {
    kinds: [Kind; 2],
    count: usize,
}

impl SignalSet {
    pub fn of(signal_type: SignalType) -> Self {
        let one = |k| SignalSet {
            kinds: [k, k],
            count: 1,
        };
        match signal_type {
            SignalType::Specular => one(Kind::Specular),
            SignalType::Diffuse => one(Kind::Diffuse),
            SignalType::SpecularAndDiffuse => SignalSet {
                kinds: [Kind::Specular, Kind::Diffuse],
                count: 2,
            },
            SignalType::DiffuseOcclusion => one(Kind::Occlusion),
            SignalType::Shadow => one(Kind::Shadow),
            SignalType::MultiShadow => one(Kind::MultiShadow),
        }
    }

    fn scalar(self) -> bool {
        self.kinds[..self.count].iter().all(|k| k.scalar())
    }

    /// The à-trous passes of this set: one chain per signal, each with a single-signal set.
    /// SpecularAndDiffuse filters its signals in separate dispatches: measured on an H100, one
    /// dispatch for both (18 live values per signal across the taps) ran 0.39 ms per iteration
    /// at 1080p, two single-signal dispatches 2 × 0.14 ms, although they read the guide twice.
    pub fn atrous_chains(self) -> Vec<(usize, SignalSet)> {
        (0..self.count)
            .map(|s| {
                (
                    s,
                    SignalSet {
                        kinds: [self.kinds[s]; 2],
                        count: 1,
                    },
                )
            })
            .collect()
    }

    /// The WGSL in front of a pass of this set: constants, the record layout and (`outputs`:
    /// the last à-trous iteration) the output textures of group 2.
    pub fn prelude(self, outputs: Option<&[wgpu::TextureFormat]>) -> String {
        let mut s = format!(
            "const DN_SIGNALS: u32 = {}u;\nconst DN_KIND0: u32 = {}u;\nconst DN_KIND1: u32 = {}u;\n",
            self.count, self.kinds[0] as u32, self.kinds[1] as u32
        );
        s += if self.scalar() {
            RECORD_SCALAR_WGSL
        } else {
            RECORD_RGBA_WGSL
        };
        match outputs {
            None => {
                s += "\nconst DN_LAST: bool = false;\n\
                      fn dn_write_output(s: u32, texel: vec2<u32>, v: vec4<f32>) {}\n";
            }
            Some(formats) => {
                s += "\nconst DN_LAST: bool = true;\n";
                for (k, f) in formats.iter().enumerate() {
                    let name = wgsl_format(*f).unwrap_or("rgba16float");
                    s += &format!(
                        "@group(2) @binding({k}) var dn_out{k}: texture_storage_2d<{name}, write>;\n"
                    );
                }
                // Radiance: rgb and the filtered hit distance; occlusion and shadows: the value
                // in every channel.
                s += "fn dn_write_output(s: u32, texel: vec2<u32>, v: vec4<f32>) {\n\
                      var out = v;\n\
                      if dn_kind(s) != DN_KIND_SPECULAR && dn_kind(s) != DN_KIND_DIFFUSE {\n\
                      out = vec4<f32>(v.x);\n\
                      }\n\
                      if s == 0u {\n\
                      textureStore(dn_out0, texel, out);\n\
                      }\n";
                if formats.len() > 1 {
                    s += "if s == 1u {\ntextureStore(dn_out1, texel, out);\n}\n";
                }
                s += "}\n";
            }
        }
        s
    }
}

/// The WGSL name of a writable output format, `None` for the others.
pub(super) fn wgsl_format(format: wgpu::TextureFormat) -> Option<&'static str> {
    match format {
        wgpu::TextureFormat::Rgba16Float => Some("rgba16float"),
        wgpu::TextureFormat::Rgba32Float => Some("rgba32float"),
        wgpu::TextureFormat::R32Float => Some("r32float"),
        wgpu::TextureFormat::Rg32Float => Some("rg32float"),
        _ => None,
    }
}
