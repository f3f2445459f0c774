// kickstart-rt trace tasks: what every trace pass shares (pixel mapping with the half-resolution
// modes, random numbers, ray offsets, sampling, the environment map). Imports the
// traversal (group 0) and the G-buffer module (group 1); the task's own bindings are group 2.
// Rust side: src/trace/tasks.rs (TraceParams) and src/trace/sampling.rs (blue noise).

#import scene/traversal
#import trace/gbuffer
#import gpu/uniform_branch

struct TrLight {
    // Point/spot: position (xyz) and emitter radius (w). Directional: the direction the light
    // travels (xyz) and tan(angular_extent / 2) (w).
    a: vec4<f32>,
    // Spot: axis (xyz) and cos(apex_angle) (w).
    b: vec4<f32>,
    // x: range, y: kind (0 directional, 1 point, 2 spot).
    c: vec4<f32>,
}

struct TraceParams {
    // x: traced-pixel mode (tr_mode), y: generator (0 blue noise,
    // 1 xorshift), z: frame index, w: flags (TR_FLAG_*).
    mode: vec4<u32>,
    // x: max ray length (FLT_MAX for ∞), y: AO radius, z: t_min relative to the view distance.
    lengths: vec4<f32>,
    // x: ray offset type (0 disabled, 1 world position, 2 camera distance), y: light count,
    // z: instance mask of secondary rays, w: pass salt (decorrelates the tasks' noise).
    misc: vec4<u32>,
    // World-position offset: threshold, float scale, int scale.
    offset_wp: vec4<f32>,
    // Camera-distance offset: constant, linear, quadratic.
    offset_cd: vec4<f32>,
    lights: array<TrLight, 32>,
}

const TR_FLAG_ENV: u32 = 1u;
const TR_FLAG_DIRECT_LIGHTING: u32 = 2u;
const TR_FLAG_BILINEAR: u32 = 4u;
const TR_FLAG_DEMODULATE: u32 = 8u;
const TR_FLAG_FIRST_HIT: u32 = 16u;
const TR_FLAG_DISNEY: u32 = 32u;
const TR_FLAG_AO: u32 = 64u;

const TR_PI: f32 = 3.14159265358979;
// Size of the blue-noise tile (src/trace/sampling.rs BLUE_NOISE_SIZE).
const TR_BN_SIZE: u32 = 64u;

@group(2) @binding(0) var<uniform> tp: TraceParams;
@group(2) @binding(1) var tr_blue_noise: texture_2d<f32>;
@group(2) @binding(2) var tr_env: texture_2d<f32>;
@group(2) @binding(3) var tr_direct_lighting: texture_2d<f32>;

// Branches on uniform values go through `tr_branch` (gpu/uniform_branch.wgsl says why).
fn tr_branch(x: u32) -> u32 {
    return uniform_branch(x, tr_blue_noise);
}

fn tr_flag(f: u32) -> bool {
    return (tr_branch(tp.mode.w) & f) != 0u;
}

// Invocations are mapped to pixels in 8×8 tiles: one workgroup (RT_WORKGROUP_SIZE = 64) traces
// one tile, so the rays of a subgroup start from neighbouring pixels (an 8×4 block for 32 lanes)
// instead of a 32-pixel row strip. Their paths through the BVH share more nodes, so a subgroup
// diverges less (primary rays above all). The Rust side dispatches one workgroup per tile
// (src/trace/tasks.rs, `traced_tiles`).
const TR_TILE: u32 = 8u;

// The traced-pixel mode (HalfResolutionMode::shader_code): bits 0-7 the mode (0 off,
// 1 checkerboard, 2 inverted, 3 one pixel per block), 8-15 the block size, 16-31 the traced
// pixel of each block (x, y).
fn tr_mode() -> u32 {
    return tr_branch(tp.mode.x) & 0xffu;
}

fn tr_block() -> u32 {
    return (tr_branch(tp.mode.x) >> 8u) & 0xffu;
}

// The grid of traced pixels: the viewport, its half-width in a checkerboard mode (a grid column
// then stands for a pair of viewport columns), or one pixel per block.
fn tr_grid() -> vec2<u32> {
    let size = gb.viewport.zw;
    switch tr_mode() {
        case 0u: {
            return size;
        }
        case 3u: {
            let b = tr_block();
            return (size + vec2<u32>(b - 1u)) / b;
        }
        default: {
            return vec2<u32>((size.x + 1u) / 2u, size.y);
        }
    }
}

struct TrPixel {
    texel: vec2<u32>,
    valid: bool,
}

// The texel of invocation i (tile i / 64, row-major over the grid's tiles; pixel i % 64
// row-major in the tile). Checkerboard traces viewport-relative (x + y) even, inverted traces
// (x + y) odd; a block mode traces its pixel of each block; the other pixels are not written.
// `valid` is false for a tile's invocations past the grid's right or bottom edge, and for a
// block's traced pixel past the viewport's.
fn tr_pixel(i: u32) -> TrPixel {
    let grid = tr_grid();
    let tiles_x = (grid.x + TR_TILE - 1u) / TR_TILE;
    let tile = i / (TR_TILE * TR_TILE);
    let lane = i % (TR_TILE * TR_TILE);
    let g = vec2<u32>((tile % tiles_x) * TR_TILE + lane % TR_TILE,
                      (tile / tiles_x) * TR_TILE + lane / TR_TILE);
    var p: TrPixel;
    p.valid = g.x < grid.x && g.y < grid.y;
    let mode = tr_mode();
    if mode == 0u {
        p.texel = gb.viewport.xy + g;
        return p;
    }
    var v: vec2<u32>;
    if mode == 3u {
        let offset = vec2<u32>((tp.mode.x >> 16u) & 0xffu, tp.mode.x >> 24u);
        v = g * tr_block() + offset;
    } else {
        let phase = (g.y + mode - 1u) & 1u;
        v = vec2<u32>(2u * g.x + phase, g.y);
    }
    p.texel = gb.viewport.xy + v;
    p.valid = p.valid && all(v < gb.viewport.zw);
    return p;
}

// ---- random numbers -------------------------------------------------------------------------

// PCG hash (Jarzynski & Olano 2020).
fn tr_hash(x: u32) -> u32 {
    let state = x * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

struct TrRng {
    state: u32,
    texel: vec2<u32>,
    dim: u32,
}

fn tr_rng(texel: vec2<u32>) -> TrRng {
    var r: TrRng;
    r.texel = texel;
    r.dim = 0u;
    r.state = tr_hash(texel.x ^ tr_hash(texel.y ^ tr_hash(tp.mode.z ^ tr_hash(tp.misc.w))));
    if r.state == 0u {
        r.state = 0x9e3779b9u;
    }
    return r;
}

// The next number in [0, 1). Blue noise: dimension d reads the tile at a fixed toroidal shift
// of d and adds frame × (golden ratio − 1) (spatially blue in every frame, low-discrepancy over
// frames). Xorshift: one 32-bit xorshift stream per pixel and frame.
fn tr_next(r: ptr<function, TrRng>) -> f32 {
    let d = (*r).dim;
    (*r).dim = d + 1u;
    if tr_branch(tp.mode.y) == 0u {
        let h = tr_hash((d * 0x68bc21ebu) ^ (tp.misc.w * 0x02e5be93u));
        let shift = vec2<u32>(h & 63u, (h >> 6u) & 63u);
        let at = ((*r).texel + shift) % vec2<u32>(TR_BN_SIZE);
        let v = textureLoad(tr_blue_noise, at, 0).x;
        let temporal = f32(tp.mode.z % 4096u) * 0.61803398875 + f32(h >> 20u) * (1.0 / 4096.0);
        return fract(v + temporal);
    }
    var s = (*r).state;
    s ^= s << 13u;
    s ^= s >> 17u;
    s ^= s << 5u;
    (*r).state = s;
    return f32(s >> 8u) * (1.0 / 16777216.0);
}

// ---- geometry helpers -----------------------------------------------------------------------

// An orthonormal basis around unit n (Duff et al. 2017): columns t, b, n.
fn tr_basis(n: vec3<f32>) -> mat3x3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t = vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let bt = vec3<f32>(b, s + n.y * n.y * a, -n.y);
    return mat3x3<f32>(t, bt, n);
}

// Uniform point in the unit disc (concentric-free polar mapping; area preserving).
fn tr_disc(u: vec2<f32>) -> vec2<f32> {
    let r = sqrt(u.x);
    let phi = 2.0 * TR_PI * u.y;
    return vec2<f32>(r * cos(phi), r * sin(phi));
}

// Cosine-weighted direction around unit n (pdf cos θ / π).
fn tr_cosine(n: vec3<f32>, u: vec2<f32>) -> vec3<f32> {
    let d = tr_disc(u);
    let z = sqrt(max(0.0, 1.0 - dot(d, d)));
    return normalize(tr_basis(n) * vec3<f32>(d, z));
}

// The ray origin: the surface point moved off the surface by the task's ray offset.
// World position: Wächter & Binder, "A Fast and Robust Method for Avoiding Self-Intersection"
// (Ray Tracing Gems, 2019): an ulp-scaled integer offset far from the origin, a float offset
// near it. Camera distance: constant + linear·d + quadratic·d² along the normal.
fn tr_origin(p: vec3<f32>, n: vec3<f32>, view_distance: f32) -> vec3<f32> {
    let offset_type = tr_branch(tp.misc.x);
    if offset_type == 1u {
        let of_i = vec3<i32>(tp.offset_wp.z * n);
        let pi = bitcast<vec3<i32>>(p);
        let moved = bitcast<vec3<f32>>(pi + select(of_i, -of_i, p < vec3<f32>(0.0)));
        return select(moved, p + tp.offset_wp.y * n, abs(p) < vec3<f32>(tp.offset_wp.x));
    }
    if offset_type == 2u {
        let d = view_distance;
        return p + n * (tp.offset_cd.x + tp.offset_cd.y * d + tp.offset_cd.z * d * d);
    }
    return p;
}

// t_min of secondary rays: a small fraction of the view distance (depth reconstruction error
// grows with it), so rays do not re-hit their own surface even without a ray offset.
fn tr_t_min(view_distance: f32) -> f32 {
    return tp.lengths.z * view_distance;
}

// ---- environment map ------------------------------------------------------------------------

// Radiance arriving along -d from the lat-long environment map (0 without one). Mapping: the top
// row is +y, v = acos(d.y) / π; u = 0.5 + atan2(d.x, −d.z) / 2π, so −z is the centre column and
// +x is at u = 0.75. Bilinear, wrapping in u.
fn tr_environment(d: vec3<f32>) -> vec3<f32> {
    if !tr_flag(TR_FLAG_ENV) {
        return vec3<f32>(0.0);
    }
    let size = textureDimensions(tr_env);
    let u = 0.5 + atan2(d.x, -d.z) / (2.0 * TR_PI);
    let v = acos(clamp(d.y, -1.0, 1.0)) / TR_PI;
    let p = vec2<f32>(u * f32(size.x) - 0.5, v * f32(size.y) - 0.5);
    let f = floor(p);
    let w = p - f;
    let x0 = (i32(f.x) % i32(size.x) + i32(size.x)) % i32(size.x);
    let x1 = (x0 + 1) % i32(size.x);
    let y0 = clamp(i32(f.y), 0, i32(size.y) - 1);
    let y1 = clamp(i32(f.y) + 1, 0, i32(size.y) - 1);
    let a = textureLoad(tr_env, vec2<i32>(x0, y0), 0).xyz;
    let b = textureLoad(tr_env, vec2<i32>(x1, y0), 0).xyz;
    let c = textureLoad(tr_env, vec2<i32>(x0, y1), 0).xyz;
    let e = textureLoad(tr_env, vec2<i32>(x1, y1), 0).xyz;
    return mix(mix(a, b, w.x), mix(c, e, w.x), w.y);
}

// The pixel this invocation traces: `valid` false past the dispatch's pixels, outside the
// viewport, or where the input mask rejects it (every trace entry point returns then).
fn tr_invocation_pixel(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> TrPixel {
    var px = tr_pixel(tr_index(wid, nwg, lid));
    px.valid = px.valid && gb_mask(px.texel);
    return px;
}

// Linear index of this invocation (dispatches are split in 2-D past 65535 workgroups).
fn tr_index(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * RT_WORKGROUP_SIZE + lid;
}
