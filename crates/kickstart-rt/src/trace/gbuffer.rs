//! G-buffer decoding shared by every pass that reads the engine's G-buffer: the trace tasks, the
//! lighting injection and the denoisers. The WGSL side is `shaders/trace/gbuffer.wgsl` (functions
//! `gb_surface`, `gb_roughness`, `gb_specular`, `gb_mask`, `gb_project`, …); this side packs its
//! uniform from the task's inputs and binds the textures.
//!
//! Binding: one bind group (the importer picks its number with the module's parameter `GBUFFER_GROUP`) with an explicit
//! layout ([`GBufferBinder::layout`]) — uniform at 0, then depth, normal, roughness, specular and
//! input mask textures at 1–5, all read with `textureLoad` as unfilterable float (so `R32Float`
//! and depth formats bind too). Absent optional textures bind a 1×1 placeholder; the uniform says
//! which are real. A pass that includes the module builds its pipeline with
//! [`crate::gpu::shader::compute_pipeline_with_layouts`] so that bindings it does not use still
//! match the layout.
//!
//! Decoding rules (documented for users in the task docs):
//! - `RClipSpace` depth is unprojected with `inverse(view_to_clip · world_to_view)`, computed in
//!   f64; a texel equal to the far plane's NDC depth (1 for normal Z, 0 for reverse Z, derived
//!   from the matrices) holds no surface. `RgbWorldSpace` depth is the position itself.
//! - `RClipSpace` depth was rendered with the jittered projection (`ViewInfo::jitter`): each
//!   texel is unprojected at its centre minus the jitter, so surfaces stay on their planes (at
//!   grazing angles a pixel of jitter is a large step in depth).
//! - A non-finite position or a zero normal also means "no surface" (nothing is traced there).
//! - Normals are decoded by type (octahedral: Cigolle et al. 2014), transformed by
//!   `normal_to_world` and normalised.

use crate::gpu::buffers::placeholder_texture;
use crate::gpu::reflect::{ReflectedLayout, ReflectedShader};
use crate::tasks::{
    DenoiseTaskCommon, DepthInput, DepthType, NormalInput, NormalType, RoughnessInput,
    SpecularInput, TextureInput, TraceTaskCommon, ViewInfo, Viewport,
};
use bytemuck::{Pod, Zeroable};
use glam::{DMat4, DVec3, DVec4};

/// The uniform of `shaders/trace/gbuffer.wgsl` (`GBufferParams`).
#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy, Debug, PartialEq)]
pub(crate) struct GBufferParams {
    clip_to_world: [[f32; 4]; 4],
    world_to_clip: [[f32; 4]; 4],
    prev_world_to_clip: [[f32; 4]; 4],
    normal_to_world: [[f32; 4]; 4],
    eye: [f32; 4],
    forward: [f32; 4],
    roughness_mask: [f32; 4],
    viewport: [u32; 4],
    depth_type: u32,
    normal_type: u32,
    has_textures: u32,
    far_ndc: f32,
    global_roughness: f32,
    roughness_multiplier: f32,
    min_roughness: f32,
    max_roughness: f32,
    global_metalness: f32,
    jitter: [f32; 2],
    pad: f32,
}

const HAS_ROUGHNESS: u32 = 1;
const HAS_SPECULAR: u32 = 2;
const HAS_MASK: u32 = 4;

/// A camera derived from a task's matrices (f64, so reverse-Z and infinite projections keep
/// their digits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CameraFrame {
    /// inverse(view_to_clip · world_to_view).
    pub clip_to_world: DMat4,
    /// view_to_clip · world_to_view.
    pub world_to_clip: DMat4,
    /// The eye (perspective); the view origin (orthographic).
    pub eye: DVec3,
    /// World-space viewing direction (the view's −z), normalised.
    pub forward: DVec3,
    /// Perspective projection (rays from the eye) rather than orthographic.
    pub perspective: bool,
    /// NDC depth of the far plane: what a cleared depth buffer holds (1 normal Z, 0 reverse Z).
    pub far_ndc: f64,
}

impl CameraFrame {
    /// The camera of `world_to_view` and `view_to_clip`.
    pub fn new(world_to_view: glam::Mat4, view_to_clip: glam::Mat4) -> Self {
        let v2c = view_to_clip.as_dmat4();
        let w2v = world_to_view.as_dmat4();
        let world_to_clip = v2c * w2v;
        let view_to_world = w2v.inverse();
        let eye = view_to_world * DVec4::new(0.0, 0.0, 0.0, 1.0);
        let eye = eye.truncate() / eye.w;
        let forward = view_to_world
            .transform_vector3(DVec3::NEG_Z)
            .normalize_or_zero();
        let w_row = v2c.row(3);
        let perspective = w_row.x != 0.0 || w_row.y != 0.0 || w_row.z != 0.0;
        // Far beyond any far plane, NDC depth leaves [0, 1] on the far side (or tends to it for
        // infinite projections): that side is the far plane's value.
        let far_point = v2c * DVec4::new(0.0, 0.0, -1e30, 1.0);
        let far_ndc = if (far_point.z / far_point.w).clamp(0.0, 1.0) >= 0.5 {
            1.0
        } else {
            0.0
        };
        CameraFrame {
            clip_to_world: world_to_clip.inverse(),
            world_to_clip,
            eye,
            forward,
            perspective,
            far_ndc,
        }
    }
}

/// The G-buffer inputs of one task, as the decoding module needs them.
#[derive(Clone, Copy)]
pub(crate) struct GBufferInputs<'a> {
    /// Depth.
    pub depth: &'a DepthInput,
    /// Normals.
    pub normal: &'a NormalInput,
    /// Roughness (`None`: the defaults, no texture).
    pub roughness: Option<&'a RoughnessInput>,
    /// Specular / metalness (`None`: the defaults, no texture).
    pub specular: Option<&'a SpecularInput>,
    /// Input mask.
    pub input_mask: Option<&'a TextureInput>,
    /// Camera.
    pub view: &'a ViewInfo,
    /// The processed rectangle (already resolved against the output size).
    pub viewport: Viewport,
}

/// `viewport`, or the whole `size` when `None`.
pub(crate) fn resolve_viewport(viewport: Option<Viewport>, size: wgpu::Extent3d) -> Viewport {
    viewport.unwrap_or(Viewport {
        x: 0,
        y: 0,
        width: size.width,
        height: size.height,
    })
}

impl<'a> GBufferInputs<'a> {
    /// The inputs of a trace task whose output is `output`.
    pub fn of_trace(common: &'a TraceTaskCommon, output: &TextureInput) -> Self {
        GBufferInputs {
            depth: &common.depth,
            normal: &common.normal,
            roughness: Some(&common.roughness),
            specular: Some(&common.specular),
            input_mask: common.input_mask.as_ref(),
            view: &common.view,
            viewport: resolve_viewport(common.viewport, output.texture().size()),
        }
    }

    /// The inputs of a denoise task whose output is `output`.
    pub fn of_denoise(common: &'a DenoiseTaskCommon, output: &TextureInput) -> Self {
        GBufferInputs {
            depth: &common.depth,
            normal: &common.normal,
            roughness: Some(&common.roughness),
            specular: None,
            input_mask: None,
            view: &common.view,
            viewport: resolve_viewport(common.viewport, output.texture().size()),
        }
    }

    /// The shader's uniform.
    pub fn params(&self) -> GBufferParams {
        let cam = CameraFrame::new(self.view.world_to_view, self.view.view_to_clip);
        let prev = CameraFrame::new(self.view.prev_world_to_view, self.view.prev_view_to_clip);
        let default_roughness = RoughnessInput::default();
        let r = self.roughness.unwrap_or(&default_roughness);
        let default_specular = SpecularInput::default();
        let sp = self.specular.unwrap_or(&default_specular);
        let mut has_textures = 0;
        if r.texture.is_some() {
            has_textures |= HAS_ROUGHNESS;
        }
        if sp.texture.is_some() {
            has_textures |= HAS_SPECULAR;
        }
        if self.input_mask.is_some() {
            has_textures |= HAS_MASK;
        }
        let vp = self.viewport;
        GBufferParams {
            clip_to_world: cam.clip_to_world.as_mat4().to_cols_array_2d(),
            world_to_clip: cam.world_to_clip.as_mat4().to_cols_array_2d(),
            prev_world_to_clip: prev.world_to_clip.as_mat4().to_cols_array_2d(),
            normal_to_world: self.normal.normal_to_world.to_cols_array_2d(),
            eye: cam
                .eye
                .as_vec3()
                .extend(if cam.perspective { 1.0 } else { 0.0 })
                .to_array(),
            forward: cam.forward.as_vec3().extend(0.0).to_array(),
            roughness_mask: r.roughness_mask.to_array(),
            viewport: [vp.x, vp.y, vp.width, vp.height],
            depth_type: match self.depth.depth_type {
                DepthType::RgbWorldSpace => 0,
                DepthType::RClipSpace => 1,
            },
            normal_type: match self.normal.normal_type {
                NormalType::RgbVector => 0,
                NormalType::RgbNormalizedVector => 1,
                NormalType::RgOctahedron => 2,
                NormalType::BaOctahedron => 3,
                NormalType::RgNormalizedOctahedron => 4,
                NormalType::BaNormalizedOctahedron => 5,
            },
            has_textures,
            far_ndc: cam.far_ndc as f32,
            global_roughness: r.global_roughness,
            roughness_multiplier: r.roughness_multiplier,
            min_roughness: r.min_roughness,
            max_roughness: r.max_roughness,
            global_metalness: sp.global_metalness,
            jitter: self.view.jitter.to_array(),
            pad: 0.0,
        }
    }
}

/// The G-buffer bind group layout and the placeholder bound for absent optional textures.
pub(crate) struct GBufferBinder {
    /// Every binding the module declares (a pass may read only some of them).
    layout: ReflectedLayout,
    placeholder: wgpu::TextureView,
}

impl GBufferBinder {
    /// Creates the layout (the bindings of `trace/gbuffer` as it declares them) and the 1×1
    /// placeholder texture.
    pub fn new(device: &wgpu::Device) -> Self {
        let shader = ReflectedShader::compose(&["trace/gbuffer"], &[("GBUFFER_GROUP", "0")]);
        let layout = ReflectedLayout::new(device, "kickstart-rt g-buffer", shader.reflection(), 0);
        let placeholder = placeholder_texture(device, "kickstart-rt g-buffer placeholder");
        GBufferBinder {
            layout,
            placeholder,
        }
    }

    /// The 1×1 texture bound where an optional input is absent.
    pub fn placeholder(&self) -> &wgpu::TextureView {
        &self.placeholder
    }

    /// The bind group layout (for pipeline layouts).
    pub fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout.layout.layout
    }

    /// The layout with its binding numbers (for the traversal passes' own SPIR-V).
    pub fn group(&self) -> crate::gpu::layout::GroupLayout<'_> {
        self.layout.group()
    }

    /// The bind group of `inputs` with its uniform in `params` (a buffer holding
    /// [`GBufferInputs::params`]).
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        params: &wgpu::Buffer,
        inputs: &GBufferInputs<'_>,
    ) -> wgpu::BindGroup {
        let or_placeholder = |t: Option<&TextureInput>| -> TextureInput {
            t.cloned().unwrap_or_else(|| self.placeholder.clone())
        };
        let roughness = or_placeholder(inputs.roughness.and_then(|r| r.texture.as_ref()));
        let specular = or_placeholder(inputs.specular.and_then(|s| s.texture.as_ref()));
        let mask = or_placeholder(inputs.input_mask);
        let view = wgpu::BindingResource::TextureView;
        self.layout.bind_group(
            device,
            &[
                ("gb", params.as_entire_binding()),
                ("gb_depth", view(&inputs.depth.texture)),
                ("gb_normal", view(&inputs.normal.texture)),
                ("gb_roughness_tex", view(&roughness)),
                ("gb_specular_tex", view(&specular)),
                ("gb_mask_tex", view(&mask)),
            ],
        )
    }
}

/// Asserts that [`GBufferParams`] has the layout of the WGSL `GBufferParams` in `module` (a
/// validated pass that imports `trace/gbuffer`).
#[cfg(test)]
pub(crate) fn assert_wgsl_layout(module: &naga::Module) {
    crate::gpu::wgsl_check::assert_wgsl_layout!(
        module,
        "GBufferParams",
        GBufferParams {
            clip_to_world,
            world_to_clip,
            prev_world_to_clip,
            normal_to_world,
            eye,
            forward,
            roughness_mask,
            viewport,
            depth_type,
            normal_type,
            has_textures,
            far_ndc,
            global_roughness,
            roughness_multiplier,
            min_roughness,
            max_roughness,
            global_metalness,
            jitter => "jitter_x",
            pad => "pad0",
        }
    );
}

#[cfg(test)]
mod tests;
