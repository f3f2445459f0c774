// DEV (session 29 experiment): rewrites every 64-byte BVH2 node of the BLAS pool in place as a
// 32-byte quantised node in its first two vec4s:
//   a = (ox | ex, oy | ey, oz | ez, lref), b = (rref, q0, q1, q2)
// o: the node's origin (the children's union's min rounded down to 16 mantissa bits), its low
// byte holding the biased exponent of the axis' step s = 2^(e-127); q: 12 bytes, the children's
// planes as o + q·s (left lo.xyz, left hi.xyz, right lo.xyz, right hi.xyz), lo rounded down and
// hi up with the decode's own arithmetic, so a decoded box always holds the stored one. An empty
// child (min.x > max.x) decodes with lo.x > hi.x.
@group(0) @binding(0) var<storage, read_write> pool: array<vec4<u32>>;

fn q_origin(x: f32) -> u32 {
    let b = bitcast<u32>(x);
    if x >= 0.0 || (b & 0xffu) == 0u {
        return b & 0xffffff00u;
    }
    // Negative with dropped bits: one step away from zero (down).
    return (b & 0xffffff00u) + 0x100u;
}

fn step_of(be: u32) -> f32 {
    return bitcast<f32>(be << 23u);
}

fn dq(o: f32, q: u32, s: f32) -> f32 {
    return o + f32(q) * s;
}

fn q_lo(o: f32, s: f32, x: f32) -> u32 {
    var q = u32(clamp(floor((x - o) / s), 0.0, 255.0));
    for (var i = 0u; i < 4u && q > 0u && dq(o, q, s) > x; i += 1u) {
        q -= 1u;
    }
    return q;
}

fn q_hi(o: f32, s: f32, x: f32) -> u32 {
    var q = u32(clamp(ceil((x - o) / s), 0.0, 255.0));
    for (var i = 0u; i < 4u && q < 255u && dq(o, q, s) < x; i += 1u) {
        q += 1u;
    }
    return q;
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * nwg.x + wid.x) * 64u + lid;
    if i >= arrayLength(&pool) / 4u {
        return;
    }
    let n0 = pool[i * 4u];
    let n1 = pool[i * 4u + 1u];
    let n2 = pool[i * 4u + 2u];
    let n3 = pool[i * 4u + 3u];
    let lmin = bitcast<vec3<f32>>(n0.xyz);
    let lmax = bitcast<vec3<f32>>(n1.xyz);
    let rmin = bitcast<vec3<f32>>(n2.xyz);
    let rmax = bitcast<vec3<f32>>(n3.xyz);
    let l_ok = lmin.x <= lmax.x;
    let r_ok = rmin.x <= rmax.x;
    var lo = vec3<f32>(0.0);
    var hi = vec3<f32>(0.0);
    if l_ok && r_ok {
        lo = min(lmin, rmin);
        hi = max(lmax, rmax);
    } else if l_ok {
        lo = lmin;
        hi = lmax;
    } else if r_ok {
        lo = rmin;
        hi = rmax;
    }
    var ob = vec3<u32>(q_origin(lo.x), q_origin(lo.y), q_origin(lo.z));
    let o = bitcast<vec3<f32>>(ob);
    var be = vec3<u32>(1u);
    var s = vec3<f32>(0.0);
    for (var k = 0u; k < 3u; k += 1u) {
        let ext = (hi[k] - o[k]) / 255.0;
        var e = clamp(((bitcast<u32>(ext) >> 23u) & 0xffu) + 1u, 1u, 254u);
        // A step of at least 2^-20 of |o|: o + q·s is then exact and an empty child's lo > hi.
        let eo = (bitcast<u32>(abs(o[k])) >> 23u) & 0xffu;
        e = max(e, select(1u, eo - 20u, eo > 21u));
        for (var j = 0u; j < 8u && e < 254u && dq(o[k], 255u, step_of(e)) < hi[k]; j += 1u) {
            e += 1u;
        }
        be[k] = e;
        s[k] = step_of(e);
    }
    var lq = vec3<u32>(255u, 0u, 0u);
    var lh = vec3<u32>(0u, 0u, 0u);
    if l_ok {
        lq = vec3<u32>(q_lo(o.x, s.x, lmin.x), q_lo(o.y, s.y, lmin.y), q_lo(o.z, s.z, lmin.z));
        lh = vec3<u32>(q_hi(o.x, s.x, lmax.x), q_hi(o.y, s.y, lmax.y), q_hi(o.z, s.z, lmax.z));
    }
    var rq = vec3<u32>(255u, 0u, 0u);
    var rh = vec3<u32>(0u, 0u, 0u);
    if r_ok {
        rq = vec3<u32>(q_lo(o.x, s.x, rmin.x), q_lo(o.y, s.y, rmin.y), q_lo(o.z, s.z, rmin.z));
        rh = vec3<u32>(q_hi(o.x, s.x, rmax.x), q_hi(o.y, s.y, rmax.y), q_hi(o.z, s.z, rmax.z));
    }
    let a = vec4<u32>(ob.x | be.x, ob.y | be.y, ob.z | be.z, n0.w);
    let b = vec4<u32>(
        n1.w,
        lq.x | (lq.y << 8u) | (lq.z << 16u) | (lh.x << 24u),
        lh.y | (lh.z << 8u) | (rq.x << 16u) | (rq.y << 24u),
        rq.z | (rh.x << 8u) | (rh.y << 16u) | (rh.z << 24u),
    );
    pool[i * 4u] = a;
    pool[i * 4u + 1u] = b;
}
