//! Field validation of render tasks: textures, viewports, views, lights and each task's own
//! fields.

use super::{finite, in_range, positive};
use crate::cache::inject::float_kind;
use crate::error::{Error, Result};
use crate::tasks::*;

fn texture_size(t: &TextureInput) -> (u32, u32) {
    let s = t.texture().size();
    (s.width, s.height)
}

fn readable(task: &'static str, field: &str, t: &TextureInput) -> Result<()> {
    if !t
        .texture()
        .usage()
        .contains(wgpu::TextureUsages::TEXTURE_BINDING)
    {
        return Err(Error::input(
            task,
            field,
            t.texture().usage(),
            "the SDK reads this texture in a shader: it needs TextureUsages::TEXTURE_BINDING",
        ));
    }
    // Depth formats are fine (WGSL compute reads them as texture_depth_2d with textureLoad).
    // Combined depth-stencil formats are refused: wgpu does not expose a view's aspect, so we
    // cannot check that a view selects depth only.
    let format = t.texture().format();
    if format.is_combined_depth_stencil_format() {
        return Err(Error::input(task, field, format, "combined depth-stencil formats are not accepted: use a Depth32Float depth buffer, or copy depth to R32Float"));
    }
    // Every input is read as unfilterable float (shaders/trace/gbuffer.wgsl): integer formats cannot
    // bind that way.
    if matches!(
        format.sample_type(None, None),
        None | Some(wgpu::TextureSampleType::Uint | wgpu::TextureSampleType::Sint)
    ) {
        return Err(Error::input(
            task,
            field,
            format,
            "the SDK reads this texture as float: use a float, unorm, snorm or depth format",
        ));
    }
    if t.texture().sample_count() != 1 {
        return Err(Error::input(
            task,
            field,
            format!("sample_count {}", t.texture().sample_count()),
            "multisampled textures are not accepted: resolve them first",
        ));
    }
    if t.texture().dimension() != wgpu::TextureDimension::D2 {
        return Err(Error::input(
            task,
            field,
            t.texture().dimension(),
            "must be a 2D texture",
        ));
    }
    Ok(())
}

fn writable(task: &'static str, field: &str, t: &TextureInput) -> Result<()> {
    if !t
        .texture()
        .usage()
        .contains(wgpu::TextureUsages::STORAGE_BINDING)
    {
        return Err(Error::input(task, field, t.texture().usage(), "the SDK writes this texture from a compute shader: it needs TextureUsages::STORAGE_BINDING"));
    }
    if !WRITABLE_OUTPUT_FORMATS.contains(&t.texture().format()) {
        return Err(Error::input(
            task,
            field,
            t.texture().format(),
            format!("output formats are {WRITABLE_OUTPUT_FORMATS:?}"),
        ));
    }
    Ok(())
}

/// The multi-shadow outputs pack per-light data into four channels (docs/trace-tasks.md).
fn four_channels(task: &'static str, field: &str, t: &TextureInput) -> Result<()> {
    let format = t.texture().format();
    if matches!(
        format,
        wgpu::TextureFormat::Rgba16Float | wgpu::TextureFormat::Rgba32Float
    ) {
        return Ok(());
    }
    Err(Error::input(
        task,
        field,
        format,
        "the packed multi-shadow format needs four channels: Rgba16Float or Rgba32Float",
    ))
}

/// Checks a viewport against the textures it addresses; returns the effective one.
fn viewport(
    task: &'static str,
    vp: Option<Viewport>,
    textures: &[(&str, &TextureInput)],
) -> Result<Viewport> {
    let Some((_, first)) = textures.first() else {
        return Ok(vp.unwrap_or_default());
    };
    let (w, h) = texture_size(first);
    let vp = vp.unwrap_or(Viewport {
        x: 0,
        y: 0,
        width: w,
        height: h,
    });
    if vp.width == 0 || vp.height == 0 {
        return Err(Error::input(
            task,
            "viewport",
            vp,
            "width and height must be > 0",
        ));
    }
    for (name, t) in textures {
        let (tw, th) = texture_size(t);
        if vp.x as u64 + vp.width as u64 > tw as u64 || vp.y as u64 + vp.height as u64 > th as u64 {
            return Err(Error::input(
                task,
                "viewport",
                vp,
                format!("exceeds `{name}` ({tw}×{th})"),
            ));
        }
    }
    Ok(vp)
}

fn matrices(task: &'static str, field: &str, v: &ViewInfo) -> Result<()> {
    for (n, m) in [
        ("world_to_view", v.world_to_view),
        ("view_to_clip", v.view_to_clip),
        ("prev_world_to_view", v.prev_world_to_view),
        ("prev_view_to_clip", v.prev_view_to_clip),
    ] {
        if !m.is_finite() || m.determinant() == 0.0 {
            return Err(Error::input(
                task,
                format!("{field}.{n}"),
                m,
                "must be finite and invertible",
            ));
        }
    }
    if !v.jitter.is_finite() {
        return Err(Error::input(
            task,
            format!("{field}.jitter"),
            v.jitter,
            "must be finite",
        ));
    }
    Ok(())
}

fn roughness(task: &'static str, r: &RoughnessInput, field: &str) -> Result<()> {
    if let Some(t) = &r.texture {
        readable(task, &format!("{field}.texture"), t)?;
    }
    if !r.roughness_mask.is_finite() {
        return Err(Error::input(
            task,
            format!("{field}.roughness_mask"),
            r.roughness_mask,
            "must be finite",
        ));
    }
    in_range(
        task,
        (field, ".global_roughness"),
        r.global_roughness,
        0.0,
        1.0,
    )?;
    finite(
        task,
        (field, ".roughness_multiplier"),
        r.roughness_multiplier,
    )?;
    in_range(task, (field, ".min_roughness"), r.min_roughness, 0.0, 1.0)?;
    in_range(
        task,
        (field, ".max_roughness"),
        r.max_roughness,
        r.min_roughness,
        1.0,
    )
}

/// The checks every trace task shares, starting with its (first) output `(field, texture)`.
fn trace_common(
    task: &'static str,
    c: &TraceTaskCommon,
    (output_field, output): (&str, &TextureInput),
) -> Result<()> {
    writable(task, output_field, output)?;
    readable(task, "common.depth.texture", &c.depth.texture)?;
    readable(task, "common.normal.texture", &c.normal.texture)?;
    if !c.normal.normal_to_world.is_finite() {
        return Err(Error::input(
            task,
            "common.normal.normal_to_world",
            c.normal.normal_to_world,
            "must be finite",
        ));
    }
    roughness(task, &c.roughness, "common.roughness")?;
    if let Some(t) = &c.specular.texture {
        readable(task, "common.specular.texture", t)?;
    }
    in_range(
        task,
        ("common.specular.", "global_metalness"),
        c.specular.global_metalness,
        0.0,
        1.0,
    )?;
    for (n, t) in [
        ("common.input_mask", &c.input_mask),
        ("common.direct_lighting", &c.direct_lighting),
        ("common.environment_map", &c.environment_map),
    ] {
        if let Some(t) = t {
            readable(task, n, t)?;
        }
    }
    matrices(task, "common.view", &c.view)?;
    positive(task, ("common.", "max_ray_length"), c.max_ray_length)?;
    let o = &c.ray_offset;
    for (n, v) in [
        ("world_position_threshold", o.world_position_threshold),
        ("world_position_float_scale", o.world_position_float_scale),
        ("world_position_int_scale", o.world_position_int_scale),
        ("cam_distance_constant", o.cam_distance_constant),
        ("cam_distance_linear", o.cam_distance_linear),
        ("cam_distance_quadratic", o.cam_distance_quadratic),
    ] {
        finite(task, ("common.ray_offset.", n), v)?;
    }
    let mut tex: Vec<(&str, &TextureInput)> = vec![
        (output_field, output),
        ("common.depth.texture", &c.depth.texture),
        ("common.normal.texture", &c.normal.texture),
    ];
    if let Some(m) = &c.input_mask {
        tex.push(("common.input_mask", m));
    }
    if let Some(d) = &c.direct_lighting {
        tex.push(("common.direct_lighting", d));
    }
    viewport(task, c.viewport, &tex)?;
    Ok(())
}

fn denoise_common(
    task: &'static str,
    c: &DenoiseTaskCommon,
    io: &[(&str, &TextureInput, bool)],
) -> Result<()> {
    readable(task, "common.depth.texture", &c.depth.texture)?;
    readable(task, "common.normal.texture", &c.normal.texture)?;
    roughness(task, &c.roughness, "common.roughness")?;
    if let Some(m) = &c.motion {
        readable(task, "common.motion.texture", &m.texture)?;
        if !m.scale.is_finite() {
            return Err(Error::input(
                task,
                "common.motion.scale",
                m.scale,
                "must be finite",
            ));
        }
    }
    matrices(task, "common.view", &c.view)?;
    let mut tex = Vec::new();
    for (n, t, write) in io {
        if *write {
            writable(task, n, t)?;
        } else {
            readable(task, n, t)?;
        }
        tex.push((*n, *t));
    }
    tex.push(("common.depth.texture", &c.depth.texture));
    viewport(task, c.viewport, &tex)?;
    Ok(())
}

fn light(task: &'static str, field: &str, l: &LightInfo) -> Result<()> {
    let unit = |n: &str, v: glam::Vec3| {
        if v.is_finite() && (v.length() - 1.0).abs() <= 1e-3 {
            Ok(())
        } else {
            Err(Error::input(
                task,
                format!("{field}.{n}"),
                v,
                "must be a finite unit vector",
            ))
        }
    };
    // Point and spot lights: a finite position, a radius ≥ 0 and a range > 0.
    let emitter = |position: glam::Vec3, radius: f32, range: f32| {
        if !position.is_finite() {
            return Err(Error::input(
                task,
                format!("{field}.position"),
                position,
                "must be finite",
            ));
        }
        in_range(task, (field, ".radius"), radius, 0.0, f32::MAX)?;
        positive(task, (field, ".range"), range)
    };
    match *l {
        LightInfo::Directional {
            direction,
            angular_extent,
        } => {
            unit("direction", direction)?;
            in_range(
                task,
                (field, ".angular_extent"),
                angular_extent,
                0.0,
                std::f32::consts::PI,
            )
        }
        LightInfo::Point {
            position,
            radius,
            range,
        } => emitter(position, radius, range),
        LightInfo::Spot {
            position,
            direction,
            radius,
            range,
            apex_angle,
        } => {
            emitter(position, radius, range)?;
            unit("direction", direction)?;
            if apex_angle > 0.0 && apex_angle <= std::f32::consts::FRAC_PI_2 {
                Ok(())
            } else {
                Err(Error::input(
                    task,
                    format!("{field}.apex_angle"),
                    apex_angle,
                    "must be in (0, π/2]",
                ))
            }
        }
    }
}

/// A buffer a [`TraceRaysTask`] binds as storage: usage, alignment and extent.
fn ray_buffer(
    task: &'static str,
    field: &str,
    buffer: &wgpu::Buffer,
    offset: u64,
    bytes: u64,
    limits: &wgpu::Limits,
) -> Result<()> {
    if !buffer.usage().contains(wgpu::BufferUsages::STORAGE) {
        return Err(Error::input(
            task,
            field,
            buffer.usage(),
            "needs BufferUsages::STORAGE (the SDK binds it as a storage buffer)",
        ));
    }
    let align = limits.min_storage_buffer_offset_alignment.max(1) as u64;
    if !offset.is_multiple_of(align) {
        return Err(Error::input(
            task,
            format!("{field}_offset"),
            offset,
            format!(
                "must be a multiple of the device's min_storage_buffer_offset_alignment ({align})"
            ),
        ));
    }
    if offset.checked_add(bytes).is_none_or(|e| e > buffer.size()) {
        return Err(Error::input(
            task,
            format!("{field}_offset"),
            offset,
            format!(
                "ray_count × 32 = {bytes} bytes from this offset exceed the buffer's {} bytes",
                buffer.size()
            ),
        ));
    }
    if bytes > limits.max_storage_buffer_binding_size {
        return Err(Error::input(
            task,
            "ray_count",
            bytes / 32,
            format!(
                "the batch exceeds the device's max_storage_buffer_binding_size ({} bytes); split it",
                limits.max_storage_buffer_binding_size
            ),
        ));
    }
    Ok(())
}

/// Validates a render task's own fields (handles are checked by the context).
pub(crate) fn render_task(task: &RenderTask, limits: &wgpu::Limits) -> Result<()> {
    let name = task.name();
    match task {
        RenderTask::TraceRays(t) => trace_rays(name, t, limits),
        RenderTask::DirectLightingInjection(t) => injection(name, t),
        RenderTask::DirectLightTransfer(t) if t.source == t.target => Err(Error::input(
            name,
            "target",
            t.target,
            "source and target must differ",
        )),
        RenderTask::DirectLightTransfer(_) => Ok(()),
        RenderTask::TraceSpecular(t) => specular(name, t),
        RenderTask::TraceDiffuse(t) => diffuse(name, t),
        RenderTask::TraceAmbientOcclusion(t) => {
            trace_common(name, &t.common, ("output", &t.output))?;
            if !t.ao_radius.is_finite() || t.ao_radius <= 0.0 {
                return Err(Error::input(
                    name,
                    "ao_radius",
                    t.ao_radius,
                    "must be finite and > 0 (world units)",
                ));
            }
            Ok(())
        }
        RenderTask::TraceShadow(t) => {
            trace_common(name, &t.common, ("output", &t.output))?;
            light(name, "light", &t.light)
        }
        RenderTask::TraceMultiShadow(t) => multi_shadow(name, t),
        denoise => denoise_task(name, denoise),
    }
}

fn trace_rays(name: &'static str, t: &TraceRaysTask, limits: &wgpu::Limits) -> Result<()> {
    let bytes = t.ray_count as u64 * 32;
    ray_buffer(name, "rays", &t.rays, t.ray_offset, bytes, limits)?;
    ray_buffer(name, "hits", &t.hits, t.hit_offset, bytes, limits)?;
    if t.instance_mask.0 & !InstanceInclusionMask::ALL.0 != 0 {
        return Err(Error::input(
            name,
            "instance_mask",
            t.instance_mask.0,
            "only bits 0–1 (InstanceInclusionMask::ALL) are defined",
        ));
    }
    Ok(())
}

fn injection(name: &'static str, t: &DirectLightingInjectionTask) -> Result<()> {
    readable(name, "depth.texture", &t.depth.texture)?;
    readable(name, "direct_lighting", &t.direct_lighting)?;
    let depth_format = t.depth.texture.texture().format();
    let Some(depth_is_depth) = float_kind(depth_format) else {
        return Err(Error::input(
            name,
            "depth.texture",
            depth_format,
            "must be a depth format or a float colour format",
        ));
    };
    let light_format = t.direct_lighting.texture().format();
    if float_kind(light_format) != Some(false) {
        return Err(Error::input(
            name,
            "direct_lighting",
            light_format,
            "must be a float colour format",
        ));
    }
    if t.depth.depth_type == DepthType::RgbWorldSpace && depth_is_depth {
        return Err(Error::input(
            name,
            "depth.depth_type",
            t.depth.depth_type,
            "RgbWorldSpace needs a float colour texture holding positions",
        ));
    }
    matrices(name, "view", &t.view)?;
    if t.average_window.is_nan() || t.average_window < 1.0 || t.average_window.is_infinite() {
        return Err(Error::input(
            name,
            "average_window",
            t.average_window,
            "must be finite and ≥ 1",
        ));
    }
    if !(1..=8).contains(&t.injection_resolution_stride) {
        return Err(Error::input(
            name,
            "injection_resolution_stride",
            t.injection_resolution_stride,
            "must be in 1..=8",
        ));
    }
    viewport(
        name,
        t.viewport,
        &[
            ("direct_lighting", &t.direct_lighting),
            ("depth.texture", &t.depth.texture),
        ],
    )?;
    Ok(())
}

fn specular(name: &'static str, t: &TraceSpecularTask) -> Result<()> {
    trace_common(name, &t.common, ("output", &t.output))?;
    match (&t.demodulation_output, t.demodulate_specular) {
        (Some(o), _) => {
            writable(name, "demodulation_output", o)?;
            viewport(
                name,
                t.common.viewport,
                &[("output", &t.output), ("demodulation_output", o)],
            )?;
            Ok(())
        }
        (None, true) => Err(Error::input(
            name,
            "demodulation_output",
            "None",
            "demodulate_specular needs a demodulation output",
        )),
        (None, false) => Ok(()),
    }
}

fn diffuse(name: &'static str, t: &TraceDiffuseTask) -> Result<()> {
    trace_common(name, &t.common, ("output", &t.output))?;
    let Some(ao) = &t.ambient_occlusion else {
        return Ok(());
    };
    writable(name, "ambient_occlusion.output", &ao.output)?;
    viewport(
        name,
        t.common.viewport,
        &[
            ("output", &t.output),
            ("ambient_occlusion.output", &ao.output),
        ],
    )?;
    if !ao.ao_radius.is_finite() || ao.ao_radius <= 0.0 {
        return Err(Error::input(
            name,
            "ambient_occlusion.ao_radius",
            ao.ao_radius,
            "must be finite and > 0 (world units)",
        ));
    }
    Ok(())
}

fn multi_shadow(name: &'static str, t: &TraceMultiShadowTask) -> Result<()> {
    trace_common(name, &t.common, ("output0", &t.output0))?;
    writable(name, "output1", &t.output1)?;
    four_channels(name, "output0", &t.output0)?;
    four_channels(name, "output1", &t.output1)?;
    viewport(
        name,
        t.common.viewport,
        &[("output0", &t.output0), ("output1", &t.output1)],
    )?;
    if t.lights.is_empty() || t.lights.len() > MAX_MULTI_SHADOW_LIGHTS {
        return Err(Error::input(
            name,
            "lights",
            t.lights.len(),
            format!("needs 1..={MAX_MULTI_SHADOW_LIGHTS} lights"),
        ));
    }
    for (i, l) in t.lights.iter().enumerate() {
        light(name, &format!("lights[{i}]"), l)?;
    }
    Ok(())
}

fn denoise_task(name: &'static str, task: &RenderTask) -> Result<()> {
    let one_in_one_out = |c: &DenoiseTaskCommon, input: &TextureInput, output: &TextureInput| {
        denoise_common(
            name,
            c,
            &[("input", input, false), ("output", output, true)],
        )
    };
    match task {
        RenderTask::DenoiseSpecular(t) => one_in_one_out(&t.common, &t.input, &t.output),
        RenderTask::DenoiseDiffuse(t) => one_in_one_out(&t.common, &t.input, &t.output),
        RenderTask::DenoiseSpecularAndDiffuse(t) => denoise_common(
            name,
            &t.common,
            &[
                ("input_specular", &t.input_specular, false),
                ("input_diffuse", &t.input_diffuse, false),
                ("output_specular", &t.output_specular, true),
                ("output_diffuse", &t.output_diffuse, true),
            ],
        ),
        RenderTask::DenoiseDiffuseOcclusion(t) => one_in_one_out(&t.common, &t.input, &t.output),
        RenderTask::DenoiseShadow(t) => one_in_one_out(&t.common, &t.input, &t.output),
        RenderTask::DenoiseMultiShadow(t) => denoise_common(
            name,
            &t.common,
            &[
                ("input0", &t.input0, false),
                ("input1", &t.input1, false),
                ("output", &t.output, true),
            ],
        ),
        _ => Ok(()),
    }
}
