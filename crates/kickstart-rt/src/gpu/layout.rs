//! Bind group layouts that remember their binding numbers (what our own SPIR-V needs,
//! `gpu/spirv.rs`). Their entries come from the shaders (`gpu/reflect.rs`).

/// A bind group layout and the binding numbers of its entries, borrowed.
#[derive(Clone, Copy)]
pub(crate) struct GroupLayout<'a> {
    /// The layout.
    pub layout: &'a wgpu::BindGroupLayout,
    /// The binding number of each of its entries.
    pub bindings: &'a [u32],
}

/// A bind group layout that keeps the binding numbers of its entries.
#[derive(Clone)]
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
