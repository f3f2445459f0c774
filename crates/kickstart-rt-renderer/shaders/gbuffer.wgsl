// G-buffer pass of ksrt's deferred rasteriser: world normals, base colour (+ metalness in
// alpha), specular colour F0 (+ roughness in alpha) and view-space motion, with a jittered
// projection. Also the emission pass (emissive meshes only, depth-equal, into the direct
// lighting target: a fifth G-buffer target would pass WebGPU's 32 bytes per sample) and the
// sun's shadow map: depth only, with the cutout test for cutout meshes.
//
// Cutouts (glTF alphaMode MASK): every pass discards the fragments whose base colour texel fails
// the SDK's test (kickstart-rt's shaders/scene/opacity.wgsl): the texel of mip 0 the coordinates
// fall in, repeating, alpha times the factor against the cutoff; never filtered sampling, so the
// G-buffer, the shadow map and the SDK's traces agree on every hole.

struct View {
    // Jittered world → clip: what rasterises.
    view_proj: mat4x4f,
    inv_view_proj: mat4x4f,
    // Unjittered world → clip of this frame and the previous one: motion vectors.
    unjittered_view_proj: mat4x4f,
    prev_view_proj: mat4x4f,
    eye: vec4f,
    // width, height, 1/width, 1/height
    size: vec4f,
}

struct Draw {
    model: mat4x4f,
    normal_matrix: mat4x4f,
    base_color: vec4f,
    emissive: vec4f,
    // metallic, roughness, MASK factor, MASK cutoff (1 and 0 for an opaque mesh: all pass)
    params: vec4f,
}

@group(0) @binding(0) var<uniform> view: View;
@group(1) @binding(0) var<uniform> draw: Draw;
@group(2) @binding(0) var base_color_tex: texture_2d<f32>;
@group(2) @binding(1) var metallic_roughness_tex: texture_2d<f32>;
@group(2) @binding(2) var emissive_tex: texture_2d<f32>;
@group(2) @binding(3) var material_sampler: sampler;

struct VertexOut {
    // Invariant: the emission pass must reproduce the G-buffer pass's depth exactly.
    @builtin(position) @invariant clip: vec4f,
    @location(0) world: vec3f,
    @location(1) normal: vec3f,
    @location(2) uv: vec2f,
}

@vertex
fn vs_main(@location(0) position: vec3f, @location(1) normal: vec3f, @location(2) uv: vec2f) -> VertexOut {
    var out: VertexOut;
    let world = draw.model * vec4f(position, 1.0);
    out.world = world.xyz;
    out.clip = view.view_proj * world;
    out.normal = (draw.normal_matrix * vec4f(normal, 0.0)).xyz;
    out.uv = uv;
    return out;
}

struct GBuffer {
    @location(0) normal: vec4f,
    @location(1) base_color: vec4f,
    @location(2) specular: vec4f,
    @location(3) motion: vec2f,
}

// Whether the surface at `uv` is opaque: the MASK test as the SDK bakes it. A cutoff of 0 (every
// opaque mesh) passes without reading the texture.
fn cutout_opaque(uv: vec2f) -> bool {
    if draw.params.w <= 0.0 {
        return true;
    }
    let size = textureDimensions(base_color_tex, 0);
    let f = uv - floor(uv);
    let texel = min(vec2u(f * vec2f(size)), size - vec2u(1u));
    let alpha = textureLoad(base_color_tex, texel, 0).a;
    return draw.params.z * alpha >= draw.params.w;
}

fn uv_of(clip: vec4f) -> vec2f {
    let ndc = clip.xy / clip.w;
    return vec2f(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBuffer {
    var out: GBuffer;
    var n = normalize(in.normal);
    // Two-sided: the side the camera sees (files often have single walls seen from both sides).
    if (!front) {
        n = -n;
    }
    let base = draw.base_color.rgb * textureSample(base_color_tex, material_sampler, in.uv).rgb;
    let mr = textureSample(metallic_roughness_tex, material_sampler, in.uv);
    let metallic = clamp(draw.params.x * mr.b, 0.0, 1.0);
    let roughness = clamp(draw.params.y * mr.g, 0.0, 1.0);
    out.normal = vec4f(n, 1.0);
    out.base_color = vec4f(base, metallic);
    out.specular = vec4f(mix(vec3f(0.04), base, metallic), roughness);
    let world = vec4f(in.world, 1.0);
    out.motion = uv_of(view.prev_view_proj * world) - uv_of(view.unjittered_view_proj * world);
    // Last, after the implicit-derivative samples above, which need every fragment of the quad.
    if (!cutout_opaque(in.uv)) {
        discard;
    }
    return out;
}

// The emission pass: emitted radiance, the lighting pass adds the lights to it.
@fragment
fn fs_emission(in: VertexOut) -> @location(0) vec4f {
    let emitted = draw.emissive.rgb * textureSample(emissive_tex, material_sampler, in.uv).rgb;
    if (!cutout_opaque(in.uv)) {
        discard;
    }
    return vec4f(emitted, 1.0);
}

// The shadow map's depth-only pass: `view.view_proj` is the sun's orthographic projection.
@vertex
fn vs_shadow(@location(0) position: vec3f) -> @builtin(position) vec4f {
    return view.view_proj * (draw.model * vec4f(position, 1.0));
}

struct ShadowOut {
    @builtin(position) clip: vec4f,
    @location(0) uv: vec2f,
}

// The shadow map of cutout meshes: positions and coordinates (the normal stream is bound but
// unused).
@vertex
fn vs_shadow_cutout(@location(0) position: vec3f, @location(2) uv: vec2f) -> ShadowOut {
    var out: ShadowOut;
    out.clip = view.view_proj * (draw.model * vec4f(position, 1.0));
    out.uv = uv;
    return out;
}

// Writes depth only where the texel is opaque: light passes through the holes.
@fragment
fn fs_shadow_cutout(in: ShadowOut) {
    if (!cutout_opaque(in.uv)) {
        discard;
    }
}
