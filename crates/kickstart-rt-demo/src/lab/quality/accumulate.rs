//! Running sums of trace samples on the GPU, for `ksrt quality`'s converged references: reading
//! thousands of full-resolution samples back to the CPU would cost far more than tracing them.

use wgpu::util::DeviceExt;

use crate::app::gpu;
use kickstart_rt_renderer::error::AnyResult;

/// How a sample texture is summed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleKind {
    /// RGB radiance (specular, diffuse).
    Radiance,
    /// A shadow trace's hit distance (negative: lit), summed as visibility.
    ShadowHitDistance,
    /// One value in R (AO), summed in every channel.
    Scalar,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    width: u32,
    height: u32,
    mode: u32,
    _pad: u32,
}

/// The sum of the samples of one texture: `Rgba32Float` texels, alpha counting the samples.
pub struct Accumulator {
    size: (u32, u32),
    sum: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    pipeline: wgpu::ComputePipeline,
}

impl Accumulator {
    /// A zeroed sum of `source`'s samples (a `width × height` float texture with
    /// `TEXTURE_BINDING`), read as `kind`.
    pub fn new(device: &wgpu::Device, source: &wgpu::Texture, kind: SampleKind) -> Accumulator {
        let size = (source.width(), source.height());
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ksrt quality accumulate"),
            source: wgpu::ShaderSource::Wgsl(
                include_str!("../../../shaders/accumulate.wgsl").into(),
            ),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("ksrt quality accumulate"),
            layout: None,
            module: &module,
            entry_point: Some("accumulate"),
            compilation_options: Default::default(),
            cache: None,
        });
        let params = Params {
            width: size.0,
            height: size.1,
            mode: match kind {
                SampleKind::Radiance => 0,
                SampleKind::ShadowHitDistance => 1,
                SampleKind::Scalar => 2,
            },
            _pad: 0,
        };
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ksrt quality accumulate params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let sum = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ksrt quality sum"),
            size: size.0 as u64 * size.1 as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let view = source.create_view(&Default::default());
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ksrt quality accumulate"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: sum.as_entire_binding(),
                },
            ],
        });
        Accumulator {
            size,
            sum,
            bind_group,
            pipeline,
        }
    }

    /// Records the reset of the sum to zero.
    pub fn clear(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.sum, 0, None);
    }

    /// Records adding the source texture's current content to the sum.
    pub fn add(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("ksrt quality accumulate"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.dispatch_workgroups(self.size.0.div_ceil(8), self.size.1.div_ceil(8), 1);
    }

    /// The mean of the samples added, RGB per pixel (row-major), waiting for the GPU.
    pub fn mean(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> AnyResult<Vec<[f32; 3]>> {
        let bytes = self.sum.size();
        let readback = gpu::readback_buffer(device, bytes);
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&self.sum, 0, &readback, 0, bytes);
        queue.submit([encoder.finish()]);
        let data = gpu::map_read(device, &readback)?;
        // Copied out: a byte vector need not be aligned for f32.
        let texels: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data);
        Ok(texels
            .iter()
            .map(|t| {
                let n = t[3].max(1.0);
                [t[0] / n, t[1] / n, t[2] / n]
            })
            .collect())
    }
}
