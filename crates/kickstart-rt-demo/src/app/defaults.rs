//! Defaults that depend on the adapter: on a CPU device (Mesa's lavapipe, SwiftShader, WARP) a
//! frame costs about a hundred times what it costs on a GPU and every pipeline is compiled by
//! LLVM on the CPU, so `ksrt render`, `quality`, `bench` and `view` pick smaller images and fewer
//! frames there and say so in one line. An option given on the command line always wins; on a
//! GPU the defaults are the ones the help text names.

/// Whether the adapter is a CPU device (software rendering).
pub fn is_software(info: &wgpu::AdapterInfo) -> bool {
    info.device_type == wgpu::DeviceType::Cpu
}

/// One option's default on a GPU and on a CPU device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Default2<T> {
    /// On a GPU (what `--help` shows).
    pub gpu: T,
    /// On a CPU device.
    pub cpu: T,
}

/// The options resolved for one adapter, and what was defaulted differently because it is a CPU
/// device (for the notice).
#[derive(Debug, Default)]
pub struct Resolver {
    software: bool,
    changed: Vec<(String, &'static str)>,
}

impl Resolver {
    /// A resolver for an adapter that is (`software`) or is not a CPU device.
    pub fn new(software: bool) -> Self {
        Resolver {
            software,
            changed: Vec::new(),
        }
    }

    /// `explicit` when the user gave it, else the default for this adapter; `label` names the
    /// value in the notice (`"{v} frames"`) and `flag` the option that changes it.
    pub fn pick<T: Copy + std::fmt::Display>(
        &mut self,
        explicit: Option<T>,
        default: Default2<T>,
        label: &str,
        flag: &'static str,
    ) -> T {
        if let Some(v) = explicit {
            return v;
        }
        if !self.software {
            return default.gpu;
        }
        self.changed
            .push((label.replace("{v}", &default.cpu.to_string()), flag));
        default.cpu
    }

    /// The one-line notice of the CPU device's defaults (`None` on a GPU, or when every option
    /// was given): "software Vulkan (NAME): 640x360, 16 frames; --size/--frames to change".
    pub fn notice(&self, adapter: &wgpu::AdapterInfo) -> Option<String> {
        if self.changed.is_empty() {
            return None;
        }
        let values: Vec<&str> = self.changed.iter().map(|(v, _)| v.as_str()).collect();
        let flags: Vec<&str> = self.changed.iter().map(|(_, f)| *f).collect();
        Some(format!(
            "software {:?} ({}): {}; {} to change",
            adapter.backend,
            adapter.name,
            values.join(", "),
            flags.join("/")
        ))
    }
}

/// `--size` of `render` and `view`.
pub const VIEW_SIZE: Default2<&str> = Default2 {
    gpu: "1280x720",
    cpu: "640x360",
};
/// `--frames` of `render`: enough for the lighting cache and the denoisers to settle on a GPU;
/// on a CPU device three, so that a first render, pipelines compiled included, takes well under
/// a minute on two busy cores. With Mesa's shader cache cold, lavapipe spends about 7 s on each
/// 640×360 frame of every effect (about 2 s with the cache warm), after about 14 s of start-up.
pub const RENDER_FRAMES: Default2<u32> = Default2 { gpu: 32, cpu: 3 };
/// `--size` of `quality` and `bench`.
pub const MEASURE_SIZE: Default2<&str> = Default2 {
    gpu: "1920x1080",
    cpu: "320x180",
};
/// `--frames` of `quality`.
pub const QUALITY_FRAMES: Default2<u32> = Default2 { gpu: 32, cpu: 4 };
/// `--warmup` of `quality`.
pub const QUALITY_WARMUP: Default2<u32> = Default2 { gpu: 64, cpu: 8 };
/// `--reference-samples` of `quality`.
pub const QUALITY_SAMPLES: Default2<u32> = Default2 { gpu: 2048, cpu: 64 };
/// `--iterations` of `bench`.
pub const BENCH_ITERATIONS: Default2<u32> = Default2 { gpu: 5, cpu: 1 };

#[cfg(test)]
mod tests {
    use super::*;

    fn info(device_type: wgpu::DeviceType) -> wgpu::AdapterInfo {
        let mut info = wgpu::AdapterInfo::new(device_type, wgpu::Backend::Vulkan);
        info.name = "llvmpipe".into();
        info
    }

    #[test]
    fn a_cpu_device_gets_small_defaults_explicit_options_win_and_a_gpu_keeps_its_own() {
        let cpu = info(wgpu::DeviceType::Cpu);
        assert!(is_software(&cpu));
        let mut r = Resolver::new(is_software(&cpu));
        assert_eq!(r.pick(None, VIEW_SIZE, "{v}", "--size"), "640x360");
        assert_eq!(r.pick(Some(3), RENDER_FRAMES, "{v} frames", "--frames"), 3);
        assert_eq!(
            r.notice(&cpu).as_deref(),
            Some("software Vulkan (llvmpipe): 640x360; --size to change")
        );
        let mut r = Resolver::new(is_software(&cpu));
        r.pick(None, VIEW_SIZE, "{v}", "--size");
        r.pick(None, RENDER_FRAMES, "{v} frames", "--frames");
        assert_eq!(
            r.notice(&cpu).as_deref(),
            Some("software Vulkan (llvmpipe): 640x360, 3 frames; --size/--frames to change")
        );
        // Every option given: nothing to say.
        let mut r = Resolver::new(true);
        r.pick(Some("64x64"), VIEW_SIZE, "{v}", "--size");
        assert_eq!(r.notice(&cpu), None);

        for gpu in [
            wgpu::DeviceType::DiscreteGpu,
            wgpu::DeviceType::IntegratedGpu,
        ] {
            let gpu = info(gpu);
            let mut r = Resolver::new(is_software(&gpu));
            assert_eq!(r.pick(None, VIEW_SIZE, "{v}", "--size"), "1280x720");
            assert_eq!(r.pick(None, RENDER_FRAMES, "{v} frames", "--frames"), 32);
            assert_eq!(r.notice(&gpu), None);
        }
    }
}
