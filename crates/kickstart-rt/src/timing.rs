//! GPU timings of the SDK's passes, from timestamp queries written around each compute pass.

use crate::error::Result;
use crate::gpu::recorder::{TimedPass, Timestamps};

/// GPU time of one compute pass.
#[derive(Debug, Clone, PartialEq)]
pub struct PassTiming {
    /// What the SDK was doing: `ingest`, `blas build`, `blas refit`, `tlas build`, `tlas refit`,
    /// `trace rays`, `debug view`.
    pub label: &'static str,
    /// The pass within it (e.g. the sort or hierarchy pass of a build).
    pub pass: &'static str,
    /// Start, milliseconds since the task's first timed pass began.
    pub start_ms: f64,
    /// Duration, milliseconds.
    pub ms: f64,
}

/// GPU timings of one GPU task's passes, in recording order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GpuTimings {
    /// Every timed pass.
    pub passes: Vec<PassTiming>,
}

impl GpuTimings {
    /// Milliseconds from the start of the first pass whose label starts with any of `prefixes`
    /// to the end of the last such pass (so gaps between them count: it is the span a frame
    /// would wait for); `None` when no pass matches.
    pub fn span_ms(&self, prefixes: &[&str]) -> Option<f64> {
        let matching = || {
            self.passes
                .iter()
                .filter(|p| prefixes.iter().any(|x| p.label.starts_with(x)))
        };
        let start = matching().map(|p| p.start_ms).reduce(f64::min)?;
        let end = matching().map(|p| p.start_ms + p.ms).reduce(f64::max)?;
        Some(end - start)
    }

    /// Sum of the durations of the passes whose label starts with any of `prefixes`.
    pub fn sum_ms(&self, prefixes: &[&str]) -> f64 {
        self.passes
            .iter()
            .filter(|p| prefixes.iter().any(|x| p.label.starts_with(x)))
            .map(|p| p.ms)
            .sum()
    }
}

/// The resolved timestamps of one task, waiting to be read.
pub(crate) struct TimingReadback {
    buffer: wgpu::Buffer,
    passes: Vec<TimedPass>,
}

impl TimingReadback {
    /// Resolves the task's queries into a mappable buffer (recorded at the end of the task).
    pub fn record(
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        ts: Timestamps,
    ) -> Option<Self> {
        let count = ts.passes.len() as u32 * 2;
        if count == 0 {
            return None;
        }
        let bytes = count as u64 * 8;
        let resolve = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kickstart-rt timestamps resolve"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kickstart-rt timestamps read-back"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.resolve_query_set(&ts.query_set, 0..count, &resolve, 0);
        encoder.copy_buffer_to_buffer(&resolve, 0, &buffer, 0, bytes);
        Some(TimingReadback {
            buffer,
            passes: ts.passes,
        })
    }

    /// Waits for the values and converts ticks (`period_ns` each) to milliseconds.
    pub fn wait(self, device: &wgpu::Device, period_ns: f32) -> Result<GpuTimings> {
        let bytes = crate::gpu::buffers::map_and_wait(device, &self.buffer)?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
        let to_ms = |t: u64| t as f64 * period_ns as f64 * 1e-6;
        let origin = ticks.first().copied().unwrap_or(0);
        let passes = self
            .passes
            .iter()
            .map(|p| {
                let b = ticks.get(p.begin as usize).copied().unwrap_or(0);
                let e = ticks.get(p.end as usize).copied().unwrap_or(b);
                PassTiming {
                    label: p.scope,
                    pass: p.label,
                    start_ms: to_ms(b.saturating_sub(origin)),
                    ms: to_ms(e.saturating_sub(b)),
                }
            })
            .collect();
        Ok(GpuTimings { passes })
    }
}
