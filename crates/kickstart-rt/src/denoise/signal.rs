//! The signals a denoising context filters: their kinds (`DN_KIND_*` of the shaders) and the
//! signal set every pass is compiled for (constant signal loops, folded kind switches, the
//! record layout: 16 bytes for radiance, 8 for occlusion and shadows).

use crate::tasks::SignalType;

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

    /// The set's kinds joined with `+` (e.g. `Specular+Diffuse`), for labels.
    pub fn label(self) -> String {
        let names: Vec<String> = self.kinds[..self.count]
            .iter()
            .map(|k| format!("{k:?}"))
            .collect();
        names.join("+")
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

    /// The WGSL of a pass of this set: the modules `roots` (the pass) composed with the set's
    /// constants (`denoise/signals`), its record layout and (`output`: the last à-trous
    /// iteration of a one-signal chain) the output texture of group 2, and the pass's own
    /// `params`.
    pub fn compose(
        self,
        roots: &[&str],
        output: Option<wgpu::TextureFormat>,
        params: &[(&str, &str)],
    ) -> String {
        let record = if self.scalar() {
            "denoise/record_scalar"
        } else {
            "denoise/record_rgba"
        };
        // Formats are checked before any pipeline is made; the fallback is never used.
        let format = output.map(|f| wgsl_format(f).unwrap_or("rgba16float"));
        let output = if format.is_some() {
            "denoise/output/one"
        } else {
            "denoise/output/none"
        };
        let constants = [
            self.count.to_string(),
            (self.kinds[0] as u32).to_string(),
            (self.kinds[1] as u32).to_string(),
        ];
        let mut all: Vec<(&str, &str)> = vec![
            ("DN_SIGNALS", &constants[0]),
            ("DN_KIND0", &constants[1]),
            ("DN_KIND1", &constants[2]),
        ];
        all.extend(format.map(|f| ("DN_OUTPUT0_FORMAT", f)));
        all.extend_from_slice(params);
        let mut modules = vec![record, output];
        modules.extend_from_slice(roots);
        crate::gpu::compose::compose(&modules, &all)
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
