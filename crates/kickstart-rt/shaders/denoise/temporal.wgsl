// kickstart-rt denoisers, pass 1: temporal accumulation.
//
// Per grid pixel (see denoise/common.wgsl): decodes the G-buffer (with the camera jitter) into
// this frame's guide, reads the noisy signal(s) (checkerboard: untraced pixels are rebuilt from
// their four traced neighbours, weighted by geometric similarity), reprojects into the previous frame (motion
// vectors of either type, or the previous matrices), keeps the bilinear taps whose surface
// matches (normal and plane distance; disocclusion drops the history), clamps the history to
// the current neighbourhood's mean ± γσ, σ the wider of the neighbourhood's and of the pixel's
// own history's spread (ghosting), and blends: the history length grows by one
// up to max_history and the new sample weighs 1 / length. The history holds the accumulated raw
// signal (never the spatially filtered one), so the spatial filter cannot blur it over time.
//
// The G-buffer is at group 0 (trace/gbuffer).

#import denoise/common
#import trace/gbuffer

@group(1) @binding(0) var<uniform> dp: DenoiseParams;
@group(1) @binding(1) var dn_motion: texture_2d<f32>;
@group(1) @binding(2) var dn_input0: texture_2d<f32>;
@group(1) @binding(3) var dn_input1: texture_2d<f32>;

@group(2) @binding(0) var<storage, read> guide_prev: array<vec2<u32>>;
@group(2) @binding(1) var<storage, read_write> guide_cur: array<vec2<u32>>;
@group(2) @binding(2) var<storage, read> hist_prev0: array<DnRecord>;
@group(2) @binding(3) var<storage, read> hist_prev1: array<DnRecord>;
@group(2) @binding(4) var<storage, read_write> hist_cur0: array<DnRecord>;
@group(2) @binding(5) var<storage, read_write> hist_cur1: array<DnRecord>;

// Width of the history clamp, in standard deviations of the neighbourhood.
const CLAMP_SIGMAS: f32 = 2.0;

// The workgroup's 8×8 pixels and a 1-pixel border of the decoded input (dn_load_input), loaded
// once per workgroup (100 loads for 64 pixels instead of 9 per pixel) for the 3×3 neighbourhood
// statistics; dn_tile_ok: inside the grid and traced.
const DN_TILE: u32 = 10u;
var<workgroup> dn_tile: array<array<vec4<f32>, 100>, DN_SIGNALS>;
var<workgroup> dn_tile_ok: array<u32, 100>;

// The noisy input of signal `s` at `texel` as (rgb, hit distance); scalar signals repeat their
// value in rgb. Occlusion: normalised hit distance (1 = open). Shadow: visibility 1 where the
// input is negative (the light is visible), 0 where a hit was found; the hit distance is kept
// for the penumbra estimate. Multi-shadow: the trace's packed output0, r = fraction of lights visible, g = closest
// occluder distance (-1 when none).
fn dn_load_input(s: u32, texel: vec2<u32>) -> vec4<f32> {
    var t: vec4<f32>;
    if s == 0u {
        t = textureLoad(dn_input0, texel, 0);
    } else {
        t = textureLoad(dn_input1, texel, 0);
    }
    t = dn_sanitize(t);
    switch dn_kind(s) {
        case DN_KIND_OCCLUSION: {
            let v = clamp(t.x, 0.0, 1.0);
            return vec4<f32>(v, v, v, v);
        }
        case DN_KIND_SHADOW: {
            let v = select(0.0, 1.0, t.x < 0.0);
            return vec4<f32>(v, v, v, max(t.x, 0.0));
        }
        case DN_KIND_MULTI_SHADOW: {
            let v = clamp(t.x, 0.0, 1.0);
            return vec4<f32>(v, v, v, max(t.y, 0.0));
        }
        default: {
            return vec4<f32>(t.xyz, max(t.w, 0.0));
        }
    }
}

// Whether the input holds a traced sample at viewport-relative pixel `p`.
fn dn_traced(p: vec2<u32>) -> bool {
    if dp.checkerboard == 0u {
        return true;
    }
    // Viewport-relative parity, the rule the trace tasks use (trace/common.wgsl, tr_pixel), so a
    // viewport at an odd offset still reads the pixels that were traced.
    return ((p.x + p.y) & 1u) == dp.checkerboard - 1u;
}

// The signal at viewport-relative pixel `p`; checkerboard holes are filled from the traced
// 4-neighbours, weighted by how well their surface matches (`pos`, `n`; `valid` false: plain
// average).
fn dn_sample(s: u32, p: vec2<u32>, valid: bool, pos: vec3<f32>, n: vec3<f32>) -> vec4<f32> {
    if dn_traced(p) {
        return dn_load_input(s, dn_texel(p));
    }
    var sum = vec4<f32>(0.0);
    var wsum = 0.0;
    var any_sum = vec4<f32>(0.0);
    var any_count = 0.0;
    let offsets = array<vec2<i32>, 4>(vec2<i32>(-1, 0), vec2<i32>(1, 0), vec2<i32>(0, -1), vec2<i32>(0, 1));
    let dist = max(dn_view_distance(pos), 1e-6);
    for (var k = 0; k < 4; k++) {
        let q = vec2<i32>(p) + offsets[k];
        if !dn_in_grid(q) {
            continue;
        }
        let texel = vec2<u32>(q) + dp.viewport.xy;
        let v = dn_load_input(s, texel);
        any_sum += v;
        any_count += 1.0;
        if valid {
            let sq = gb_surface(texel);
            if sq.valid {
                let plane = abs(dot(n, sq.position - pos)) / (0.02 * dist);
                let w = max(dot(n, sq.normal), 0.0) * exp(-plane * plane);
                sum += w * v;
                wsum += w;
            }
        }
    }
    if wsum > 1e-4 {
        return sum / wsum;
    }
    return any_sum / max(any_count, 1.0);
}

// The guide depth of the surface at `texel` (position `pos`): the G-buffer's own hardware depth
// (unprojecting it repeats the G-buffer's decoding exactly), or a world position's projection.
fn dn_guide_depth(texel: vec2<u32>, pos: vec3<f32>) -> f32 {
    if gb_branch(gb.depth_type) == 0u {
        let c = gb.world_to_clip * vec4<f32>(pos, 1.0);
        return c.z / c.w;
    }
    return textureLoad(gb_depth, texel, 0).x;
}

// Weight of the previous frame's pixel `q` (guide `g`, bilinear weight `bw`) for this pixel's
// history: 0 outside the grid or where it shows another surface.
fn dn_history_weight(
    q: vec2<i32>,
    g: vec2<u32>,
    bw: f32,
    pos: vec3<f32>,
    n: vec3<f32>,
    pred: vec3<f32>,
) -> f32 {
    if !dn_in_grid(q) {
        return 0.0;
    }
    let gq = dn_unpack_guide(g, vec2<u32>(q), true);
    if !gq.valid || !dn_reusable(gq, pos, n, pred) {
        return 0.0;
    }
    return max(bw, 1e-4);
}

fn dn_store_hist(s: u32, i: u32, v: DnRecord) {
    if s == 0u {
        hist_cur0[i] = v;
    } else {
        hist_cur1[i] = v;
    }
}

// Whether the previous frame's surface `g` is the current one: similar normal, and on the same
// plane as the predicted previous position (or, with view-space motion, which does not say how
// depth changed, at the same camera distance).
fn dn_reusable(g: DnGuide, pos: vec3<f32>, n: vec3<f32>, pred: vec3<f32>) -> bool {
    if dot(g.normal, n) < 0.8 {
        return false;
    }
    let dist = max(dn_prev_view_distance(pred), 1e-6);
    let plane_ok = abs(dot(n, g.position - pred)) < 0.01 * dist;
    if dp.motion_type != 1u {
        return plane_ok;
    }
    let d = dn_view_distance(pos);
    let ndv = max(abs(dot(n, dn_to_eye(pos))), 0.1);
    return plane_ok || abs(dn_prev_view_distance(g.position) - d) < (0.03 / ndv) * d;
}

// Visibility signals (a shadow, a multi-shadow: each compiled alone) reconstruct their history
// with a Catmull-Rom kernel instead of the bilinear one, see dn_sharp_visibility_history.
const DN_SHARP_HISTORY: bool = DN_SIGNALS == 1u
    && (DN_KIND0 == DN_KIND_SHADOW || DN_KIND0 == DN_KIND_MULTI_SHADOW);

// Catmull-Rom weights of the taps at -1, 0, 1, 2 for a sample at fraction `t` past tap 0.
fn dn_catmull_rom(t: f32) -> vec4<f32> {
    let t2 = t * t;
    let t3 = t2 * t;
    return vec4<f32>(
        -0.5 * t3 + t2 - 0.5 * t,
        1.5 * t3 - 2.5 * t2 + 1.0,
        -1.5 * t3 + 2.0 * t2 + 0.5 * t,
        0.5 * t3 - 0.5 * t2,
    );
}

// One ring tap of dn_sharp_visibility_history at previous grid pixel `q`: (w × value,
// w × second moment, w), or w = -1e9 where the tap cannot be used (outside the grid, no surface,
// or off this pixel's plane). Only the plane is tested (with the previous distance `dist` of
// `pred`), not the normal (no decode per tap): a tap of another normal on the same plane is
// rare, weighs little, and the result is clamped to the neighbourhood anyway.
fn dn_ring_tap(q: vec2<i32>, w: f32, n: vec3<f32>, pred: vec3<f32>, dist: f32) -> vec3<f32> {
    let cq = dn_clamped(q);
    let j = dn_index(cq);
    let g = guide_prev[j];
    let r = hist_prev0[j];
    let gp = dn_guide_position(cq, bitcast<f32>(g.x), true);
    let on_plane = abs(dot(n, gp - pred)) < 0.01 * dist;
    if !dn_in_grid(q) || !dn_guide_valid(g) || !on_plane {
        return vec3<f32>(0.0, 0.0, -1e9);
    }
    return w * vec3<f32>(dn_value(r).x, dn_rec_z(r), 1.0);
}

// Cell (column, row) of ring tap `k` (0..8) in the Catmull-Rom footprint's 4×4: the two above
// the bilinear taps, then left and right of each of their rows, then the two below. Computed,
// not read from a constant array, so that no array is indexed at run time.
fn dn_ring_cell(k: i32) -> vec2<i32> {
    if k < 2 {
        return vec2<i32>(1 + k, 0);
    }
    if k < 6 {
        return vec2<i32>(select(0, 3, (k & 1) == 1), 1 + (k - 2) / 2);
    }
    return vec2<i32>(k - 5, 3);
}

// Component `i` (0..4) of `v`, by selects (no dynamic vector index).
fn dn_component(v: vec4<f32>, i: i32) -> f32 {
    return select(select(select(v.x, v.y, i == 1), v.z, i == 2), v.w, i == 3);
}

// A visibility history resampled with a Catmull-Rom kernel: (value, second moment, 1), or z = 0
// where it cannot be (a tap outside the grid or showing another surface: the caller keeps the
// bilinear history). The bilinear kernel blurs by its sub-pixel offset every frame, and a shadow
// edge one or two grid pixels wide, which keeps its history, faded along a pan; the cubic's
// negative lobes undo most of that blur. `base`, `f`: the bilinear footprint's first tap and
// fraction; `inner`: its four records (all usable). The kernel's 4×4 corners weigh at most
// 0.0055 each and are left out (12 taps, weights renormalised). The value is clamped to [0, 1],
// the moment between the value's square and the value (the bounds of a [0, 1] signal's).
//
// The ring's 8 taps are a loop, not written out: written out, SwiftShader's pipeline compile
// (Chromium's WebGPU without a GPU) grew steeply with each tap (4 taps 21 s, 8 past its GPU
// watchdog's 3 minutes); the loop compiles in 2 s.
fn dn_sharp_visibility_history(
    base: vec2<i32>,
    f: vec2<f32>,
    inner: array<DnRecord, 4>,
    n: vec3<f32>,
    pred: vec3<f32>,
) -> vec3<f32> {
    let wx = dn_catmull_rom(f.x);
    let wy = dn_catmull_rom(f.y);
    let dist = max(dn_prev_view_distance(pred), 1e-6);
    var sum = vec3<f32>(0.0);
    for (var k = 0; k < 8; k++) {
        let c = dn_ring_cell(k);
        let w = dn_component(wx, c.x) * dn_component(wy, c.y);
        sum += dn_ring_tap(base - vec2<i32>(1) + c, w, n, pred, dist);
    }
    if sum.z < -1.0 {
        return vec3<f32>(0.0);
    }
    let w0 = wx.y * wy.y;
    let w1 = wx.z * wy.y;
    let w2 = wx.y * wy.z;
    let w3 = wx.z * wy.z;
    sum += w0 * vec3<f32>(dn_value(inner[0]).x, dn_rec_z(inner[0]), 1.0);
    sum += w1 * vec3<f32>(dn_value(inner[1]).x, dn_rec_z(inner[1]), 1.0);
    sum += w2 * vec3<f32>(dn_value(inner[2]).x, dn_rec_z(inner[2]), 1.0);
    sum += w3 * vec3<f32>(dn_value(inner[3]).x, dn_rec_z(inner[3]), 1.0);
    let v = clamp(sum.x / sum.z, 0.0, 1.0);
    let m2 = clamp(sum.y / sum.z, v * v, v);
    return vec3<f32>(v, m2, 1.0);
}

// Whether the previous frame's taps (records `h`, weights `w`; 0: unusable) straddle a hard
// visibility edge: taps that each saw one value all along (their sample spread is small) but
// disagree. Resampling them would blur the edge by the reprojection's sub-pixel offset every
// frame, while this frame's sample of a hard shadow is exact: the history is dropped there.
fn dn_hard_edge(h: array<DnRecord, 4>, w: vec4<f32>) -> bool {
    var lo = 1e30;
    var hi = -1e30;
    var spread = 0.0;
    for (var k = 0; k < 4; k++) {
        if w[k] <= 0.0 {
            continue;
        }
        let v = dn_value(h[k]).x;
        lo = min(lo, v);
        hi = max(hi, v);
        spread = max(spread, max(dn_rec_z(h[k]) - v * v, 0.0));
    }
    return hi - lo > 0.5 && spread < 0.02;
}

// Whether the shadow edge at grid pixel `p` (surface point `pos`) is narrower than a grid pixel:
// its penumbra, 2 × `hit` (the largest occluder distance of the 3×3 neighbours) × the light's
// tan, against the size of a grid pixel at `pos`. The tan is read from the raw sample of `lit`,
// a lit neighbour: the shadow trace writes a lit pixel's value as minus that tan. Inputs written
// elsewhere, whose lit value is -1, read as a very wide penumbra (no edge is called sharp).
fn dn_sharp_shadow_edge(s: u32, lit: vec2<u32>, hit: f32, pos: vec3<f32>) -> bool {
    var t: f32;
    if s == 0u {
        t = textureLoad(dn_input0, dn_texel(lit), 0).x;
    } else {
        t = textureLoad(dn_input1, dn_texel(lit), 0).x;
    }
    let tan_l = max(-dn_sanitize(vec4<f32>(t)).x, 0.0);
    // Viewport pixels per world unit at `pos`, across the view direction.
    let v = dn_to_eye(pos);
    let a = select(vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), abs(v.y) > 0.9);
    let e = normalize(cross(v, a));
    let k = 0.01 * max(dn_view_distance(pos), 1e-6);
    let ppu = length(gb_project(pos + e * k).xy - gb_project(pos).xy) / k;
    return 2.0 * hit * tan_l * ppu < f32(dp.grid.z);
}

// Loads the workgroup's tile (every invocation takes part, before any returns).
fn dn_fill_tile(wg: vec2<u32>, lid: u32) {
    let origin = vec2<i32>(wg * 8u) - vec2<i32>(1);
    for (var t = lid; t < DN_TILE * DN_TILE; t += 64u) {
        let q = origin + vec2<i32>(i32(t % DN_TILE), i32(t / DN_TILE));
        var ok = false;
        if dn_in_grid(q) {
            ok = dn_traced(vec2<u32>(q)) && dn_texel_inside(vec2<u32>(q));
        }
        dn_tile_ok[t] = select(0u, 1u, ok);
        if ok {
            for (var s = 0u; s < DN_SIGNALS; s++) {
                dn_tile[s][t] = dn_load_input(s, dn_texel(vec2<u32>(q)));
            }
        }
    }
}

@compute @workgroup_size(8, 8)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) lindex: u32,
) {
    // The G-buffer and the previous frame's taps are read before the tile is filled and the
    // workgroup waits on it: no load can be moved across the barrier, and read after it they
    // would add their two latencies (the taps' addresses depend on the G-buffer) to the tile's
    // instead of overlapping it. Nothing returns before the barrier (it needs every invocation).
    let p = gid.xy;
    let in_grid = gid.x < dp.grid.x && gid.y < dp.grid.y;
    let inside = in_grid && dn_texel_inside(p);
    let texel = dn_texel(p);

    // gb_surface unprojects the jittered depth where it was sampled (trace/gbuffer.wgsl).
    var surf: GbSurface;
    if inside {
        surf = gb_surface(texel);
    }
    let pos = surf.position;
    let n = surf.normal;

    // Bilinear taps of the previous frame that show this surface, written out: the four
    // previous guides and history records are loaded before any is used (indices clamped into
    // the viewport; unusable taps get weight 0), so that their latencies overlap.
    var pred = pos;
    var base = vec2<i32>(0);
    var f = vec2<f32>(0.0);
    var h00: DnRecord;
    var h01: DnRecord;
    var h02: DnRecord;
    var h03: DnRecord;
    var h10: DnRecord;
    var h11: DnRecord;
    var h12: DnRecord;
    var h13: DnRecord;
    var w0 = 0.0;
    var w1 = 0.0;
    var w2 = 0.0;
    var w3 = 0.0;
    if inside && surf.valid {
        // Where this surface was in the previous frame (continuous viewport pixel coordinates),
        // then on the previous frame's grid (below).
        var prev_xy: vec2<f32>;
        let size = vec2<f32>(dp.viewport.zw);
        if dp.motion_type == 1u {
            let m = textureLoad(dn_motion, texel, 0).xy * dp.motion_scale.xy;
            let uv = (vec2<f32>(dn_grid_pixel(p)) + 0.5 - dp.jitter.xy) / size;
            prev_xy = (uv + m) * size + dp.jitter.zw;
        } else {
            if dp.motion_type == 2u {
                pred = pos + textureLoad(dn_motion, texel, 0).xyz * dp.motion_scale.xyz;
            }
            let c = gb_project_prev(pred);
            prev_xy = c.xy + dp.jitter.zw;
            if c.w <= 0.0 {
                prev_xy = vec2<f32>(-1e6);
            }
        }
        let use_history = dp.discard_history == 0u && all(abs(prev_xy) < vec2<f32>(1e6));
        // The previous grid's pixel g covered viewport pixel g · block + its traced pixel.
        prev_xy = (prev_xy - 0.5 - vec2<f32>(dp.lattice.zw)) / f32(dp.grid.z) + 0.5;
        let base_f = select(vec2<f32>(0.0), floor(prev_xy - 0.5), use_history);
        f = prev_xy - 0.5 - base_f;
        base = vec2<i32>(base_f);
        let q0 = base;
        let q1 = base + vec2<i32>(1, 0);
        let q2 = base + vec2<i32>(0, 1);
        let q3 = base + vec2<i32>(1, 1);
        let j0 = dn_clamped_index(q0);
        let j1 = dn_clamped_index(q1);
        let j2 = dn_clamped_index(q2);
        let j3 = dn_clamped_index(q3);
        let pg0 = guide_prev[j0];
        let pg1 = guide_prev[j1];
        let pg2 = guide_prev[j2];
        let pg3 = guide_prev[j3];
        h00 = hist_prev0[j0];
        h01 = hist_prev0[j1];
        h02 = hist_prev0[j2];
        h03 = hist_prev0[j3];
        h10 = h00;
        h11 = h01;
        h12 = h02;
        h13 = h03;
        if DN_SIGNALS > 1u {
            h10 = hist_prev1[j0];
            h11 = hist_prev1[j1];
            h12 = hist_prev1[j2];
            h13 = hist_prev1[j3];
        }
        if use_history {
            w0 = dn_history_weight(q0, pg0, (1.0 - f.x) * (1.0 - f.y), pos, n, pred);
            w1 = dn_history_weight(q1, pg1, f.x * (1.0 - f.y), pos, n, pred);
            w2 = dn_history_weight(q2, pg2, (1.0 - f.x) * f.y, pos, n, pred);
            w3 = dn_history_weight(q3, pg3, f.x * f.y, pos, n, pred);
        }
    }

    dn_fill_tile(wg.xy, lindex);
    workgroupBarrier();
    if !in_grid {
        return;
    }
    let i = dn_index(p);
    if !inside {
        // A block whose traced pixel lies past the viewport this frame: nothing traced.
        guide_cur[i] = vec2<u32>(DN_INVALID);
        for (var s = 0u; s < DN_SIGNALS; s++) {
            dn_store_hist(s, i, dn_pack_signal(vec4<f32>(0.0), 0.0, 0.0));
        }
        return;
    }
    if !surf.valid {
        guide_cur[i] = vec2<u32>(DN_INVALID);
        for (var s = 0u; s < DN_SIGNALS; s++) {
            let v = dn_sample(s, p, false, pos, n);
            dn_store_hist(s, i, dn_pack_signal(v, 0.0, 0.0));
        }
        return;
    }
    guide_cur[i] = dn_pack_guide(dn_guide_depth(texel, pos), n, gb_roughness(texel));

    let wsum = w0 + w1 + w2 + w3;

    // This pixel's entry in the tile.
    let tc = (lid.y + 1u) * DN_TILE + lid.x + 1u;
    for (var s = 0u; s < DN_SIGNALS; s++) {
        // A traced pixel's sample is the tile's centre (the same decoded load); a checkerboard
        // hole is rebuilt from its neighbours.
        var cur: vec4<f32>;
        if dn_tile_ok[tc] != 0u {
            cur = dn_tile[s][tc];
        } else {
            cur = dn_sample(s, p, true, pos, n);
        }

        // Neighbourhood statistics of the current input (traced pixels only).
        var m1 = vec4<f32>(0.0);
        var m2 = vec4<f32>(0.0);
        var cnt = 0.0;
        var lo = vec4<f32>(1e30);
        var hi = vec4<f32>(-1e30);
        // A neighbour whose sample is 1 (for a shadow: lit), for dn_sharp_shadow_edge.
        var lit = p;
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let t = (lid.y + u32(1 + dy)) * DN_TILE + lid.x + u32(1 + dx);
                if dn_tile_ok[t] == 0u {
                    continue;
                }
                let v = dn_tile[s][t];
                m1 += v;
                m2 += v * v;
                cnt += 1.0;
                lo = min(lo, v);
                hi = max(hi, v);
                if v.x == 1.0 {
                    lit = vec2<u32>(vec2<i32>(p) + vec2<i32>(dx, dy));
                }
            }
        }
        let mean = m1 / max(cnt, 1.0);
        let sigma = sqrt(max(m2 / max(cnt, 1.0) - mean * mean, vec4<f32>(0.0)));
        let kind = dn_kind(s);

        var hist = vec4<f32>(0.0);
        var hist_m2 = 0.0;
        var hist_len = 0.0;
        let second = s == 1u;
        let ha = select(h00, h10, second);
        let hb = select(h01, h11, second);
        let hc = select(h02, h12, second);
        let hd = select(h03, h13, second);
        let visibility = kind == DN_KIND_SHADOW || kind == DN_KIND_MULTI_SHADOW;
        // This frame's samples around a shadow edge sharper than a grid pixel are exact (the
        // point each pixel shows is lit or not), and history resampled at a sub-pixel offset,
        // frame after frame, only blurs them: thin shadows faded along a pan. Wider penumbrae
        // keep their history (their 1-spp samples are noise).
        let sharp = kind == DN_KIND_SHADOW && cnt > 0.0 && lo.x == 0.0 && hi.x == 1.0
            && dn_sharp_shadow_edge(s, lit, hi.w, pos);
        let edge = visibility && (sharp || dn_hard_edge(array<DnRecord, 4>(ha, hb, hc, hd),
                                                        vec4<f32>(w0, w1, w2, w3)));
        let has_history = wsum > 1e-3 && !edge;
        if has_history {
            let inv = 1.0 / wsum;
            hist = (w0 * dn_value(ha) + w1 * dn_value(hb) + w2 * dn_value(hc) + w3 * dn_value(hd)) * inv;
            hist_m2 = (w0 * dn_rec_z(ha) + w1 * dn_rec_z(hb) + w2 * dn_rec_z(hc) + w3 * dn_rec_z(hd)) * inv;
            hist_len = (w0 * dn_rec_len(ha) + w1 * dn_rec_len(hb) + w2 * dn_rec_len(hc)
                + w3 * dn_rec_len(hd)) * inv;
            // Where the four taps hold one value the bilinear history is kept: that is most of
            // a frame (lit or in umbra all along, where the cubic clamped to [0, 1] returns the
            // same value), and the cubic's 16 more loads go only to taps that differ.
            let va = vec4<f32>(dn_value(ha).x, dn_value(hb).x, dn_value(hc).x, dn_value(hd).x);
            let differ = any(va != vec4<f32>(va.x));
            if DN_SHARP_HISTORY && differ && min(min(w0, w1), min(w2, w3)) > 0.0 {
                let sharp_hist = dn_sharp_visibility_history(
                    base, f, array<DnRecord, 4>(ha, hb, hc, hd), n, pred);
                if sharp_hist.z > 0.0 {
                    hist = vec4<f32>(vec3<f32>(sharp_hist.x), hist.w);
                    hist_m2 = sharp_hist.y;
                }
            }
        }
        // The spread of the samples this pixel has seen (its luminance moments over the
        // history). A 3×3 neighbourhood of a sparse 1-spp signal (dark radiance with rare
        // bright hits, a penumbra's 0/1 visibility) is often all alike, so its spread alone
        // would call the rare samples the mean is made of outliers and clamp them away: a
        // darkening bias that grows with every frame of history.
        //
        // No sample is clamped as a firefly here: a threshold from the neighbourhood or the
        // history rejects every sample of a sparse signal (bounce light through a small window:
        // most pixels' history is 0, so each bright sample looks like a firefly and the signal
        // is lost whole). A lone bright sample is spread by the à-trous filter instead, whose
        // luminance weight is symmetric in the noise of both pixels, and fades into the history:
        // its energy is kept.
        var sigma_t = 0.0;
        if hist_len >= 1.0 {
            let hl = dn_luminance(hist.xyz);
            sigma_t = sqrt(max(hist_m2 - hl * hl, 0.0));
        }
        if has_history {
            // Ghosting: the history may not leave the range the current neighbourhood and the
            // pixel's own sample spread allow. The range has a floor too, for the first frames
            // of a sparse signal, when neither spread is known yet.
            var floor = 0.25 * max(abs(mean), abs(hist));
            if kind != DN_KIND_SPECULAR && kind != DN_KIND_DIFFUSE {
                floor += vec4<f32>(0.2);
            }
            let half = CLAMP_SIGMAS * max(sigma, vec4<f32>(sigma_t)) + floor;
            if visibility && cnt > 0.0 {
                // Visibility: the range of the neighbourhood's samples, widened by the pixel's
                // own sample spread. Where every neighbour agrees (umbra, or fully lit) the
                // history takes their value exactly: a shadow that moved leaves no ghost, and a
                // hard shadow stays as exact as its raw samples.
                let wide = vec4<f32>(CLAMP_SIGMAS * sigma_t);
                hist = clamp(hist, lo - wide, hi + wide);
            } else {
                hist = clamp(hist, mean - half, mean + half);
            }
        }
        let len = min(hist_len + 1.0, dp.max_history);
        let alpha = 1.0 / len;
        let lum = dn_luminance(cur.xyz);
        let value = mix(hist, cur, alpha);
        let moment2 = mix(hist_m2, lum * lum, alpha);
        dn_store_hist(s, i, dn_pack_signal(value, moment2, len));
    }
}
