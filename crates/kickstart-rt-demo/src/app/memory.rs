//! The SDK's GPU memory over a render: the peak by the SDK's own count (by kind and by denoising
//! context) and by wgpu's allocator (the allocations the SDK labelled, driver acceleration
//! structures included), printed as a breakdown and written as CSV or JSON.

use kickstart_rt::{DenoisingContextHandle, ExecuteContext, ResourceAllocations, SignalType};

use kickstart_rt_renderer::error::AnyResult;

/// Every wgpu allocation the SDK makes carries a label starting with this.
const SDK_LABEL: &str = "kickstart-rt";

/// The SDK's memory at the frame it held the most, and wgpu's view of it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MemoryPeak {
    /// The SDK's count at its peak (by [`ResourceAllocations::total`]).
    pub sdk: ResourceAllocations,
    /// Each denoising context's bytes at that frame.
    pub contexts: Vec<(SignalType, u64)>,
    /// The largest total of wgpu's live allocations labelled by the SDK, over the same frames;
    /// `None` where wgpu has no allocator report (Metal, GL, WebGPU).
    pub wgpu_sdk: Option<u64>,
    /// wgpu's SDK allocations at that peak, bytes by label (largest first).
    pub wgpu_labels: Vec<(String, u64)>,
    /// Frames sampled.
    pub frames: u32,
    /// The SDK's count and wgpu's labelled total after the last frame sampled: what a scene
    /// holds once its builds are done (static BLASes compacted, build memory given back).
    pub last: (u64, Option<u64>),
}

impl MemoryPeak {
    /// Samples `ctx` after a frame: keeps the SDK's breakdown when its total is the largest so
    /// far, and the largest labelled total of `device`'s allocator report.
    pub fn sample(
        &mut self,
        device: &wgpu::Device,
        ctx: &ExecuteContext,
        contexts: &[(SignalType, DenoisingContextHandle)],
    ) {
        self.frames += 1;
        let now = ctx.resource_allocations();
        self.last.0 = now.total();
        if self.frames == 1 || now.total() > self.sdk.total() {
            self.sdk = now;
            self.contexts = contexts
                .iter()
                .map(|(signal, h)| (*signal, ctx.denoising_context_bytes(*h).unwrap_or(0)))
                .collect();
        }
        let labels = wgpu_sdk_labels(device);
        self.last.1 = labels.as_ref().map(|l| l.iter().map(|(_, b)| b).sum());
        if let Some(labels) = labels {
            let bytes = labels.iter().map(|(_, b)| b).sum();
            if self.wgpu_sdk.is_none_or(|peak| bytes > peak) {
                self.wgpu_sdk = Some(bytes);
                self.wgpu_labels = labels;
            }
        }
    }

    /// The SDK's peak total, bytes.
    pub fn total(&self) -> u64 {
        self.sdk.total()
    }

    /// Rows of (kind, bytes): each kind of the SDK's count, then each denoising context.
    pub fn rows(&self) -> Vec<(String, u64)> {
        let a = &self.sdk;
        let mut rows: Vec<(String, u64)> = [
            ("vertex_copies", a.vertex_copies),
            ("blas", a.blas),
            ("tlas", a.tlas),
            ("scratch", a.scratch),
            ("cache", a.cache),
            ("denoiser", a.denoiser),
            ("staging", a.staging),
            ("pool_reserve", a.pool_reserve),
            (
                "driver_acceleration_structures",
                a.driver_acceleration_structures,
            ),
        ]
        .into_iter()
        .map(|(k, b)| (k.to_string(), b))
        .collect();
        for (signal, bytes) in &self.contexts {
            rows.push((format!("denoising_context:{signal:?}"), *bytes));
        }
        rows
    }

    /// The breakdown as printed by `ksrt render`: each kind in MB (10⁶ bytes), the denoisers'
    /// bytes per pixel of `pixels` and the scene's per triangle of `triangles`.
    pub fn breakdown(&self, pixels: u64, triangles: u64) -> String {
        let mb = |b: u64| b as f64 / 1e6;
        let mut out = format!(
            "SDK memory peak over {} frames: {:.1} MB",
            self.frames,
            mb(self.total())
        );
        match self.wgpu_sdk {
            Some(w) => out += &format!(" (wgpu's allocator: {:.1} MB)\n", mb(w)),
            None => out += " (no allocator report on this backend)\n",
        }
        for (kind, bytes) in self.rows() {
            out += &format!("  {kind:<34} {:>9.1} MB\n", mb(bytes));
        }
        let a = &self.sdk;
        let scene = a.total() - a.denoiser - a.staging;
        out += &format!(
            "  denoisers {:.1} bytes per pixel; scene and cache {:.1} bytes per triangle\n",
            a.denoiser as f64 / pixels.max(1) as f64,
            scene as f64 / triangles.max(1) as f64
        );
        out += &format!("  after the last frame: {:.1} MB", mb(self.last.0));
        match self.last.1 {
            Some(w) => out += &format!(" (wgpu's allocator: {:.1} MB)\n", mb(w)),
            None => out += "\n",
        }
        out
    }

    /// The rows as CSV (`kind,bytes`, then a `total` row).
    pub fn csv(&self) -> String {
        let mut out = String::from("kind,bytes\n");
        for (kind, bytes) in self.rows() {
            out += &format!("{kind},{bytes}\n");
        }
        out += &format!("total,{}\n", self.total());
        if let Some(w) = self.wgpu_sdk {
            out += &format!("wgpu_allocator,{w}\n");
        }
        for (label, bytes) in &self.wgpu_labels {
            out += &format!("wgpu:{label},{bytes}\n");
        }
        out
    }

    /// The peak as JSON (`total`, `wgpu_allocator`, and `kinds` by name).
    pub fn json(&self) -> serde_json::Value {
        let kinds: serde_json::Map<String, serde_json::Value> = self
            .rows()
            .into_iter()
            .map(|(k, b)| (k, serde_json::json!(b)))
            .collect();
        serde_json::json!({
            "frames": self.frames,
            "total": self.total(),
            "wgpu_allocator": self.wgpu_sdk,
            "kinds": kinds,
            "last_total": self.last.0,
            "last_wgpu_allocator": self.last.1,
        })
    }

    /// Writes [`Self::csv`] to `path`.
    pub fn write_csv(&self, path: &std::path::Path) -> AnyResult<()> {
        std::fs::write(path, self.csv()).map_err(|e| format!("{}: {e}", path.display()).into())
    }
}

/// `device`'s live allocations labelled by the SDK, by wgpu's allocator report: bytes by label,
/// largest first.
fn wgpu_sdk_labels(device: &wgpu::Device) -> Option<Vec<(String, u64)>> {
    device.generate_allocator_report().map(|r| {
        let mut by_label = std::collections::BTreeMap::<String, u64>::new();
        for a in r
            .allocations
            .iter()
            .filter(|a| a.name.starts_with(SDK_LABEL))
        {
            *by_label.entry(a.name.clone()).or_default() += a.size;
        }
        let mut rows: Vec<(String, u64)> = by_label.into_iter().collect();
        rows.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
        rows
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peak() -> MemoryPeak {
        MemoryPeak {
            sdk: ResourceAllocations {
                vertex_copies: 1,
                blas: 2_000_000,
                denoiser: 4_000_000,
                ..Default::default()
            },
            contexts: vec![(SignalType::Shadow, 3_000_000)],
            wgpu_sdk: Some(6_500_000),
            wgpu_labels: vec![("kickstart-rt BLAS nodes".into(), 6_500_000)],
            frames: 2,
            last: (5_000_000, Some(5_400_000)),
        }
    }

    #[test]
    fn csv_has_every_kind_each_context_and_the_totals() {
        let csv = peak().csv();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], "kind,bytes");
        assert!(lines.contains(&"vertex_copies,1"), "{csv}");
        assert!(lines.contains(&"denoiser,4000000"), "{csv}");
        assert!(lines.contains(&"denoising_context:Shadow,3000000"), "{csv}");
        assert!(lines.contains(&"total,6000001"), "{csv}");
        assert!(lines.contains(&"wgpu_allocator,6500000"), "{csv}");
        assert_eq!(lines.last(), Some(&"wgpu:kickstart-rt BLAS nodes,6500000"));
        assert_eq!(lines.len(), 1 + 9 + 1 + 2 + 1);
    }

    #[test]
    fn breakdown_gives_megabytes_and_per_pixel_and_per_triangle_figures() {
        let text = peak().breakdown(1_000_000, 1_000);
        assert!(
            text.starts_with("SDK memory peak over 2 frames: 6.0 MB (wgpu's allocator: 6.5 MB)"),
            "{text}"
        );
        assert!(text.contains("denoisers 4.0 bytes per pixel"), "{text}");
        assert!(
            text.contains("scene and cache 2000.0 bytes per triangle"),
            "{text}"
        );
        assert!(
            text.contains("after the last frame: 5.0 MB (wgpu's allocator: 5.4 MB)"),
            "{text}"
        );
    }
}
