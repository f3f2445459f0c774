//! `ksrt bench --busy-gpu-ms`: GPU work submitted right before each timed task, untimed, so
//! short tasks run at the clocks a busy GPU holds.
//!
//! Why: between two timed repetitions the CPU prepares the next task (for the TLAS bench,
//! 100 000 instance updates) while the GPU idles, and the H100 lowers its clocks within that
//! gap. Sub-millisecond tasks (a refit, a TLAS build) then measured up to 2× slower in some runs
//! than in others with the same binary (docs/decisions/busy-gpu-clocks.md). In a frame, these
//! tasks run between the engine's other GPU work.

/// A spin kernel: an LCG step chain per invocation, whose result invocation 0 stores (so the
/// loop cannot be dropped, and a test can check that it ran).
const SPIN_WGSL: &str = r#"
@group(0) @binding(0) var<storage, read_write> sink: array<u32>;

@compute @workgroup_size(256)
fn spin(@builtin(global_invocation_id) id: vec3<u32>) {
    var x = id.x;
    for (var i = 0u; i < STEPSu; i++) {
        x = x * 1664525u + 1013904223u;
    }
    if id.x == 0u {
        sink[0] = x;
    }
}
"#;

/// LCG steps of one invocation.
const STEPS: u32 = 4096;
/// Workgroups of one spin dispatch: 4096 × 256 invocations × 4096 steps, about 0.15 ms of
/// integer work on an H100 at full clocks.
const WORKGROUPS: u32 = 4096;
/// What one dispatch is taken to last at full clocks, to turn milliseconds into dispatches.
const DISPATCH_MS: f64 = 0.15;

/// The spin pipeline and how many dispatches make the asked-for time.
pub struct BusyGpu {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    /// Invocation 0's result (read by the test).
    #[cfg_attr(not(test), allow(dead_code))]
    sink: wgpu::Buffer,
    dispatches: u32,
    workgroups: u32,
}

impl BusyGpu {
    /// About `ms` milliseconds of GPU work (at an H100's full clocks; longer on slower GPUs).
    pub fn new(device: &wgpu::Device, ms: f64) -> Self {
        Self::with_dispatches(
            device,
            (ms / DISPATCH_MS).ceil().max(1.0) as u32,
            WORKGROUPS,
        )
    }

    /// `dispatches` dispatches of `workgroups` workgroups each.
    fn with_dispatches(device: &wgpu::Device, dispatches: u32, workgroups: u32) -> Self {
        let source = SPIN_WGSL.replace("STEPS", &STEPS.to_string());
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ksrt bench busy gpu"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("ksrt bench busy gpu"),
            layout: None,
            module: &module,
            entry_point: Some("spin"),
            compilation_options: Default::default(),
            cache: None,
        });
        let sink = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ksrt bench busy gpu sink"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ksrt bench busy gpu"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: sink.as_entire_binding(),
            }],
        });
        BusyGpu {
            pipeline,
            bind_group,
            sink,
            dispatches: dispatches.max(1),
            workgroups: workgroups.max(1),
        }
    }

    /// Submits the spin work (returns at once; the next submission runs after it).
    pub fn submit(&self, device: &wgpu::Device, queue: &wgpu::Queue) {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ksrt bench busy gpu"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("ksrt bench busy gpu"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            for _ in 0..self.dispatches {
                pass.dispatch_workgroups(self.workgroups, 1, 1);
            }
        }
        queue.submit([encoder.finish()]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spin_kernel_runs_every_step() {
        let (device, queue) = crate::app::testing::device();
        let busy = BusyGpu::with_dispatches(device, 2, 1);
        busy.submit(device, queue);
        let read = device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: 16,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&busy.sink, 0, &read, 0, 16);
        queue.submit([encoder.finish()]);
        read.slice(..)
            .map_async(wgpu::MapMode::Read, |r| r.expect("map"));
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
        let view = read.slice(..4).get_mapped_range().expect("mapped");
        let got = u32::from_le_bytes([view[0], view[1], view[2], view[3]]);
        let want = (0..STEPS).fold(0u32, |x, _| {
            x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223)
        });
        assert_eq!(got, want, "invocation 0's LCG chain of {STEPS} steps");
        // The number of dispatches `new` makes from milliseconds.
        assert_eq!(BusyGpu::new(device, 1.0).dispatches, 7);
        assert_eq!(BusyGpu::new(device, 0.0).dispatches, 1);
    }
}
