// TraceShadowTask and TraceMultiShadowTask: one ray per pixel and light towards a random point
// of the light (soft shadows: the disc of a sphere light facing the pixel, the cone of a
// directional light's angular extent). Entry points: `shadow` (one light, output0 = closest hit
// distance, or where the light is visible minus the tangent of its angular radius, at least
// TR_LIT_MIN; -1 where no surface is) and `multi_shadow` (up to 32 lights, the packed
// format of docs/trace-tasks.md in output0 and output1). The G-buffer is at
// group 1 (trace/common).

#import trace/common
#param OUTPUT0_FORMAT
#param OUTPUT1_FORMAT

@group(2) @binding(4) var out0: texture_storage_2d<{{OUTPUT0_FORMAT}}, write>;
@group(2) @binding(5) var out1: texture_storage_2d<{{OUTPUT1_FORMAT}}, write>;

// The light reaches the pixel?  0: no (beyond range, outside the cone: not traced, written as
// lit), 1: traced, 2: the surface faces away from the sampled point (shadowed at distance 0).
struct TrShadowRay {
    status: u32,
    dir: vec3<f32>,
    t_max: f32,
}

fn tr_shadow_ray(l: TrLight, p: vec3<f32>, n: vec3<f32>, u: vec2<f32>) -> TrShadowRay {
    var r: TrShadowRay;
    r.status = 1u;
    let kind = tr_branch(u32(l.c.y + 0.5));
    let d = tr_disc(u);
    if kind == 0u {
        let to_light = -l.a.xyz;
        let b = tr_basis(to_light);
        r.dir = normalize(to_light + l.a.w * (b[0] * d.x + b[1] * d.y));
        r.t_max = tp.lengths.x;
    } else {
        let to_centre = l.a.xyz - p;
        let dist = length(to_centre);
        if dist > l.c.x {
            r.status = 0u;
            return r;
        }
        if kind == 2u && dot(-to_centre, l.b.xyz) < l.b.w * dist {
            r.status = 0u;
            return r;
        }
        var q = l.a.xyz;
        if dist > 0.0 {
            let b = tr_basis(to_centre / dist);
            q = q + l.a.w * (b[0] * d.x + b[1] * d.y);
        }
        let v = q - p;
        let len = length(v);
        if !(len > 0.0) {
            r.status = 0u;
            return r;
        }
        r.dir = v / len;
        r.t_max = min(len, tp.lengths.x);
    }
    if dot(r.dir, n) <= 0.0 {
        r.status = 2u;
    }
    return r;
}

// Hit distance towards light `li`: -1 visible (or unreachable), ≥ 0 occluded.
fn tr_light_hit(li: u32, s: GbSurface, origin: vec3<f32>, rng: ptr<function, TrRng>) -> f32 {
    let u = vec2<f32>(tr_next(rng), tr_next(rng));
    let r = tr_shadow_ray(tp.lights[li], s.position, s.normal, u);
    if r.status == 0u {
        return -1.0;
    }
    if r.status == 2u {
        return 0.0;
    }
    let ray = RtRay(origin, tr_t_min(s.view_distance), r.dir, r.t_max);
    let h = rt_find(ray, tp.misc.z, tr_flag(TR_FLAG_FIRST_HIT));
    if h.instance != RT_NO_INDEX {
        return h.t;
    }
    return -1.0;
}

@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn shadow(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let px = tr_invocation_pixel(wid, nwg, lid);
    if !px.valid {
        return;
    }
    let s = gb_surface(px.texel);
    if !s.valid {
        textureStore(out0, px.texel, vec4<f32>(-1.0));
        return;
    }
    var rng = tr_rng(px.texel);
    let origin = tr_origin(s.position, s.normal, s.view_distance);
    let t = tr_light_hit(0u, s, origin, &rng);
    // Lit: the light's angular size instead of -1 (still negative), which the shadow denoiser
    // needs for the penumbra's width (occluder distance × 2 tan): hard edges keep their exact
    // samples, penumbrae their history.
    textureStore(out0, px.texel, vec4<f32>(select(t, -tr_light_tan(tp.lights[0], s.position), t < 0.0)));
}

// Smallest magnitude of a lit pixel's value: f16's smallest normal, so that it stays negative in
// every float output format.
const TR_LIT_MIN: f32 = 6.103515625e-5;

// tan of the angular radius of light `l` seen from `p` (a sphere light's radius over its
// distance), at least TR_LIT_MIN.
fn tr_light_tan(l: TrLight, p: vec3<f32>) -> f32 {
    var t = l.a.w;
    if tr_branch(u32(l.c.y + 0.5)) != 0u {
        t = l.a.w / max(length(l.a.xyz - p), 1e-6);
    }
    return max(t, TR_LIT_MIN);
}

// Light li's bit in the packed visibility: channel li / 8, bit li % 8.
fn tr_light_bit(li: u32) -> vec4<u32> {
    let bit = 1u << (li % 8u);
    return select(vec4<u32>(0u), vec4<u32>(bit), vec4<u32>(0u, 1u, 2u, 3u) == vec4<u32>(li / 8u));
}

@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn multi_shadow(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let px = tr_invocation_pixel(wid, nwg, lid);
    if !px.valid {
        return;
    }
    let s = gb_surface(px.texel);
    let count = tr_branch(tp.misc.y);
    if !s.valid {
        // No surface: every light visible.
        textureStore(out0, px.texel, vec4<f32>(1.0, -1.0, -1.0, f32(count)));
        var all = vec4<u32>(0u);
        for (var li = 0u; li < count; li += 1u) {
            all = all | tr_light_bit(li);
        }
        textureStore(out1, px.texel, vec4<f32>(all));
        return;
    }
    var rng = tr_rng(px.texel);
    let origin = tr_origin(s.position, s.normal, s.view_distance);
    var bits = vec4<u32>(0u);
    var visible = 0u;
    var closest = -1.0;
    var sum = 0.0;
    var occluded = 0u;
    for (var li = 0u; li < count; li += 1u) {
        let t = tr_light_hit(li, s, origin, &rng);
        if t < 0.0 {
            visible += 1u;
            bits = bits | tr_light_bit(li);
        } else {
            occluded += 1u;
            sum += t;
            closest = select(t, min(closest, t), closest >= 0.0);
        }
    }
    let mean = select(-1.0, sum / f32(max(occluded, 1u)), occluded > 0u);
    textureStore(
        out0,
        px.texel,
        vec4<f32>(f32(visible) / f32(max(count, 1u)), closest, mean, f32(count)),
    );
    textureStore(out1, px.texel, vec4<f32>(bits));
}
