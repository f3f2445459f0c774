// kickstart-rt G-buffer decoding, shared by every pass that reads the engine's G-buffer (trace
// tasks, lighting injection, denoisers). GBUFFER_GROUP is the bind group the includer binds it
// at; the Rust side (src/trace/gbuffer.rs) fills GBufferParams and binds the textures with
// an explicit layout (so a pass may use only some of them).
//
// Every texture is read with textureLoad as texture_2d<f32>: float, unorm and snorm formats, and
// depth formats (WebGPU lets a depth texture bind as unfilterable float; depth is in .r).
//
// Pixels: `texel` is a texel coordinate of the engine's textures; the viewport maps the processed
// rectangle into them. NDC: x right, y up, z as the projection writes it (normal or reverse Z).

#param GBUFFER_GROUP
#import gpu/uniform_branch

struct GBufferParams {
    // inverse(view_to_clip * world_to_view) (computed in f64 on the CPU).
    clip_to_world: mat4x4<f32>,
    // view_to_clip * world_to_view.
    world_to_clip: mat4x4<f32>,
    // prev_view_to_clip * prev_world_to_view (reprojection).
    prev_world_to_clip: mat4x4<f32>,
    // Turns decoded normals into world space.
    normal_to_world: mat4x4<f32>,
    // xyz: the eye (perspective) ; w: 1 perspective, 0 orthographic.
    eye: vec4<f32>,
    // xyz: world-space viewing direction (the camera's -z), normalised.
    forward: vec4<f32>,
    // Dot product with the roughness texel selects its channel.
    roughness_mask: vec4<f32>,
    // x, y, width, height of the viewport in texels.
    viewport: vec4<u32>,
    // 0: RGB world space, 1: R clip-space depth.
    depth_type: u32,
    // NormalType in declaration order (0 RgbVector … 5 BaNormalizedOctahedron).
    normal_type: u32,
    // Which optional textures are bound (bit 0 roughness, 1 specular, 2 input mask).
    has_textures: u32,
    // The NDC depth of "nothing rendered here" (the far plane: 1 normal Z, 0 reverse Z).
    far_ndc: f32,
    global_roughness: f32,
    roughness_multiplier: f32,
    min_roughness: f32,
    max_roughness: f32,
    global_metalness: f32,
    // ViewInfo::jitter, pixels: a point at unjittered pixel coordinate c was rendered at
    // c + jitter, so a texel's depth is unprojected at its centre minus the jitter.
    jitter_x: f32,
    jitter_y: f32,
    pad0: f32,
}

@group({{GBUFFER_GROUP}}) @binding(0) var<uniform> gb: GBufferParams;
@group({{GBUFFER_GROUP}}) @binding(1) var gb_depth: texture_2d<f32>;
@group({{GBUFFER_GROUP}}) @binding(2) var gb_normal: texture_2d<f32>;
@group({{GBUFFER_GROUP}}) @binding(3) var gb_roughness_tex: texture_2d<f32>;
@group({{GBUFFER_GROUP}}) @binding(4) var gb_specular_tex: texture_2d<f32>;
@group({{GBUFFER_GROUP}}) @binding(5) var gb_mask_tex: texture_2d<f32>;

const GB_HAS_ROUGHNESS: u32 = 1u;
const GB_HAS_SPECULAR: u32 = 2u;
const GB_HAS_MASK: u32 = 4u;

// A decoded G-buffer texel.
struct GbSurface {
    // False where nothing was rendered (far-plane depth, non-finite position, zero normal).
    valid: bool,
    // World-space position.
    position: vec3<f32>,
    // World-space unit normal.
    normal: vec3<f32>,
    // Unit vector from the surface towards the camera.
    to_eye: vec3<f32>,
    // Distance from the camera (the eye; the near plane's point for orthographic views).
    view_distance: f32,
}

// True when `x` is NaN or ±∞ (by bit pattern: WGSL may assume finite floats).
fn gb_non_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) == 0x7f800000u;
}

// Number of viewport pixels.
fn gb_pixel_count() -> u32 {
    return gb.viewport.z * gb.viewport.w;
}

// The texel of the i-th viewport pixel (row-major).
fn gb_texel(i: u32) -> vec2<u32> {
    let w = gb.viewport.z;
    return vec2<u32>(gb.viewport.x + i % w, gb.viewport.y + i / w);
}

// NDC xy of a point at viewport-relative texel coordinates `p` (texel centre = +0.5).
fn gb_ndc_of(p: vec2<f32>) -> vec2<f32> {
    let size = vec2<f32>(gb.viewport.zw);
    let uv = (p - vec2<f32>(gb.viewport.xy)) / size;
    return vec2<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0);
}

// World-space point at NDC (xy, z).
fn gb_unproject(ndc: vec2<f32>, z: f32) -> vec3<f32> {
    let p = gb.clip_to_world * vec4<f32>(ndc, z, 1.0);
    return p.xyz / p.w;
}

// Branches on uniform values go through `gb_branch` (gpu/uniform_branch.wgsl says why).
fn gb_branch(x: u32) -> u32 {
    return uniform_branch(x, gb_depth);
}

// Whether the view is a perspective one (the eye is a point), for a branch (gb_branch).
fn gb_perspective() -> bool {
    return bitcast<f32>(gb_branch(bitcast<u32>(gb.eye.w))) > 0.5;
}

// Standard octahedral decode (Cigolle et al. 2014) of e in [-1, 1]².
fn gb_oct_decode(e: vec2<f32>) -> vec3<f32> {
    var n = vec3<f32>(e, 1.0 - abs(e.x) - abs(e.y));
    if n.z < 0.0 {
        let s = select(vec2<f32>(-1.0), vec2<f32>(1.0), n.xy >= vec2<f32>(0.0));
        n = vec3<f32>((1.0 - abs(n.yx)) * s, n.z);
    }
    return n;
}

// The normal texel decoded and turned into world space (zero where the texel holds none).
fn gb_decode_normal(t: vec4<f32>) -> vec3<f32> {
    var n: vec3<f32>;
    switch gb_branch(gb.normal_type) {
        case 0u: { n = t.xyz; }
        case 1u: { n = t.xyz * 2.0 - 1.0; }
        case 2u: { n = gb_oct_decode(t.xy); }
        case 3u: { n = gb_oct_decode(t.zw); }
        case 4u: { n = gb_oct_decode(t.xy * 2.0 - 1.0); }
        default: { n = gb_oct_decode(t.zw * 2.0 - 1.0); }
    }
    let w = (gb.normal_to_world * vec4<f32>(n, 0.0)).xyz;
    let len2 = dot(w, w);
    if !(len2 > 1e-12) || gb_non_finite(len2) {
        return vec3<f32>(0.0);
    }
    return w * inverseSqrt(len2);
}

// Unit vector from `p` towards the camera.
fn gb_to_eye(p: vec3<f32>) -> vec3<f32> {
    if gb_perspective() {
        return normalize(gb.eye.xyz - p);
    }
    return -gb.forward.xyz;
}

// Distance of `p` from the camera (along the view direction for orthographic views).
fn gb_view_distance(p: vec3<f32>) -> f32 {
    if gb_perspective() {
        return length(gb.eye.xyz - p);
    }
    return abs(dot(p - gb.eye.xyz, gb.forward.xyz));
}

// Decodes the surface at `texel`.
// This frame's camera jitter, pixels (x right, y down).
fn gb_jitter() -> vec2<f32> {
    return vec2<f32>(gb.jitter_x, gb.jitter_y);
}

fn gb_surface(texel: vec2<u32>) -> GbSurface {
    var s: GbSurface;
    s.valid = false;
    let d = textureLoad(gb_depth, texel, 0);
    if gb_branch(gb.depth_type) == 0u {
        s.position = d.xyz;
    } else {
        if d.x == gb.far_ndc || gb_non_finite(d.x) {
            return s;
        }
        s.position = gb_unproject(gb_ndc_of(vec2<f32>(texel) + 0.5 - gb_jitter()), d.x);
    }
    if gb_non_finite(s.position.x) || gb_non_finite(s.position.y) || gb_non_finite(s.position.z) {
        return s;
    }
    s.normal = gb_decode_normal(textureLoad(gb_normal, texel, 0));
    if all(s.normal == vec3<f32>(0.0)) {
        return s;
    }
    s.to_eye = gb_to_eye(s.position);
    s.view_distance = gb_view_distance(s.position);
    s.valid = true;
    return s;
}

// Roughness at `texel`: the masked texel (or the global value), × multiplier, clamped.
fn gb_roughness(texel: vec2<u32>) -> f32 {
    var r = gb.global_roughness;
    if (gb_branch(gb.has_textures) & GB_HAS_ROUGHNESS) != 0u {
        r = dot(textureLoad(gb_roughness_tex, texel, 0), gb.roughness_mask);
    }
    return clamp(r * gb.roughness_multiplier, gb.min_roughness, gb.max_roughness);
}

// Specular input at `texel`: the texel (RGB specular reflectance F0, A as the engine wrote it),
// or the global metalness in every channel when no texture is bound.
fn gb_specular(texel: vec2<u32>) -> vec4<f32> {
    if (gb_branch(gb.has_textures) & GB_HAS_SPECULAR) != 0u {
        return textureLoad(gb_specular_tex, texel, 0);
    }
    return vec4<f32>(gb.global_metalness);
}

// False where the input mask's red channel is 0 (the pixel is skipped); true without a mask.
fn gb_mask(texel: vec2<u32>) -> bool {
    if (gb_branch(gb.has_textures) & GB_HAS_MASK) != 0u {
        return textureLoad(gb_mask_tex, texel, 0).x != 0.0;
    }
    return true;
}

// Projects a world-space point with `m` (a world-to-clip matrix): xy = viewport-relative texel
// coordinates (continuous; texel centres at +0.5) of the unjittered projection (the G-buffer
// holds the point at xy + gb_jitter()), z = NDC depth, w = clip w (≤ 0: behind).
fn gb_project_with(m: mat4x4<f32>, p: vec3<f32>) -> vec4<f32> {
    let c = m * vec4<f32>(p, 1.0);
    let ndc = c.xyz / c.w;
    let size = vec2<f32>(gb.viewport.zw);
    let xy = vec2<f32>((ndc.x + 1.0) * 0.5, (1.0 - ndc.y) * 0.5) * size;
    return vec4<f32>(xy, ndc.z, c.w);
}

// `p` in this frame's viewport (see gb_project_with).
fn gb_project(p: vec3<f32>) -> vec4<f32> {
    return gb_project_with(gb.world_to_clip, p);
}

// `p` in the previous frame's viewport (see gb_project_with).
fn gb_project_prev(p: vec3<f32>) -> vec4<f32> {
    return gb_project_with(gb.prev_world_to_clip, p);
}
