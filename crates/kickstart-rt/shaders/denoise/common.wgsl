// kickstart-rt denoisers: parameters and packing shared by every denoise pass
// (src/denoise/mod.rs fills DenoiseParams).
//
// Every pass is compiled per signal set (src/denoise/signal.rs): denoise/signals gives
// DN_SIGNALS (1 or 2) and DN_KIND0 / DN_KIND1 (DN_KIND_*) as constants, so that signal loops have
// constant bounds (their arrays stay in registers) and kind switches fold away. The pass composes
// beside this module one of denoise/record_rgba (radiance) or denoise/record_scalar (occlusion,
// shadows), which define the signal record `DnRecord` and its accessors, and one of
// denoise/output/* (none, or the one output texture of a chain), which define DN_LAST (the last
// à-trous iteration, which writes the output texture) and dn_write_output.
//
// The passes work on a grid of pixels: the viewport, or in a block mode (one traced pixel per
// 2×2 or 4×4 block, HalfResolutionMode::OnePer*) one pixel per block, the block's traced one
// (dn_texel); the upsample pass then writes every viewport pixel from that grid. Per-pixel
// buffers are indexed by grid pixel, row-major with the grid's width.
// - guide (vec2<u32>): x = the surface's clip-space depth (f32 bits: the G-buffer's hardware
//   depth, or its world position's projection); y = octahedral normal (12 + 12 bits) and
//   roughness (8 bits), or DN_INVALID where the G-buffer holds no surface. The position is the
//   depth unprojected at the grid pixel's texel with its frame's camera and jitter
//   (dn_guide_position), as the G-buffer's own decoding does: 8 bytes instead of a position's 12.
// - signal (DnRecord, history and filter intermediates): the value (rgb or scalar), the hit
//   distance, z = history: second moment of luminance / filter: variance of the value's noise,
//   and the history length in frames (layouts in the record files).

#import denoise/signals

struct DenoiseParams {
    // x, y, width, height of the viewport in texels.
    viewport: vec4<u32>,
    // xyz: this frame's eye; w: 1 perspective, 0 orthographic.
    eye: vec4<f32>,
    // xyz: this frame's viewing direction.
    forward: vec4<f32>,
    // xyz: the previous frame's eye; w: 1 perspective.
    prev_eye: vec4<f32>,
    // xyz: the previous frame's viewing direction.
    prev_forward: vec4<f32>,
    // xy: this frame's jitter, zw: the previous frame's (pixels; a point at unjittered pixel
    // coordinate c is rendered at c + jitter).
    jitter: vec4<f32>,
    // xyz: motion scale.
    motion_scale: vec4<f32>,
    // Signal kind of signal 0 and 1 (DN_KIND_*).
    kind0: u32,
    kind1: u32,
    // 1 or 2.
    signal_count: u32,
    // 0: none (reproject with the matrices), 1: RgViewSpace, 2: RgbWorldSpace.
    motion_type: u32,
    // Longest history, frames.
    max_history: f32,
    // 1: drop the history this frame.
    discard_history: u32,
    // 0: off, 1: checkerboard (even cells traced), 2: inverted (odd cells traced).
    checkerboard: u32,
    // Base radius of the spatial filter, pixels.
    base_radius: f32,
    // xy: the grid's size; z: pixels per grid pixel along each axis (the block size, 1 but in
    // a block mode).
    grid: vec4<u32>,
    // xy: this frame's traced pixel of each block, zw: the previous frame's (block modes).
    lattice: vec4<u32>,
    // This and the previous frame's clip-to-world matrices (the guides' unprojection).
    clip_to_world: mat4x4<f32>,
    prev_clip_to_world: mat4x4<f32>,
}

const DN_INVALID: u32 = 0xffffffffu;

const DN_KIND_SPECULAR: u32 = 0u;
const DN_KIND_DIFFUSE: u32 = 1u;
const DN_KIND_OCCLUSION: u32 = 2u;
const DN_KIND_SHADOW: u32 = 3u;
const DN_KIND_MULTI_SHADOW: u32 = 4u;

// Largest magnitude stored as f16 (keeps huge hit distances and HDR spikes finite).
const DN_F16_MAX: f32 = 65000.0;

fn dn_non_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) == 0x7f800000u;
}

// A finite, f16-representable copy of `v` (NaN and ±∞ become 0).
fn dn_sanitize(v: vec4<f32>) -> vec4<f32> {
    var r = v;
    for (var k = 0; k < 4; k++) {
        if dn_non_finite(r[k]) {
            r[k] = 0.0;
        }
    }
    return clamp(r, vec4<f32>(-DN_F16_MAX), vec4<f32>(DN_F16_MAX));
}

fn dn_luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

fn dn_oct_encode(n: vec3<f32>) -> vec2<f32> {
    let p = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
    if n.z < 0.0 {
        let s = select(vec2<f32>(-1.0), vec2<f32>(1.0), p >= vec2<f32>(0.0));
        return (1.0 - abs(p.yx)) * s;
    }
    return p;
}

fn dn_oct_decode(e: vec2<f32>) -> vec3<f32> {
    var n = vec3<f32>(e, 1.0 - abs(e.x) - abs(e.y));
    if n.z < 0.0 {
        let s = select(vec2<f32>(-1.0), vec2<f32>(1.0), n.xy >= vec2<f32>(0.0));
        n = vec3<f32>((1.0 - abs(n.yx)) * s, n.z);
    }
    return normalize(n);
}

// The guide of a surface at clip-space depth `z`, normal `n`, `roughness`.
fn dn_pack_guide(z: f32, n: vec3<f32>, roughness: f32) -> vec2<u32> {
    let e = clamp(dn_oct_encode(n) * 0.5 + 0.5, vec2<f32>(0.0), vec2<f32>(1.0));
    let q = vec2<u32>(round(e * 4095.0));
    let r = u32(round(clamp(roughness, 0.0, 1.0) * 254.0));
    return vec2<u32>(bitcast<u32>(z), q.x | (q.y << 12u) | (r << 24u));
}

// Whether guide `g` holds a surface.
fn dn_guide_valid(g: vec2<u32>) -> bool {
    return g.y != DN_INVALID;
}

// World position of clip-space depth `z` at grid pixel `q` of this frame (`prev` false) or of
// the previous one: the same arithmetic as the G-buffer's decoding (gb_ndc_of, gb_unproject) on
// that frame's texel, jitter and camera.
fn dn_guide_position(q: vec2<u32>, z: f32, prev: bool) -> vec3<f32> {
    var lattice = dp.lattice.xy;
    var jitter = dp.jitter.xy;
    var m = dp.clip_to_world;
    if prev {
        lattice = dp.lattice.zw;
        jitter = dp.jitter.zw;
        m = dp.prev_clip_to_world;
    }
    let texel = dp.viewport.xy + q * dp.grid.z + lattice;
    let at = vec2<f32>(texel) + 0.5 - jitter;
    let uv = (at - vec2<f32>(dp.viewport.xy)) / vec2<f32>(dp.viewport.zw);
    let c = m * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, z, 1.0);
    return c.xyz / c.w;
}

struct DnGuide {
    valid: bool,
    position: vec3<f32>,
    normal: vec3<f32>,
    roughness: f32,
}

// The surface of guide `g` at grid pixel `q` of this frame (`prev` false) or the previous one.
fn dn_unpack_guide(g: vec2<u32>, q: vec2<u32>, prev: bool) -> DnGuide {
    var r: DnGuide;
    r.valid = dn_guide_valid(g);
    if !r.valid {
        return r;
    }
    r.position = dn_guide_position(q, bitcast<f32>(g.x), prev);
    let e = vec2<f32>(f32(g.y & 4095u), f32((g.y >> 12u) & 4095u)) / 4095.0;
    r.normal = dn_oct_decode(e * 2.0 - 1.0);
    r.roughness = f32(g.y >> 24u) / 254.0;
    return r;
}

fn dn_pixel_count() -> u32 {
    return dp.grid.x * dp.grid.y;
}

// Whether grid pixel `p` exists.
fn dn_in_grid(p: vec2<i32>) -> bool {
    return p.x >= 0 && p.y >= 0 && p.x < i32(dp.grid.x) && p.y < i32(dp.grid.y);
}

// Row-major buffer index of grid pixel `p` (inside the grid).
fn dn_index(p: vec2<u32>) -> u32 {
    return p.y * dp.grid.x + p.x;
}

// Grid pixel `q` clamped into the grid.
fn dn_clamped(q: vec2<i32>) -> vec2<u32> {
    return vec2<u32>(clamp(q, vec2<i32>(0), vec2<i32>(dp.grid.xy) - vec2<i32>(1)));
}

// Row-major buffer index of grid pixel `q` clamped into the grid.
fn dn_clamped_index(q: vec2<i32>) -> u32 {
    return dn_index(dn_clamped(q));
}

// Viewport-relative pixel of grid pixel `g`: itself, or the traced pixel of block `g` (which
// may lie past the viewport in its last column or row: see dn_texel_inside).
fn dn_grid_pixel(g: vec2<u32>) -> vec2<u32> {
    return g * dp.grid.z + dp.lattice.xy;
}

fn dn_texel_inside(g: vec2<u32>) -> bool {
    return all(dn_grid_pixel(g) < dp.viewport.zw);
}

// Texel of grid pixel `g`.
fn dn_texel(g: vec2<u32>) -> vec2<u32> {
    return dp.viewport.xy + dn_grid_pixel(g);
}

// Distance of `p` from this frame's camera (along the view direction when orthographic).
fn dn_view_distance(p: vec3<f32>) -> f32 {
    if dp.eye.w > 0.5 {
        return length(dp.eye.xyz - p);
    }
    return abs(dot(p - dp.eye.xyz, dp.forward.xyz));
}

fn dn_prev_view_distance(p: vec3<f32>) -> f32 {
    if dp.prev_eye.w > 0.5 {
        return length(dp.prev_eye.xyz - p);
    }
    return abs(dot(p - dp.prev_eye.xyz, dp.prev_forward.xyz));
}

// Unit vector from `p` towards this frame's camera.
fn dn_to_eye(p: vec3<f32>) -> vec3<f32> {
    if dp.eye.w > 0.5 {
        return normalize(dp.eye.xyz - p);
    }
    return -dp.forward.xyz;
}

fn dn_kind(s: u32) -> u32 {
    return select(DN_KIND0, DN_KIND1, s == 1u);
}
