//! Bind group layout entries of the kinds every compute pass uses (compute stage only, no
//! dynamic offsets, no minimum sizes: the passes bind whole ranges they sized themselves), and
//! layouts that remember their binding numbers (what our own SPIR-V needs, `gpu/spirv.rs`).

/// A bind group layout and the binding numbers of its entries, borrowed.
#[derive(Clone, Copy)]
pub(crate) struct GroupLayout<'a> {
    /// The layout.
    pub layout: &'a wgpu::BindGroupLayout,
    /// The binding number of each of its entries.
    pub bindings: &'a [u32],
}

/// A bind group layout that keeps the binding numbers of its entries.
pub(crate) struct BoundLayout {
    /// The layout.
    pub layout: wgpu::BindGroupLayout,
    /// The binding number of each of its entries.
    pub bindings: Vec<u32>,
}

impl BoundLayout {
    /// Creates the layout of `entries`.
    pub fn new(device: &wgpu::Device, label: &str, entries: &[wgpu::BindGroupLayoutEntry]) -> Self {
        BoundLayout {
            layout: device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries,
            }),
            bindings: entries.iter().map(|e| e.binding).collect(),
        }
    }

    /// This layout as a pipeline's group.
    pub fn group(&self) -> GroupLayout<'_> {
        GroupLayout {
            layout: &self.layout,
            bindings: &self.bindings,
        }
    }
}

/// A uniform buffer at `binding`.
pub(crate) fn uniform_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    buffer_entry(binding, wgpu::BufferBindingType::Uniform)
}

/// A storage buffer at `binding`, read-only or read-write.
pub(crate) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    buffer_entry(binding, wgpu::BufferBindingType::Storage { read_only })
}

/// A sampled 2-D float texture (not filterable: passes only `textureLoad`) at `binding`.
pub(crate) fn float_texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}
