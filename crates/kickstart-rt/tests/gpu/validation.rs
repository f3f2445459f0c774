//! One test per row of the crate docs' validation table: a bad value must return
//! `Error::InvalidInput` naming the field, record nothing, and leave the context usable.

use crate::common;
use common::*;
use glam::{Affine3A, Mat4, Vec3, Vec4};
use kickstart_rt::*;
use proptest::prelude::*;
use wgpu::{TextureFormat as F, TextureUsages as U};

/// Builds `c`, expects an `InvalidInput` for `field` from `task`, and checks nothing was recorded
/// and that the context still builds a valid container.
fn expect_field(ctx: &ExecuteContext, c: TaskContainer, task: &str, field: &str) {
    let before = ctx.recorded_task_counts();
    let mut e = encoder();
    match ctx.build_gpu_task(c, &mut e) {
        Err(Error::InvalidInput {
            task: t,
            field: f,
            value,
            reason,
        }) => {
            assert_eq!((t, f.as_str()), (task, field), "value {value}: {reason}");
        }
        other => panic!("expected InvalidInput for {task}.{field}, got {other:?}"),
    }
    submit(e);
    assert_eq!(ctx.recorded_task_counts(), before, "nothing recorded");
    let mut e = encoder();
    let t = ctx
        .build_gpu_task(ctx.create_task_container(), &mut e)
        .expect("context still usable");
    submit(e);
    ctx.mark_gpu_task_completed(t).unwrap();
}

fn geometry_case(f: impl FnOnce(&mut GeometryTask)) -> (ExecuteContext, TaskContainer) {
    let ctx = context(2);
    let (vb, ib) = quad(1.0);
    let mut t = GeometryTask {
        operation: TaskOperation::Register,
        handle: ctx.create_geometry_handle(),
        input: geometry_input(vb, Some(ib)),
    };
    f(&mut t);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(t);
    (ctx, c)
}

fn geometry_row(field: &str, f: impl FnOnce(&mut GeometryTask)) {
    let (ctx, c) = geometry_case(f);
    expect_field(&ctx, c, "GeometryTask", field);
}

#[test]
fn row_supported_working_sets() {
    let g = gpu();
    let err = ExecuteContext::new(
        &g.device,
        &g.queue,
        InitSettings {
            supported_working_sets: 0,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(matches!(err, Error::InvalidInput { field, .. } if field == "supported_working_sets"));
}

#[test]
fn row_container_from_another_context() {
    let a = context(1);
    let b = context(1);
    expect_field(&a, b.create_task_container(), "TaskContainer", "context");
}

#[test]
fn row_geometry_operation() {
    // Update of a geometry never registered.
    geometry_row("operation", |t| t.operation = TaskOperation::Update);
    // Register twice in one container.
    let ctx = context(2);
    let h = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, h, 1.0);
    register_geometry(&mut c, h, 1.0);
    expect_field(&ctx, c, "GeometryTask", "operation");
    // Update without allow_update.
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, h, 1.0);
    build_submit_complete(&ctx, c);
    let (vb, ib) = quad(2.0);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Update,
        handle: h,
        input: geometry_input(vb, Some(ib)),
    });
    expect_field(&ctx, c, "GeometryTask", "operation");
}

/// An `Update` of an `allow_update` geometry replaces its vertices: rays hit where the new
/// vertices are and no longer where the old ones were. Before: the unit quad in z = 0. After:
/// the same triangles scaled by 2 and moved to z = −2 (a refit keeps the topology).
#[test]
fn geometry_update_with_allow_update_replaces_data() {
    let ctx = context(2);
    let h = ctx.create_geometry_handle();
    let instance = ctx.create_instance_handle();
    let quad_at = |scale: f32, z: f32| {
        let p: Vec<[f32; 3]> = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
            .iter()
            .map(|[x, y]| [x * scale, y * scale, z])
            .collect();
        // As `quad`'s buffers.
        let vb = buffer(
            bytemuck::cast_slice(&p),
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_SRC,
        );
        let ib = buffer(
            bytemuck::cast_slice(&[0u32, 1, 2, 0, 2, 3]),
            wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_SRC,
        );
        let mut input = geometry_input(vb, Some(ib));
        input.allow_update = true;
        input
    };
    // From z = 5 straight down: one ray over both quads, one over the big quad only, one past
    // both.
    let rays = [
        rt::ray(Vec3::new(0.5, 0.5, 5.0), -Vec3::Z, 0.0, 100.0),
        rt::ray(Vec3::new(1.5, 1.5, 5.0), -Vec3::Z, 0.0, 100.0),
        rt::ray(Vec3::new(2.5, 0.5, 5.0), -Vec3::Z, 0.0, 100.0),
    ];
    let distances = |ctx: &ExecuteContext| -> Vec<Option<f32>> {
        rt::closest(ctx, &rays)
            .iter()
            .map(|hit| {
                hit.is_hit().then(|| {
                    assert_eq!(hit.instance, instance.index(), "{hit:?}");
                    hit.t
                })
            })
            .collect()
    };
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: h,
        input: quad_at(1.0, 0.0),
    });
    register_instance(&mut c, instance, h, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let before = distances(&ctx);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Update,
        handle: h,
        input: quad_at(2.0, -2.0),
    });
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let after = distances(&ctx);
    assert_eq!(ctx.recorded_task_counts().geometry_tasks, 2);
    let near = |got: &[Option<f32>], want: [Option<f32>; 3]| {
        got.iter().zip(want).all(|(g, w)| match (g, w) {
            (Some(g), Some(w)) => (g - w).abs() < 1e-4,
            (g, w) => g.is_none() && w.is_none(),
        })
    };
    assert!(
        near(&before, [Some(5.0), None, None]),
        "before the update: {before:?}"
    );
    assert!(
        near(&after, [Some(7.0), Some(7.0), None]),
        "after the update: {after:?}"
    );
}

#[test]
fn row_components_empty() {
    geometry_row("input.components", |t| t.input.components.clear());
}

#[test]
fn row_tile_unit_length() {
    geometry_row("input.tile_unit_length", |t| t.input.tile_unit_length = 0.0);
    geometry_row("input.tile_unit_length", |t| {
        t.input.tile_unit_length = f32::NAN
    });
}

#[test]
fn row_tile_resolution_limit() {
    geometry_row("input.tile_resolution_limit", |t| {
        t.input.tile_resolution_limit = 0
    });
}

#[test]
fn row_direct_tile_mapping_threshold() {
    geometry_row("input.direct_tile_mapping_threshold", |t| {
        t.input.direct_tile_mapping_threshold = 1.5
    });
}

#[test]
fn row_vertex_buffer_usage() {
    geometry_row("input.components[0].vertex_buffer.buffer", |t| {
        t.input.components[0].vertex_buffer.buffer = buffer(&[0; 48], wgpu::BufferUsages::VERTEX)
    });
}

#[test]
fn row_vertex_stride() {
    geometry_row("input.components[0].vertex_buffer.stride", |t| {
        t.input.components[0].vertex_buffer.stride = 8
    });
}

#[test]
fn row_vertex_count() {
    geometry_row("input.components[0].vertex_buffer.count", |t| {
        t.input.components[0].vertex_buffer.count = 0
    });
    // Non-indexed with 4 vertices: not a multiple of 3.
    geometry_row("input.components[0].vertex_buffer.count", |t| {
        t.input.components[0].index_buffer = None
    });
}

#[test]
fn row_vertex_offset_past_end() {
    geometry_row("input.components[0].vertex_buffer.offset", |t| {
        t.input.components[0].vertex_buffer.offset = 16
    });
}

#[test]
fn row_component_transform() {
    geometry_row("input.components[0].transform", |t| {
        t.input.components[0].transform = Some(Affine3A::from_translation(Vec3::new(
            f32::INFINITY,
            0.0,
            0.0,
        )))
    });
}

#[test]
fn row_index_buffer_usage() {
    geometry_row("input.components[0].index_buffer.buffer", |t| {
        t.input.components[0].index_buffer.as_mut().unwrap().buffer =
            buffer(&[0; 24], wgpu::BufferUsages::INDEX)
    });
}

#[test]
fn row_index_offset() {
    geometry_row("input.components[0].index_buffer.offset", |t| {
        t.input.components[0].index_buffer.as_mut().unwrap().offset = 2
    });
    geometry_row("input.components[0].index_buffer.offset", |t| {
        t.input.components[0].index_buffer.as_mut().unwrap().offset = 4
    });
}

#[test]
fn row_index_count() {
    geometry_row("input.components[0].index_buffer.count", |t| {
        t.input.components[0].index_buffer.as_mut().unwrap().count = 4
    });
}

#[test]
fn row_index_range() {
    geometry_row("input.components[0].index_range", |t| {
        t.input.components[0].index_range = Some((3, 6))
    });
    geometry_row("input.components[0].index_range", |t| {
        t.input.components[0].index_range = Some((1, 3))
    });
}

#[test]
fn index_range_and_u16_indices_count_triangles() {
    let ctx = context(2);
    let h = ctx.create_geometry_handle();
    let (vb, _) = quad(1.0);
    let idx: [u16; 8] = [0, 1, 2, 0, 2, 3, 0, 0];
    let ib = buffer(
        bytemuck::cast_slice(&idx),
        wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_SRC,
    );
    let mut input = geometry_input(vb, None);
    input.components[0].index_buffer = Some(IndexBufferInput {
        buffer: ib,
        offset: 0,
        count: 6,
        format: IndexFormat::Uint16,
    });
    input.components[0].index_range = Some((3, 3));
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: h,
        input,
    });
    build_submit_complete(&ctx, c);
    assert_eq!(ctx.geometry_triangle_count(h).unwrap(), Some(1));
}

/// The fields of a texture opacity source, editable before it becomes a `ComponentOpacity`
/// (an enum variant has no struct update syntax).
struct Cutout {
    texture: wgpu::TextureView,
    uvs: UvBufferInput,
    channel: u32,
    factor: f32,
    cutoff: f32,
    level: u32,
}

impl Cutout {
    /// A valid cutout of `quad`: a 4×4 `Rgba8Unorm` texture, one `Float32x2` coordinate per
    /// vertex, alpha channel, factor 1, cutoff 0.5, level 4.
    fn valid() -> Self {
        let uv: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        Cutout {
            texture: alpha_texture(F::Rgba8Unorm, U::TEXTURE_BINDING | U::COPY_DST),
            uvs: uv_buffer(bytemuck::cast_slice(&uv), wgpu::BufferUsages::COPY_SRC),
            channel: 3,
            factor: 1.0,
            cutoff: 0.5,
            level: ComponentOpacity::DEFAULT_MICROMAP_LEVEL,
        }
    }

    /// The `ComponentOpacity` these fields make.
    fn opacity(self) -> ComponentOpacity {
        ComponentOpacity {
            source: OpacitySource::Texture {
                texture: self.texture,
                uvs: self.uvs,
                channel: self.channel,
                factor: self.factor,
                cutoff: self.cutoff,
            },
            micromap_level: self.level,
        }
    }
}

/// A 4×4 texture to read alpha from.
fn alpha_texture(format: F, usage: U) -> wgpu::TextureView {
    texture(format, 4, 4, usage)
}

/// `Float32x2` coordinates, 8 bytes apart, in a buffer holding `bytes` (`usage` | `VERTEX`).
fn uv_buffer(bytes: &[u8], usage: wgpu::BufferUsages) -> UvBufferInput {
    UvBufferInput {
        buffer: buffer(bytes, usage | wgpu::BufferUsages::VERTEX),
        offset: 0,
        stride: 8,
        format: UvFormat::Float32x2,
    }
}

/// Gives `quad`'s component the texture opacity `f` makes of a valid one; expects `field`.
fn cutout_row(field: &str, f: impl FnOnce(&mut Cutout)) {
    let mut cutout = Cutout::valid();
    f(&mut cutout);
    let opacity = cutout.opacity();
    geometry_row(field, |t| t.input.components[0].opacity = Some(opacity));
}

/// Gives `quad`'s component (2 triangles) a per-triangle opacity: `bytes` at `offset`; expects
/// `field`.
fn per_triangle_row(field: &str, bytes: &[u8], usage: wgpu::BufferUsages, offset: u64) {
    let opacity = ComponentOpacity::per_triangle(buffer(bytes, usage), offset);
    geometry_row(field, |t| t.input.components[0].opacity = Some(opacity));
}

/// The field path of `quad`'s component's opacity.
const OPACITY: &str = "input.components[0].opacity";

#[test]
fn row_opacity_micromap_level() {
    cutout_row(&format!("{OPACITY}.micromap_level"), |c| c.level = 7);
}

#[test]
fn row_opacity_channel() {
    cutout_row(&format!("{OPACITY}.source.channel"), |c| c.channel = 4);
}

#[test]
fn row_opacity_factor() {
    cutout_row(&format!("{OPACITY}.source.factor"), |c| c.factor = f32::NAN);
    cutout_row(&format!("{OPACITY}.source.factor"), |c| c.factor = -0.5);
    cutout_row(&format!("{OPACITY}.source.factor"), |c| {
        c.factor = f32::INFINITY
    });
}

#[test]
fn row_opacity_cutoff() {
    cutout_row(&format!("{OPACITY}.source.cutoff"), |c| c.cutoff = 1.5);
    cutout_row(&format!("{OPACITY}.source.cutoff"), |c| c.cutoff = f32::NAN);
}

#[test]
fn row_opacity_texture() {
    let field = format!("{OPACITY}.source.texture");
    // Without TEXTURE_BINDING the baking pass cannot read it.
    cutout_row(&field, |c| {
        c.texture = alpha_texture(F::Rgba8Unorm, U::COPY_DST)
    });
    // Depth and integer formats have no float sample type.
    cutout_row(&field, |c| {
        c.texture = alpha_texture(F::Depth32Float, U::TEXTURE_BINDING | U::COPY_DST)
    });
    cutout_row(&field, |c| {
        c.texture = alpha_texture(F::R32Uint, U::TEXTURE_BINDING | U::COPY_DST)
    });
}

#[test]
fn row_opacity_uv_stride() {
    cutout_row(&format!("{OPACITY}.source.uvs.stride"), |c| {
        c.uvs.stride = 4
    });
    // 2^63 × 3 gaps (between 4 vertices) overflow u64: refused on the stride, not wrapped.
    cutout_row(&format!("{OPACITY}.source.uvs.stride"), |c| {
        c.uvs.stride = 1 << 63
    });
}

#[test]
fn row_opacity_uv_buffer() {
    let field = format!("{OPACITY}.source.uvs.buffer");
    // Without COPY_SRC.
    cutout_row(&field, |c| {
        c.uvs = uv_buffer(&[0; 32], wgpu::BufferUsages::empty())
    });
    // 3 coordinates for `quad`'s 4 vertices.
    cutout_row(&field, |c| {
        c.uvs = uv_buffer(&[0; 24], wgpu::BufferUsages::COPY_SRC)
    });
}

#[test]
fn row_opacity_uv_offset() {
    cutout_row(&format!("{OPACITY}.source.uvs.offset"), |c| {
        c.uvs.offset = 8
    });
}

#[test]
fn row_opacity_per_triangle_offset() {
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
    let field = format!("{OPACITY}.source.offset");
    per_triangle_row(&field, &[0; 12], usage, 2);
    // Two flags from byte 4 of an 8-byte buffer.
    per_triangle_row(&field, &[0; 8], usage, 4);
}

#[test]
fn row_opacity_per_triangle_buffer() {
    let field = format!("{OPACITY}.source.buffer");
    // One flag for `quad`'s 2 triangles.
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
    per_triangle_row(&field, &[0; 4], usage, 0);
    per_triangle_row(&field, &[0; 8], wgpu::BufferUsages::STORAGE, 0);
}

/// Valid texture and per-triangle opacities pass validation and register: a per-triangle source
/// ignores `micromap_level` (7 is not refused there), and the UVs may use any format whose
/// stride fits.
#[test]
fn valid_opacity_registers() {
    let ctx = context(2);
    let mut c = ctx.create_task_container();
    let (vb, ib) = quad(1.0);
    let mut handles = Vec::new();
    let mut per_triangle = ComponentOpacity::per_triangle(
        buffer(&[1, 0, 0, 0, 0, 0, 0, 0], wgpu::BufferUsages::COPY_SRC),
        0,
    );
    per_triangle.micromap_level = 7;
    let unorm = Cutout {
        uvs: UvBufferInput {
            stride: 4,
            format: UvFormat::Unorm16x2,
            ..uv_buffer(&[0; 16], wgpu::BufferUsages::COPY_SRC)
        },
        texture: alpha_texture(F::R8Unorm, U::TEXTURE_BINDING | U::COPY_DST),
        channel: 0,
        ..Cutout::valid()
    };
    for opacity in [Cutout::valid().opacity(), unorm.opacity(), per_triangle] {
        let mut input = geometry_input(vb.clone(), Some(ib.clone()));
        input.components[0].opacity = Some(opacity);
        let h = ctx.create_geometry_handle();
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: h,
            input,
        });
        handles.push(h);
    }
    build_submit_complete(&ctx, c);
    for h in handles {
        assert_eq!(ctx.geometry_triangle_count(h).unwrap(), Some(2));
    }
}

fn instance_row(field: &str, f: impl FnOnce(&mut InstanceInput)) {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    let mut input = InstanceInput::new(g, Affine3A::IDENTITY);
    f(&mut input);
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Register,
        handle: ctx.create_instance_handle(),
        input,
    });
    expect_field(&ctx, c, "InstanceTask", field);
}

#[test]
fn row_instance_geometry_unregistered() {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_instance(&mut c, ctx.create_instance_handle(), g, Affine3A::IDENTITY);
    expect_field(&ctx, c, "InstanceTask", "input.geometry");
}

#[test]
fn row_instance_transform() {
    instance_row("input.transform", |i| {
        i.transform = Affine3A::from_translation(Vec3::splat(f32::NAN))
    });
}

#[test]
fn row_instance_inclusion_mask() {
    instance_row("input.inclusion_mask", |i| {
        i.inclusion_mask = InstanceInclusionMask(8)
    });
}

#[test]
fn row_instance_initial_tile_color() {
    instance_row("input.initial_tile_color", |i| {
        i.initial_tile_color = Vec4::new(-1.0, 0.0, 0.0, 1.0)
    });
}

#[test]
fn row_max_blas_build_count() {
    let ctx = context(2);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 0,
        ..Default::default()
    });
    expect_field(&ctx, c, "BvhBuildTask", "max_blas_build_count");
}

fn sampled(w: u32, h: u32) -> wgpu::TextureView {
    texture(F::R32Float, w, h, U::TEXTURE_BINDING)
}

fn output(w: u32, h: u32) -> wgpu::TextureView {
    texture(F::Rgba16Float, w, h, U::STORAGE_BINDING)
}

fn common(w: u32, h: u32) -> TraceTaskCommon {
    TraceTaskCommon::new(
        DepthInput {
            texture: sampled(w, h),
            depth_type: DepthType::RClipSpace,
        },
        NormalInput {
            texture: texture(F::Rgba8Unorm, w, h, U::TEXTURE_BINDING),
            normal_type: NormalType::RgbNormalizedVector,
            normal_to_world: Mat4::IDENTITY,
        },
    )
}

fn ao_task() -> TraceAmbientOcclusionTask {
    TraceAmbientOcclusionTask {
        common: common(16, 16),
        output: output(16, 16),
        ao_radius: 1.0,
    }
}

/// A trace-AO task with one field made bad by `f` must be refused naming `field`.
fn ao_row(field: &str, f: impl FnOnce(&mut TraceAmbientOcclusionTask)) {
    let mut t = ao_task();
    f(&mut t);
    render_row(
        RenderTask::TraceAmbientOcclusion(t),
        "TraceAmbientOcclusionTask",
        field,
    );
}

fn render_row(task: RenderTask, name: &str, field: &str) {
    let ctx = context(2);
    let mut c = ctx.create_task_container();
    c.schedule_render_task(task);
    expect_field(&ctx, c, name, field);
}

#[test]
fn valid_render_task_is_refused_as_unsupported_by_name() {
    let ctx = context(2);
    let mut c = ctx.create_task_container();
    // A debug view the trace tasks do not write yet.
    let mut t = ao_task();
    t.common.debug_parameters.debug_output_type = DebugOutputType::Normal;
    c.schedule_render_task(RenderTask::TraceAmbientOcclusion(t));
    let mut e = encoder();
    assert_eq!(
        ctx.build_gpu_task(c, &mut e),
        Err(Error::Unsupported {
            task: "TraceAmbientOcclusionTask"
        })
    );
    submit(e);
}

#[test]
fn row_trace_output() {
    ao_row("output", |t| {
        t.output = texture(F::Rgba8Unorm, 16, 16, U::STORAGE_BINDING)
    });
    ao_row("output", |t| {
        t.output = texture(F::Rgba16Float, 16, 16, U::TEXTURE_BINDING)
    });
}

#[test]
fn row_trace_inputs_readable() {
    ao_row("common.depth.texture", |t| {
        t.common.depth.texture = texture(F::R32Float, 16, 16, U::STORAGE_BINDING)
    });
    ao_row("common.depth.texture", |t| {
        t.common.depth.texture = texture(F::Depth24PlusStencil8, 16, 16, U::TEXTURE_BINDING)
    });
    // An engine's Depth32Float depth buffer is accepted as is.
    let ctx = context(1);
    let mut t = ao_task();
    t.common.depth.texture = texture(F::Depth32Float, 16, 16, U::TEXTURE_BINDING);
    let mut c = ctx.create_task_container();
    c.schedule_render_task(RenderTask::TraceAmbientOcclusion(t));
    let mut e = encoder();
    let task = ctx
        .build_gpu_task(c, &mut e)
        .expect("Depth32Float depth is accepted");
    submit(e);
    ctx.mark_gpu_task_completed(task).unwrap();
    ao_row("common.environment_map", |t| {
        t.common.environment_map = Some(texture(F::Rgba16Float, 16, 16, U::STORAGE_BINDING))
    });
}

#[test]
fn row_trace_roughness() {
    ao_row("common.roughness.global_roughness", |t| {
        t.common.roughness.global_roughness = 2.0
    });
    let mut t = ao_task();
    t.common.roughness.min_roughness = 0.5;
    t.common.roughness.max_roughness = 0.2;
    render_row(
        RenderTask::TraceAmbientOcclusion(t),
        "TraceAmbientOcclusionTask",
        "common.roughness.max_roughness",
    );
    ao_row("common.roughness.roughness_multiplier", |t| {
        t.common.roughness.roughness_multiplier = f32::NAN
    });
}

#[test]
fn row_trace_metalness() {
    ao_row("common.specular.global_metalness", |t| {
        t.common.specular.global_metalness = -0.1
    });
}

#[test]
fn row_trace_view_matrices() {
    ao_row("common.view.view_to_clip", |t| {
        t.common.view.view_to_clip = Mat4::ZERO
    });
}

#[test]
fn row_trace_max_ray_length() {
    ao_row("common.max_ray_length", |t| t.common.max_ray_length = 0.0);
}

#[test]
fn row_trace_ray_offset() {
    ao_row("common.ray_offset.cam_distance_linear", |t| {
        t.common.ray_offset.cam_distance_linear = f32::INFINITY
    });
}

#[test]
fn row_viewport() {
    ao_row("viewport", |t| {
        t.common.viewport = Some(Viewport {
            x: 8,
            y: 0,
            width: 16,
            height: 16,
        })
    });
    ao_row("viewport", |t| {
        t.common.viewport = Some(Viewport {
            x: 0,
            y: 0,
            width: 0,
            height: 16,
        })
    });
    // Mismatched sizes: output smaller than the G-buffer's full extent.
    ao_row("viewport", |t| t.common.depth.texture = sampled(8, 8));
}

#[test]
fn row_diffuse_ambient_occlusion() {
    let task = |ao: DiffuseAmbientOcclusion| {
        RenderTask::TraceDiffuse(TraceDiffuseTask {
            ambient_occlusion: Some(ao),
            ..TraceDiffuseTask::new(common(16, 16), output(16, 16))
        })
    };
    let name = "TraceDiffuseTask";
    render_row(
        task(DiffuseAmbientOcclusion {
            output: output(16, 16),
            ao_radius: 0.0,
        }),
        name,
        "ambient_occlusion.ao_radius",
    );
    render_row(
        task(DiffuseAmbientOcclusion {
            output: texture(F::Rgba8Unorm, 16, 16, U::STORAGE_BINDING),
            ao_radius: 1.0,
        }),
        name,
        "ambient_occlusion.output",
    );
    render_row(
        task(DiffuseAmbientOcclusion {
            output: output(8, 8),
            ao_radius: 1.0,
        }),
        name,
        "viewport",
    );
}

#[test]
fn row_demodulation_output() {
    let t = TraceSpecularTask {
        common: common(16, 16),
        output: output(16, 16),
        demodulate_specular: true,
        demodulation_output: None,
    };
    render_row(
        RenderTask::TraceSpecular(t),
        "TraceSpecularTask",
        "demodulation_output",
    );
}

#[test]
fn row_ao_radius() {
    ao_row("ao_radius", |t| t.ao_radius = -1.0);
}

#[test]
fn row_shadow_light() {
    let bad = [
        (
            LightInfo::Directional {
                direction: Vec3::new(0.0, 2.0, 0.0),
                angular_extent: 0.01,
            },
            "light.direction",
        ),
        (
            LightInfo::Point {
                position: Vec3::ZERO,
                radius: 0.1,
                range: 0.0,
            },
            "light.range",
        ),
        (
            LightInfo::Spot {
                position: Vec3::ZERO,
                direction: Vec3::Y,
                radius: 0.1,
                range: 5.0,
                apex_angle: 2.0,
            },
            "light.apex_angle",
        ),
    ];
    for (light, field) in bad {
        let t = TraceShadowTask {
            common: common(16, 16),
            output: output(16, 16),
            light,
            enable_first_hit_and_end_search: true,
        };
        render_row(RenderTask::TraceShadow(t), "TraceShadowTask", field);
    }
}

#[test]
fn row_multi_shadow_lights() {
    let light = LightInfo::Point {
        position: Vec3::ZERO,
        radius: 0.1,
        range: 5.0,
    };
    for n in [0, 33] {
        let t = TraceMultiShadowTask {
            common: common(16, 16),
            output0: output(16, 16),
            output1: output(16, 16),
            lights: vec![light; n],
            enable_first_hit_and_end_search: true,
        };
        render_row(
            RenderTask::TraceMultiShadow(t),
            "TraceMultiShadowTask",
            "lights",
        );
    }
}

fn injection() -> DirectLightingInjectionTask {
    DirectLightingInjectionTask::new(
        DepthInput {
            texture: sampled(16, 16),
            depth_type: DepthType::RClipSpace,
        },
        texture(F::Rgba16Float, 16, 16, U::TEXTURE_BINDING),
        ViewInfo::default(),
    )
}

#[test]
fn row_injection_average_window() {
    let mut t = injection();
    t.average_window = 0.5;
    render_row(
        RenderTask::DirectLightingInjection(t),
        "DirectLightingInjectionTask",
        "average_window",
    );
}

#[test]
fn row_injection_stride() {
    let mut t = injection();
    t.injection_resolution_stride = 9;
    render_row(
        RenderTask::DirectLightingInjection(t),
        "DirectLightingInjectionTask",
        "injection_resolution_stride",
    );
}

#[test]
fn row_transfer_same_instance() {
    let ctx = context(2);
    let i = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    c.schedule_render_task(RenderTask::DirectLightTransfer(DirectLightTransferTask {
        source: i,
        target: i,
    }));
    expect_field(&ctx, c, "DirectLightTransferTask", "target");
}

fn denoise_common(ctx: &ExecuteContext) -> DenoiseTaskCommon {
    let c = common(16, 16);
    DenoiseTaskCommon {
        context: ctx
            .create_denoising_context_handle(DenoisingContextInput {
                max_width: 16,
                max_height: 16,
                signal_type: SignalType::Diffuse,
                method: DenoisingMethod::Fast,
            })
            .unwrap(),
        viewport: None,
        depth: c.depth,
        normal: c.normal,
        roughness: RoughnessInput::default(),
        motion: None,
        view: ViewInfo::default(),
        half_resolution_mode: HalfResolutionMode::Off,
        mode: DenoiseMode::Continue,
    }
}

#[test]
fn row_denoise_context_stale() {
    let ctx = context(2);
    let common = denoise_common(&ctx);
    ctx.destroy_denoising_context_handle(common.context)
        .unwrap();
    let mut c = ctx.create_task_container();
    c.schedule_render_task(RenderTask::DenoiseDiffuse(DenoiseDiffuseTask {
        common,
        input: texture(F::Rgba16Float, 16, 16, U::TEXTURE_BINDING),
        output: output(16, 16),
    }));
    let mut e = encoder();
    assert!(matches!(
        ctx.build_gpu_task(c, &mut e),
        Err(Error::InvalidHandle {
            kind: HandleKind::DenoisingContext,
            ..
        })
    ));
    submit(e);
}

#[test]
fn row_denoise_motion_scale() {
    let ctx = context(2);
    let mut common = denoise_common(&ctx);
    common.motion = Some(MotionInput {
        texture: texture(F::Rg32Float, 16, 16, U::TEXTURE_BINDING),
        motion_type: MotionType::RgViewSpace,
        scale: Vec3::splat(f32::NAN),
    });
    let mut c = ctx.create_task_container();
    c.schedule_render_task(RenderTask::DenoiseDiffuse(DenoiseDiffuseTask {
        common,
        input: texture(F::Rgba16Float, 16, 16, U::TEXTURE_BINDING),
        output: output(16, 16),
    }));
    expect_field(&ctx, c, "DenoiseDiffuseTask", "common.motion.scale");
}

#[test]
fn row_denoising_context_size() {
    let ctx = context(1);
    let err = ctx
        .create_denoising_context_handle(DenoisingContextInput {
            max_width: 0,
            max_height: 16,
            signal_type: SignalType::Shadow,
            method: DenoisingMethod::HighQuality,
        })
        .unwrap_err();
    assert!(matches!(err, Error::InvalidInput { field, .. } if field == "max_width/max_height"));
}

#[test]
fn defaults_match_the_reference() {
    let g = GeometryInput::default();
    assert_eq!(
        (
            g.tile_unit_length,
            g.tile_resolution_limit,
            g.direct_tile_mapping_threshold
        ),
        (1.0, 64, 0.7)
    );
    assert_eq!(
        (g.surfel_type, g.build_hint),
        (SurfelType::MeshColors, BuildHint::Auto)
    );
    assert_eq!(
        BvhBuildTask::default(),
        BvhBuildTask {
            max_blas_build_count: 4,
            build_tlas: true,
            tlas_update: TlasUpdate::Auto,
        }
    );
    let r = RoughnessInput::default();
    assert_eq!(
        (
            r.global_roughness,
            r.roughness_multiplier,
            r.min_roughness,
            r.max_roughness
        ),
        (0.3, 1.0, 0.0, 1.0)
    );
    assert_eq!(r.roughness_mask, Vec4::new(0.0, 0.0, 0.0, 1.0));
    assert_eq!(SpecularInput::default().global_metalness, 1.0);
    let o = RayOffset::default();
    assert_eq!(o.offset_type, RayOffsetType::Disabled);
    assert_eq!(
        (
            o.world_position_threshold,
            o.world_position_float_scale,
            o.world_position_int_scale
        ),
        (1.0 / 32.0, 1.0 / 65536.0, 256.0)
    );
    assert_eq!(
        (
            o.cam_distance_constant,
            o.cam_distance_linear,
            o.cam_distance_quadratic
        ),
        (0.00174, -0.0001547, 0.0000996)
    );
    let i = InstanceInput::new(GeometryHandleForDefaults::get(), Affine3A::IDENTITY);
    assert_eq!(
        i.inclusion_mask,
        InstanceInclusionMask::DIRECT_LIGHT_INJECTION_TARGET | InstanceInclusionMask::VISIBLE_IN_RT
    );
    assert!(i.participating_in_tlas);
    assert_eq!(i.initial_tile_color, Vec4::ZERO);
    let inj = injection();
    assert_eq!(
        (inj.average_window, inj.injection_resolution_stride),
        (200.0, 4)
    );
    let c = common(4, 4);
    assert!(c.use_bilinear_sampling && c.max_ray_length.is_infinite());
    assert_eq!(c.half_resolution_mode, HalfResolutionMode::Off);
    assert_eq!(
        c.debug_parameters.random_number_generator,
        RandomNumberGenerator::BlueNoise
    );
    assert_eq!(DenoiseMode::default(), DenoiseMode::Continue);
    assert_eq!(DiffuseBrdf::default(), DiffuseBrdf::Lambertian);
    assert_eq!(MAX_MULTI_SHADOW_LIGHTS, 32);
}

struct GeometryHandleForDefaults;
impl GeometryHandleForDefaults {
    fn get() -> GeometryHandle {
        context(1).create_geometry_handle()
    }
}

#[test]
fn row_major_conversion_helper() {
    let a = affine_from_row_major_3x4([
        [1.0, 0.0, 0.0, 5.0],
        [0.0, 1.0, 0.0, 6.0],
        [0.0, 0.0, 1.0, 7.0],
    ]);
    assert_eq!(a.translation, glam::Vec3A::new(5.0, 6.0, 7.0));
    let b = affine_from_row_major_3x4([
        [0.0, -1.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ]);
    assert!((b.transform_vector3(Vec3::X) - Vec3::Y).length() < 1e-6);
}

#[test]
fn row_instance_operation() {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let i = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Update,
        handle: i,
        input: InstanceInput::new(g, Affine3A::IDENTITY),
    });
    expect_field(&ctx, c, "InstanceTask", "operation");
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    for _ in 0..2 {
        register_instance(&mut c, i, g, Affine3A::IDENTITY);
    }
    expect_field(&ctx, c, "InstanceTask", "operation");
}

/// What a context shows of its state: enough to tell whether a refused task changed anything
/// (registrations, queued builds, instance records, the task serial, memory).
#[derive(Debug, PartialEq)]
struct Observed {
    counts: RecordedTaskCounts,
    in_flight: usize,
    geometries: Vec<(Option<u32>, bool)>,
    has_instance_table: bool,
    allocations: ResourceAllocations,
}

fn observe(ctx: &ExecuteContext, geometries: &[GeometryHandle]) -> Observed {
    Observed {
        counts: ctx.recorded_task_counts(),
        in_flight: ctx.in_flight_task_count(),
        geometries: geometries
            .iter()
            .map(|g| {
                (
                    ctx.geometry_triangle_count(*g).unwrap(),
                    ctx.geometry_is_built(*g).unwrap(),
                )
            })
            .collect(),
        has_instance_table: ctx.instance_table().is_some(),
        allocations: ctx.resource_allocations(),
    }
}

/// A container that registers a geometry and an instance of it, builds, and then asks for
/// `bad`: refused with an error `expected` accepts, it must leave the context exactly as it
/// was (no registration half-applied, no serial taken, no memory grown); the same container
/// without `bad` is then accepted, and its task takes the next serial.
fn refused_task_changes_nothing(
    working_sets: u32,
    bad: impl FnOnce(&ExecuteContext) -> RenderTask,
    expected: impl FnOnce(&Error) -> bool,
) {
    refused_changes_nothing(
        working_sets,
        |ctx, _, c| c.schedule_render_task(bad(ctx)),
        expected,
    );
}

/// [`refused_task_changes_nothing`] with any bad task: `schedule_bad` adds it to the container
/// (given the geometry an earlier task registered and built).
fn refused_changes_nothing(
    working_sets: u32,
    schedule_bad: impl FnOnce(&ExecuteContext, GeometryHandle, &mut TaskContainer),
    expected: impl FnOnce(&Error) -> bool,
) {
    let ctx = context(working_sets);
    // An earlier task the refused one must not disturb.
    let first = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, first, 1.0);
    c.schedule_bvh_task(BvhBuildTask::default());
    let mut e = encoder();
    let earlier = ctx.build_gpu_task(c, &mut e).unwrap();
    submit(e);
    if working_sets > 1 {
        ctx.mark_gpu_task_completed(earlier).unwrap();
    }
    let (geometry, instance) = (ctx.create_geometry_handle(), ctx.create_instance_handle());
    let schedule = |c: &mut TaskContainer| {
        register_geometry(c, geometry, 2.0);
        register_instance(c, instance, geometry, Affine3A::IDENTITY);
        c.schedule_bvh_task(BvhBuildTask::default());
    };
    // wgpu frees what a finished submission used at its next maintenance: settle that first, so
    // the refused task's own submission below cannot change the driver's bytes by itself.
    gpu()
        .device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    let before = observe(&ctx, &[first, geometry]);
    let mut c = ctx.create_task_container();
    schedule(&mut c);
    schedule_bad(&ctx, first, &mut c);
    let mut e = encoder();
    match ctx.build_gpu_task(c, &mut e) {
        Err(err) => assert!(expected(&err), "unexpected error {err:?}"),
        Ok(t) => panic!("task {} accepted", t.serial()),
    }
    submit(e);
    assert_eq!(observe(&ctx, &[first, geometry]), before);
    if working_sets == 1 {
        ctx.mark_gpu_task_completed(earlier).unwrap();
    }
    let mut c = ctx.create_task_container();
    schedule(&mut c);
    let mut e = encoder();
    let t = ctx
        .build_gpu_task(c, &mut e)
        .expect("the same work without the bad task");
    submit(e);
    assert_eq!(t.serial(), earlier.serial() + 1);
    ctx.mark_gpu_task_completed(t).unwrap();
    assert_eq!(ctx.geometry_triangle_count(geometry).unwrap(), Some(2));
}

fn invalid(field: &'static str) -> impl FnOnce(&Error) -> bool {
    move |e| matches!(e, Error::InvalidInput { field: f, .. } if f == field)
}

#[test]
fn injection_of_world_positions_in_a_depth_format_is_refused_before_anything_changes() {
    refused_task_changes_nothing(
        2,
        |_| {
            let mut t = injection();
            t.depth = DepthInput {
                texture: texture(F::Depth32Float, 16, 16, U::TEXTURE_BINDING),
                depth_type: DepthType::RgbWorldSpace,
            };
            RenderTask::DirectLightingInjection(t)
        },
        invalid("depth.depth_type"),
    );
}

/// An injection whose depth cannot be read as depth or float positions (an integer format) is
/// refused by the plan, naming the field, before the container's registrations apply.
#[test]
fn injection_of_integer_depth_is_refused_before_anything_changes() {
    refused_task_changes_nothing(
        2,
        |_| {
            let mut t = injection();
            t.depth.texture = texture(F::R32Uint, 16, 16, U::TEXTURE_BINDING);
            RenderTask::DirectLightingInjection(t)
        },
        invalid("depth.texture"),
    );
}

/// Direct lighting in a depth format (it must be a float colour format) is refused by the
/// plan, naming the field, before anything changes.
#[test]
fn injection_of_direct_lighting_in_a_depth_format_is_refused_before_anything_changes() {
    refused_task_changes_nothing(
        2,
        |_| {
            let mut t = injection();
            t.direct_lighting = texture(F::Depth32Float, 16, 16, U::TEXTURE_BINDING);
            RenderTask::DirectLightingInjection(t)
        },
        invalid("direct_lighting"),
    );
}

/// An injection whose per-pixel accumulation (32 bytes per injected pixel, beside one word
/// per surfel of the cache) exceeds one storage binding is refused by the plan with the stride
/// named, on a device that binds the least the SDK supports (128 MiB): nothing changes, and the
/// same injection at a coarser stride is accepted.
#[test]
fn injection_too_large_for_one_binding_is_refused_before_anything_changes() {
    const LIMIT: u64 = 128 << 20;
    let (device, queue, ctx) = small_binding_context(LIMIT);
    let submit = |e: wgpu::CommandEncoder| {
        queue.submit([e.finish()]);
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    };
    let encoder = || device.create_command_encoder(&Default::default());
    let tex = |format, w, h| {
        device
            .create_texture(&wgpu::TextureDescriptor {
                label: None,
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: U::TEXTURE_BINDING,
                view_formats: &[],
            })
            .create_view(&Default::default())
    };
    // 2048 × 2040 pixels at stride 1: 4.18 M accumulation slots of 32 bytes (133.7 MB) with
    // the cache's 1 MiB of surfel words do not fit 128 MiB; at stride 2 a quarter of it does.
    let (w, h) = (2048, 2040);
    let injection = |stride| {
        let mut t = DirectLightingInjectionTask::new(
            DepthInput {
                texture: tex(F::R32Float, w, h),
                depth_type: DepthType::RClipSpace,
            },
            tex(F::Rgba16Float, w, h),
            ViewInfo::default(),
        );
        t.injection_resolution_stride = stride;
        RenderTask::DirectLightingInjection(t)
    };
    let geometry = ctx.create_geometry_handle();
    let c = register_and_build(
        &ctx,
        (geometry, ctx.create_instance_handle()),
        many_triangles(&device, 2),
    );
    let mut e = encoder();
    let earlier = ctx.build_gpu_task(c, &mut e).unwrap();
    submit(e);
    ctx.mark_gpu_task_completed(earlier).unwrap();
    let before = observe(&ctx, &[geometry]);
    let mut c = ctx.create_task_container();
    c.schedule_render_task(injection(1));
    let mut e = encoder();
    match ctx.build_gpu_task(c, &mut e) {
        Err(Error::InvalidInput {
            task, field, value, ..
        }) => {
            assert_eq!(
                (task, field.as_str(), value.as_str()),
                (
                    "DirectLightingInjectionTask",
                    "injection_resolution_stride",
                    "1"
                )
            );
        }
        other => panic!("expected InvalidInput, got {other:?}"),
    }
    submit(e);
    assert_eq!(observe(&ctx, &[geometry]), before);
    let mut c = ctx.create_task_container();
    c.schedule_render_task(injection(2));
    let mut e = encoder();
    let t = ctx.build_gpu_task(c, &mut e).expect("stride 2 fits");
    submit(e);
    assert_eq!(t.serial(), earlier.serial() + 1);
    ctx.mark_gpu_task_completed(t).unwrap();
}

#[test]
fn refused_for_any_reason_the_context_is_unchanged() {
    // A field rule of a render task.
    refused_task_changes_nothing(
        2,
        |_| {
            let mut t = ao_task();
            t.ao_radius = f32::NAN;
            RenderTask::TraceAmbientOcclusion(t)
        },
        invalid("ao_radius"),
    );
    // A debug view this version does not write.
    refused_task_changes_nothing(
        2,
        |_| {
            let mut t = ao_task();
            t.common.debug_parameters.debug_output_type = DebugOutputType::Normal;
            RenderTask::TraceAmbientOcclusion(t)
        },
        |e| matches!(e, Error::Unsupported { .. }),
    );
    // A destroyed denoising context.
    refused_task_changes_nothing(
        2,
        |ctx| {
            let common = denoise_common(ctx);
            ctx.destroy_denoising_context_handle(common.context)
                .unwrap();
            RenderTask::DenoiseDiffuse(DenoiseDiffuseTask {
                common,
                input: texture(F::Rgba16Float, 16, 16, U::TEXTURE_BINDING),
                output: output(16, 16),
            })
        },
        |e| matches!(e, Error::InvalidHandle { .. }),
    );
    // A transfer between instances no earlier task registered.
    refused_task_changes_nothing(
        2,
        |ctx| {
            RenderTask::DirectLightTransfer(DirectLightTransferTask {
                source: ctx.create_instance_handle(),
                target: ctx.create_instance_handle(),
            })
        },
        invalid("source"),
    );
    // Every working set in flight.
    refused_task_changes_nothing(
        1,
        |_| RenderTask::TraceAmbientOcclusion(ao_task()),
        |e| matches!(e, Error::WorkingSetsExhausted { supported: 1 }),
    );
}

/// A device of the test adapter whose storage buffers bind at most `bytes` bytes, and a context
/// on it.
fn small_binding_context(bytes: u64) -> (wgpu::Device, wgpu::Queue, ExecuteContext) {
    let g = gpu();
    let mut limits = g.device.limits();
    limits.max_storage_buffer_binding_size = bytes;
    let (device, queue) = own_test_device(limits, "kickstart-rt small-binding tests");
    let settings = InitSettings {
        supported_working_sets: 2,
        ..Default::default()
    };
    let ctx = ExecuteContext::new(&device, &queue, settings).expect("context");
    assert_pass_backend(&ctx);
    (device, queue, ctx)
}

/// The record phase allocates as it goes (staged triangles, then the BLAS's triangles and
/// nodes, then its build's scratch ...). A task whose allocation past the first would exceed the
/// device's binding size must be refused by the plan, before the earlier ones changed anything: the context is as it
/// was, then accepts a task that fits, and the next frame traces the scene as it should.
#[test]
fn a_task_past_the_devices_memory_limit_is_refused_and_changes_nothing() {
    // The least binding size the SDK works with (`Limits::default()`'s), whatever the adapter
    // offers.
    const LIMIT: u64 = 128 << 20;
    let (device, queue, ctx) = small_binding_context(LIMIT);
    let submit = |e: wgpu::CommandEncoder| {
        queue.submit([e.finish()]);
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    };
    let encoder = || device.create_command_encoder(&Default::default());
    // An earlier task the refused one must not disturb: the unit quad at z = 0.
    let first = (ctx.create_geometry_handle(), ctx.create_instance_handle());
    let c = register_and_build(&ctx, first, many_triangles(&device, 2));
    let mut e = encoder();
    let earlier = ctx.build_gpu_task(c, &mut e).unwrap();
    submit(e);
    ctx.mark_gpu_task_completed(earlier).unwrap();
    // Down onto the quad; down from above with t_min past it; up from below; beside it.
    let rays = [
        common::rt::ray(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.0, 10.0),
        common::rt::ray(Vec3::new(0.75, 0.25, 1.0), -Vec3::Z, 1.5, 10.0),
        common::rt::ray(Vec3::new(0.75, 0.25, -3.0), Vec3::Z, 0.0, 10.0),
        common::rt::ray(Vec3::new(1.5, 0.5, 1.0), -Vec3::Z, 0.0, 10.0),
    ];
    let hits_at = |h: &GpuHit, t: f32, instance: InstanceHandle| {
        h.is_hit() && (h.t - t).abs() < 1e-5 && h.instance == instance.index()
    };
    let (hits, traced) = trace_on(&device, &queue, &ctx, &rays);
    assert!(hits_at(&hits[0], 1.0, first.1), "{:?}", hits[0]);
    assert!(!hits[1].is_hit(), "{:?}", hits[1]);
    assert!(hits_at(&hits[2], 3.0, first.1), "{:?}", hits[2]);
    assert!(!hits[3].is_hit(), "{:?}", hits[3]);
    // 2.2M triangles: their staged copy and BLAS triangles (48 bytes each, 106 MB) fit the
    // 128 MiB binding, their BLAS nodes (64 bytes each, 141 MB) do not.
    let handles = (ctx.create_geometry_handle(), ctx.create_instance_handle());
    let before = observe(&ctx, &[first.0, handles.0]);
    let c = register_and_build(&ctx, handles, many_triangles(&device, 2_200_000));
    let mut e = encoder();
    match ctx.build_gpu_task(c, &mut e) {
        Err(Error::OutOfDeviceMemory { what, bytes, limit }) => {
            assert_eq!(what, "BLAS nodes of geometry `2200000 triangles`");
            assert_eq!(limit, LIMIT);
            assert!(bytes > LIMIT, "{bytes}");
        }
        other => panic!("expected OutOfDeviceMemory, got {other:?}"),
    }
    submit(e);
    assert_eq!(observe(&ctx, &[first.0, handles.0]), before);
    // 2M triangles: their nodes (128.0 MB) fit, their build's scratch (68 bytes a triangle,
    // 136 MB, bound whole) does not.
    let c = register_and_build(&ctx, handles, many_triangles(&device, 2_000_000));
    let mut e = encoder();
    match ctx.build_gpu_task(c, &mut e) {
        Err(Error::OutOfDeviceMemory { what, bytes, limit }) => {
            assert_eq!(what, "BLAS build scratch of geometry `2000000 triangles`");
            assert_eq!((bytes, limit), (135_999_964, LIMIT));
        }
        other => panic!("expected OutOfDeviceMemory, got {other:?}"),
    }
    submit(e);
    assert_eq!(observe(&ctx, &[first.0, handles.0]), before);
    // The same context accepts the same work at a size that fits, placed 2 below the first.
    let below = Affine3A::from_translation(Vec3::new(0.0, 0.0, -2.0));
    let c = register_and_build_at(&ctx, handles, many_triangles(&device, 1000), below);
    let mut e = encoder();
    let t = ctx.build_gpu_task(c, &mut e).expect("a task that fits");
    submit(e);
    assert_eq!(t.serial(), traced + 1);
    ctx.mark_gpu_task_completed(t).unwrap();
    assert_eq!(ctx.geometry_triangle_count(handles.0).unwrap(), Some(1000));
    assert!(ctx.geometry_is_built(handles.0).unwrap());
    // The next frame sees both quads: the first where it was, the new one below it.
    let (hits, _) = trace_on(&device, &queue, &ctx, &rays);
    assert!(hits_at(&hits[0], 1.0, first.1), "{:?}", hits[0]);
    assert!(hits_at(&hits[1], 3.0, handles.1), "{:?}", hits[1]);
    assert!(hits_at(&hits[2], 1.0, handles.1), "{:?}", hits[2]);
    assert!(!hits[3].is_hit(), "{:?}", hits[3]);
}

/// One field of one task made invalid, for the property test below.
#[derive(Debug, Clone)]
enum Bad {
    TileUnitLength(f32),
    DirectTileMappingThreshold(f32),
    VertexStride(u64),
    VertexOffset(u64),
    VertexCount(u32),
    ComponentTransform(usize, f32),
    IndexOffset(u64),
    IndexCount(u32),
    InstanceTransform(usize, f32),
    InitialTileColor(usize, f32),
    AoRadius(f32),
    MaxRayLength(f32),
    RayOffset(f32),
    Viewport(u32, u32, u32, u32),
    InjectionStride(u32),
    InjectionAverageWindow(f32),
    DenoiseMotionScale(usize, f32),
}

/// A float that is not finite.
fn non_finite() -> impl Strategy<Value = f32> {
    prop::sample::select(vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY])
}

/// A float that is not finite or not above 0.
fn not_positive() -> impl Strategy<Value = f32> {
    prop_oneof![non_finite(), Just(0.0f32), -1.0e9f32..=0.0]
}

fn bad_task() -> impl Strategy<Value = Bad> {
    prop_oneof![
        not_positive().prop_map(Bad::TileUnitLength),
        prop_oneof![non_finite(), 1.0001f32..100.0, -100.0f32..-0.0001]
            .prop_map(Bad::DirectTileMappingThreshold),
        // Extreme values as well as slightly wrong ones: a stride whose product with the count
        // passes u64 must be refused, not wrap to a length the bounds check accepts.
        prop_oneof![0u64..12, (u64::MAX / 3 + 1)..=u64::MAX].prop_map(Bad::VertexStride),
        prop_oneof![(1u64..64).prop_map(|k| 4 * k), (u64::MAX - 4096)..=u64::MAX]
            .prop_map(Bad::VertexOffset),
        prop_oneof![5u32..1000, (u32::MAX - 1000)..=u32::MAX].prop_map(Bad::VertexCount),
        (0usize..12, non_finite()).prop_map(|(k, v)| Bad::ComponentTransform(k, v)),
        prop_oneof![1u64..10_000, (u64::MAX - 4096)..=u64::MAX].prop_map(Bad::IndexOffset),
        prop::sample::select(vec![
            1u32,
            2,
            4,
            5,
            7,
            8,
            9,
            3_000_000_000,
            u32::MAX - 3,
            u32::MAX
        ])
        .prop_map(Bad::IndexCount),
        (0usize..12, non_finite()).prop_map(|(k, v)| Bad::InstanceTransform(k, v)),
        (0usize..4, prop_oneof![non_finite(), -1.0e9f32..-1.0e-6])
            .prop_map(|(k, v)| Bad::InitialTileColor(k, v)),
        not_positive().prop_map(Bad::AoRadius),
        // +∞ is a valid length (rays without a limit).
        prop_oneof![
            prop::sample::select(vec![f32::NAN, f32::NEG_INFINITY, 0.0]),
            -1.0e9f32..=0.0
        ]
        .prop_map(Bad::MaxRayLength),
        non_finite().prop_map(Bad::RayOffset),
        prop_oneof![
            (1u32..16, 0u32..16).prop_map(|(x, y)| Bad::Viewport(x, y, 16, 16)),
            (0u32..16).prop_map(|y| Bad::Viewport(0, y, 0, 8)),
            (0u32..16).prop_map(|x| Bad::Viewport(x, 0, 8, 0)),
        ],
        (9u32..10_000).prop_map(Bad::InjectionStride),
        prop_oneof![non_finite(), -10.0f32..0.99].prop_map(Bad::InjectionAverageWindow),
        (0usize..3, non_finite()).prop_map(|(k, v)| Bad::DenoiseMotionScale(k, v)),
    ]
}

/// An affine transform with element `k` of its 3×4 matrix set to `v`.
fn affine_with(k: usize, v: f32) -> Affine3A {
    let mut cols = Affine3A::IDENTITY.to_cols_array();
    cols[k] = v;
    Affine3A::from_cols_array(&cols)
}

/// Schedules `bad` into `c` (instances of `geometry`, which an earlier task built); returns the
/// field the refusal must name.
fn schedule(
    bad: &Bad,
    ctx: &ExecuteContext,
    geometry: GeometryHandle,
    c: &mut TaskContainer,
) -> String {
    let geometry_task = |f: &dyn Fn(&mut GeometryInput)| {
        let (vb, ib) = quad(1.0);
        let mut input = geometry_input(vb, Some(ib));
        f(&mut input);
        GeometryTask {
            operation: TaskOperation::Register,
            handle: ctx.create_geometry_handle(),
            input,
        }
    };
    let instance_task = |f: &dyn Fn(&mut InstanceInput)| {
        let mut input = InstanceInput::new(geometry, Affine3A::IDENTITY);
        f(&mut input);
        InstanceTask {
            operation: TaskOperation::Register,
            handle: ctx.create_instance_handle(),
            input,
        }
    };
    let component = "input.components[0]";
    let field = match bad.clone() {
        Bad::TileUnitLength(v) => {
            c.schedule_bvh_task(geometry_task(&|i| i.tile_unit_length = v));
            "input.tile_unit_length".to_string()
        }
        Bad::DirectTileMappingThreshold(v) => {
            c.schedule_bvh_task(geometry_task(&|i| i.direct_tile_mapping_threshold = v));
            "input.direct_tile_mapping_threshold".to_string()
        }
        Bad::VertexStride(v) => {
            c.schedule_bvh_task(geometry_task(&|i| i.components[0].vertex_buffer.stride = v));
            format!("{component}.vertex_buffer.stride")
        }
        Bad::VertexOffset(v) => {
            c.schedule_bvh_task(geometry_task(&|i| i.components[0].vertex_buffer.offset = v));
            format!("{component}.vertex_buffer.offset")
        }
        Bad::VertexCount(v) => {
            c.schedule_bvh_task(geometry_task(&|i| i.components[0].vertex_buffer.count = v));
            format!("{component}.vertex_buffer.count")
        }
        Bad::ComponentTransform(k, v) => {
            c.schedule_bvh_task(geometry_task(&|i| {
                i.components[0].transform = Some(affine_with(k, v))
            }));
            format!("{component}.transform")
        }
        Bad::IndexOffset(v) => {
            c.schedule_bvh_task(geometry_task(&|i| {
                if let Some(ib) = i.components[0].index_buffer.as_mut() {
                    ib.offset = v;
                }
            }));
            format!("{component}.index_buffer.offset")
        }
        Bad::IndexCount(v) => {
            c.schedule_bvh_task(geometry_task(&|i| {
                if let Some(ib) = i.components[0].index_buffer.as_mut() {
                    ib.count = v;
                }
            }));
            format!("{component}.index_buffer.count")
        }
        Bad::InstanceTransform(k, v) => {
            c.schedule_bvh_task(instance_task(&|i| i.transform = affine_with(k, v)));
            "input.transform".to_string()
        }
        Bad::InitialTileColor(k, v) => {
            c.schedule_bvh_task(instance_task(&|i| i.initial_tile_color[k] = v));
            "input.initial_tile_color".to_string()
        }
        _ => {
            let (task, field) = render_task(bad, ctx);
            c.schedule_render_task(task);
            field.to_string()
        }
    };
    field
}

/// The render task of a render-task `bad` and the field its refusal must name.
fn render_task(bad: &Bad, ctx: &ExecuteContext) -> (RenderTask, &'static str) {
    match bad.clone() {
        Bad::AoRadius(v) => {
            let mut t = ao_task();
            t.ao_radius = v;
            (RenderTask::TraceAmbientOcclusion(t), "ao_radius")
        }
        Bad::MaxRayLength(v) => {
            let mut t = ao_task();
            t.common.max_ray_length = v;
            (
                RenderTask::TraceAmbientOcclusion(t),
                "common.max_ray_length",
            )
        }
        Bad::RayOffset(v) => {
            let mut t = ao_task();
            t.common.ray_offset.cam_distance_linear = v;
            (
                RenderTask::TraceAmbientOcclusion(t),
                "common.ray_offset.cam_distance_linear",
            )
        }
        Bad::Viewport(x, y, width, height) => {
            let mut t = ao_task();
            t.common.viewport = Some(Viewport {
                x,
                y,
                width,
                height,
            });
            (RenderTask::TraceAmbientOcclusion(t), "viewport")
        }
        Bad::InjectionStride(v) => {
            let mut t = injection();
            t.injection_resolution_stride = v;
            (
                RenderTask::DirectLightingInjection(t),
                "injection_resolution_stride",
            )
        }
        Bad::InjectionAverageWindow(v) => {
            let mut t = injection();
            t.average_window = v;
            (RenderTask::DirectLightingInjection(t), "average_window")
        }
        Bad::DenoiseMotionScale(k, v) => {
            let mut common = denoise_common(ctx);
            let mut scale = Vec3::ONE;
            scale[k] = v;
            common.motion = Some(MotionInput {
                texture: texture(F::Rg32Float, 16, 16, U::TEXTURE_BINDING),
                motion_type: MotionType::RgViewSpace,
                scale,
            });
            let task = RenderTask::DenoiseDiffuse(DenoiseDiffuseTask {
                common,
                input: texture(F::Rgba16Float, 16, 16, U::TEXTURE_BINDING),
                output: output(16, 16),
            });
            (task, "common.motion.scale")
        }
        other => unreachable!("{other:?} is not a render task"),
    }
}

proptest! {
    #![proptest_config(common::proptest_config(32))]

    /// Random invalid tasks of every kind (geometry, instance, trace, injection, denoise), each
    /// among valid work in one container: refused with `InvalidInput` naming the bad field, and
    /// the context exactly as it was (registrations, queued builds, serials, memory); the same
    /// container without the bad task is then accepted.
    #[test]
    fn random_invalid_tasks_are_refused_by_field_and_change_nothing(bad in bad_task()) {
        let field = std::cell::RefCell::new(String::new());
        refused_changes_nothing(
            2,
            |ctx, geometry, c| *field.borrow_mut() = schedule(&bad, ctx, geometry, c),
            |e| matches!(e, Error::InvalidInput { field: f, .. } if *f == *field.borrow()),
        );
    }
}

/// A valid skinning task of 3 vertices (one joint, full weight), its buffers storage-bound.
fn skinning_task() -> SkinningTask {
    let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
    let rest = buffer(bytemuck::cast_slice(&[0.5f32; 9]), storage);
    let joints = buffer(bytemuck::cast_slice(&[0u16; 12]), storage);
    let weights = buffer(bytemuck::cast_slice(&[[1.0f32, 0.0, 0.0, 0.0]; 3]), storage);
    let out = buffer(&[0u8; 36], storage);
    SkinningTask {
        name: "skin".into(),
        rest_positions: SkinAttribute {
            buffer: rest,
            offset: 0,
            stride: 12,
            format: VertexFormat::Float32x3,
        },
        vertex_count: 3,
        influences: Some(SkinInfluences {
            joints: SkinAttribute {
                buffer: joints,
                offset: 0,
                stride: 8,
                format: JointFormat::Uint16x4,
            },
            weights: SkinAttribute {
                buffer: weights,
                offset: 0,
                stride: 16,
                format: WeightFormat::Float32x4,
            },
        }),
        joint_matrices: vec![Mat4::from_translation(Vec3::X)],
        morph_targets: None,
        morph_weights: Vec::new(),
        output: SkinningOutput {
            buffer: out,
            offset: 0,
            stride: 12,
        },
    }
}

fn skinning_row(field: &str, f: impl FnOnce(&mut SkinningTask)) {
    let ctx = context(2);
    let mut t = skinning_task();
    f(&mut t);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(t);
    expect_field(&ctx, c, "SkinningTask", field);
}

#[test]
fn row_skinning_layouts() {
    skinning_row("rest_positions.format", |t| {
        t.rest_positions.format = VertexFormat::Float16x4
    });
    skinning_row("rest_positions.offset", |t| t.rest_positions.offset = 2);
    skinning_row("rest_positions.offset", |t| t.rest_positions.offset = 4);
    skinning_row("influences.joints.stride", |t| {
        if let Some(i) = &mut t.influences {
            i.joints.stride = 4;
        }
    });
    skinning_row("influences.weights.offset", |t| {
        if let Some(i) = &mut t.influences {
            i.weights.offset = 16;
        }
    });
    skinning_row("output.stride", |t| t.output.stride = 10);
    skinning_row("output.offset", |t| t.output.offset = 4);
}

#[test]
fn row_skinning_buffers() {
    skinning_row("influences.joints.buffer", |t| {
        if let Some(i) = &mut t.influences {
            i.joints.buffer = buffer(&[0u8; 24], wgpu::BufferUsages::COPY_SRC);
        }
    });
    skinning_row("output.buffer", |t| {
        t.output.buffer = t.rest_positions.buffer.clone()
    });
}

#[test]
fn row_skinning_matrices_and_weights() {
    skinning_row("joint_matrices[1]", |t| {
        t.joint_matrices
            .push(Mat4::from_translation(Vec3::new(f32::NAN, 0.0, 0.0)))
    });
    skinning_row("joint_matrices", |t| t.joint_matrices.clear());
    skinning_row("morph_weights", |t| t.morph_weights.push(1.0));
    skinning_row("morph_weights[0]", |t| {
        t.morph_targets = Some(MorphTargetsInput {
            buffer: t.rest_positions.buffer.clone(),
            offset: 0,
            stride: 12,
            target_stride: 36,
            count: 1,
        });
        t.morph_weights = vec![f32::INFINITY];
    });
    skinning_row("morph_targets.count", |t| {
        t.morph_targets = Some(MorphTargetsInput {
            buffer: t.rest_positions.buffer.clone(),
            offset: 0,
            stride: 12,
            target_stride: 0,
            count: SkinningTask::MAX_MORPH_TARGETS + 1,
        });
    });
}

/// A refused skinning task leaves the output it names untouched and the context usable: the
/// same task, corrected, then poses the vertices.
#[test]
fn a_refused_skinning_task_writes_nothing() {
    let ctx = context(2);
    let mut bad = skinning_task();
    bad.joint_matrices[0].x_axis.y = f32::NAN;
    let out = bad.output.buffer.clone();
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(bad.clone());
    let mut e = encoder();
    assert!(matches!(
        ctx.build_gpu_task(c, &mut e),
        Err(Error::InvalidInput { .. })
    ));
    submit(e);
    assert_eq!(read_buffer(&out), vec![0u8; 36]);
    bad.joint_matrices[0] = Mat4::from_translation(Vec3::X);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(bad);
    build_submit_complete(&ctx, c);
    let posed: Vec<f32> = bytemuck::pod_collect_to_vec(&read_buffer(&out));
    assert_eq!(posed, [1.5, 0.5, 0.5, 1.5, 0.5, 0.5, 1.5, 0.5, 0.5]);
}
