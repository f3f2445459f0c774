//! One GPU device for the crate's unit tests (device creation is slow on lavapipe). A missing
//! adapter fails the test: GPU tests never skip. `KSRT_TEST_MINIMAL_DEVICE=1` requests
//! `Features::empty()` and `Limits::default()`, as CI's second run.

use std::sync::OnceLock;

pub(crate) struct TestGpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
}

pub(crate) fn gpu() -> &'static TestGpu {
    static GPU: OnceLock<TestGpu> = OnceLock::new();
    GPU.get_or_init(|| {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var("WGPU_BACKEND").is_err() {
            desc.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(desc);
        let adapter = pollster::block_on(instance.request_adapter(&Default::default()))
            .unwrap_or_else(|e| {
                panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}")
            });
        let minimal = std::env::var("KSRT_TEST_MINIMAL_DEVICE").is_ok_and(|v| v == "1");
        let hardware = backend() == crate::device::TraversalBackend::HardwareRayQuery;
        let (mut features, mut limits) = if minimal {
            (wgpu::Features::empty(), wgpu::Limits::default())
        } else {
            (
                // What the SDK can use, not every adapter feature: wgpu refuses experimental
                // ones (NVIDIA lists mesh shaders and ray-tracing pipelines) unless opted in.
                crate::device::required_features()
                    | crate::device::optional_features_supported(&adapter),
                adapter.limits(),
            )
        };
        if hardware {
            let rq = crate::device::hardware_ray_query_features(&adapter).unwrap_or_else(|| {
                panic!("KSRT_TEST_BACKEND=hardware needs an adapter with ray queries")
            });
            features |= rq;
            limits = crate::device::hardware_ray_query_limits(&adapter, limits);
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("kickstart-rt unit tests"),
            required_features: features,
            required_limits: limits,
            experimental_features: if hardware {
                // SAFETY: the tests accept wgpu's experimental ray-query support.
                unsafe { wgpu::ExperimentalFeatures::enabled() }
            } else {
                wgpu::ExperimentalFeatures::disabled()
            },
            ..Default::default()
        }))
        .expect("request_device");
        TestGpu { device, queue }
    })
}

/// The traversal backend the unit tests that trace use (`KSRT_TEST_BACKEND=hardware`: the
/// hardware ray-query one, on a device created with ray queries; anything else: software), as
/// the integration suites read it.
pub(crate) fn backend() -> crate::device::TraversalBackend {
    match std::env::var("KSRT_TEST_BACKEND").as_deref() {
        Ok("hardware") => crate::device::TraversalBackend::HardwareRayQuery,
        _ => crate::device::TraversalBackend::Software,
    }
}

/// Reads `size` bytes of `buffer` from `offset` back to the CPU (waits; tests only).
pub(crate) fn read_back(buffer: &wgpu::Buffer, offset: u64, size: u64) -> Vec<u8> {
    let g = gpu();
    crate::gpu::buffers::read_back(&g.device, &g.queue, buffer, offset, size).expect("read-back")
}

/// A storage buffer (STORAGE | COPY_SRC | COPY_DST) with `data` in it.
pub(crate) fn buffer_with(data: &[u8]) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    gpu()
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("test data"),
            contents: data,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        })
}

/// An empty storage buffer (STORAGE | COPY_SRC | COPY_DST) of `size` bytes.
pub(crate) fn buffer(size: u64) -> wgpu::Buffer {
    gpu().device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("test buffer"),
        size,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Submits `f`'s recording and waits for it (tests only).
pub(crate) fn run(f: impl FnOnce(&mut super::Recorder<'_>)) {
    let g = gpu();
    let mut enc = g.device.create_command_encoder(&Default::default());
    {
        let mut rec = super::Recorder::new(&g.device, &mut enc);
        f(&mut rec);
    }
    g.queue.submit([enc.finish()]);
    g.device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
}

/// Small seeded PRNG (xorshift64*) for the unit tests' random inputs: failures reproduce from
/// the seed.
pub(crate) struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in `0..n`.
    pub fn below(&mut self, n: u32) -> u32 {
        (((self.next() >> 32) * u64::from(n)) >> 32) as u32
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next() >> 40) as f32 / (1u64 << 24) as f32)
    }
}

/// A 2D texture (TEXTURE_BINDING | COPY_DST | COPY_SRC | STORAGE_BINDING where the format allows
/// it) of `width × height` texels holding `texels` (tightly packed rows), and its view.
pub(crate) fn texture_with(
    format: wgpu::TextureFormat,
    width: u32,
    height: u32,
    texels: &[u8],
) -> wgpu::TextureView {
    let g = gpu();
    let mut usage = wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::COPY_DST
        | wgpu::TextureUsages::COPY_SRC;
    if crate::tasks::WRITABLE_OUTPUT_FORMATS.contains(&format) {
        usage |= wgpu::TextureUsages::STORAGE_BINDING;
    }
    let size = wgpu::Extent3d {
        width,
        height,
        depth_or_array_layers: 1,
    };
    let texture = g.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("test texture"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    });
    let bpp = format.block_copy_size(None).expect("a colour format");
    g.queue.write_texture(
        texture.as_image_copy(),
        texels,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(width * bpp),
            rows_per_image: Some(height),
        },
        size,
    );
    texture.create_view(&Default::default())
}
