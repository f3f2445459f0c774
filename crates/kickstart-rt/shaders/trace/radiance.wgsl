// TraceSpecularTask (`specular`) and TraceDiffuseTask (`diffuse`): one ray per pixel, the
// incoming radiance along it (RGB) and its hit distance (A) written to output0. Radiance at a hit
// comes from the lighting cache (cache_radiance, group 3: the sampling contract of
// src/cache/mod.rs), or from the engine's direct lighting texture where the hit is visible in it;
// a miss reads the environment map.
//
// The diffuse pass can also write ambient occlusion from its own rays (TR_FLAG_AO: the hit
// distance within the AO radius, in the AO task's format), one traversal for both effects.
//
// A second output (the specular's demodulation factor, the diffuse's AO) is declared only when
// the task has one (a pipeline must not reference a binding its layout lacks): the pass composes
// one of trace/second_output/none or trace/second_output/texture beside this module, defining
// tr_store_second.

#import trace/common
#import cache/sample
#param OUTPUT0_FORMAT

@group(2) @binding(4) var out0: texture_storage_2d<{{OUTPUT0_FORMAT}}, write>;

// Largest finite f16: a miss's hit distance when the ray length is unbounded.
const TR_MISS_DISTANCE: f32 = 65504.0;
// The direct lighting texture is used where the view distance of the surface the G-buffer holds
// at the hit's pixel is within this fraction of the hit's own (a tolerance that scales with
// distance; a depth test, since the hit may lie anywhere inside the texel's footprint).
const TR_DIRECT_LIGHTING_TOLERANCE: f32 = 0.01;

struct TrTraced {
    radiance: vec3<f32>,
    t: f32,
    hit: bool,
}

// Radiance arriving at `origin` from direction `dir` and the hit distance (the miss distance on
// a miss).
fn tr_incoming(origin: vec3<f32>, dir: vec3<f32>, t_min: f32) -> TrTraced {
    var r: TrTraced;
    let hit = rt_closest_hit(RtRay(origin, t_min, dir, tp.lengths.x), tp.misc.z);
    r.hit = hit.hit != 0u;
    if !r.hit {
        r.radiance = tr_environment(dir);
        r.t = min(tp.lengths.x, TR_MISS_DISTANCE);
        return r;
    }
    r.t = hit.t;
    let p = origin + dir * hit.t;
    if tr_flag(TR_FLAG_DIRECT_LIGHTING) {
        let q = gb_project(p);
        // Where the G-buffer holds the point: the jittered position.
        let xy = q.xy + gb_jitter();
        let size = vec2<f32>(gb.viewport.zw);
        if q.w > 0.0 && all(xy >= vec2<f32>(0.0)) && all(xy < size) {
            let texel = gb.viewport.xy + vec2<u32>(xy);
            let s = gb_surface(texel);
            let d = gb_view_distance(p);
            if s.valid && abs(s.view_distance - d) <= TR_DIRECT_LIGHTING_TOLERANCE * d {
                r.radiance = textureLoad(tr_direct_lighting, texel, 0).xyz;
                return r;
            }
        }
    }
    r.radiance = cache_radiance(hit.instance, hit.primitive, vec2<f32>(hit.u, hit.v), tr_flag(TR_FLAG_BILINEAR));
    return r;
}

// GGX visible-normal sample (Heitz 2018, "Sampling the GGX Distribution of Visible Normals"):
// `v` the view direction in the tangent frame (z up), `alpha` = roughness².
fn tr_ggx_vndf(v: vec3<f32>, alpha: f32, u: vec2<f32>) -> vec3<f32> {
    let vh = normalize(vec3<f32>(alpha * v.x, alpha * v.y, v.z));
    let lensq = vh.x * vh.x + vh.y * vh.y;
    var t1 = vec3<f32>(1.0, 0.0, 0.0);
    if lensq > 0.0 {
        t1 = vec3<f32>(-vh.y, vh.x, 0.0) * inverseSqrt(lensq);
    }
    let t2 = cross(vh, t1);
    let r = sqrt(u.x);
    let phi = 2.0 * TR_PI * u.y;
    let p1 = r * cos(phi);
    var p2 = r * sin(phi);
    let s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2;
    let nh = p1 * t1 + p2 * t2 + sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh;
    return normalize(vec3<f32>(alpha * nh.x, alpha * nh.y, max(0.0, nh.z)));
}

// Pre-integrated specular reflectance of GGX with Schlick Fresnel (Karis' analytic fit, "Physically
// Based Shading on Mobile", 2014): the demodulation factor.
fn tr_specular_albedo(f0: vec3<f32>, n_dot_v: f32, roughness: f32) -> vec3<f32> {
    let c0 = vec4<f32>(-1.0, -0.0275, -0.572, 0.022);
    let c1 = vec4<f32>(1.0, 0.0425, 1.04, -0.04);
    let r = roughness * c0 + c1;
    let a004 = min(r.x * r.x, exp2(-9.28 * n_dot_v)) * r.x + r.y;
    let ab = vec2<f32>(-1.04, 1.04) * a004 + r.zw;
    return f0 * ab.x + ab.y;
}

@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn specular(
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
        textureStore(out0, px.texel, vec4<f32>(0.0));
        if tr_flag(TR_FLAG_DEMODULATE) {
            tr_store_second(px.texel, vec4<f32>(0.0));
        }
        return;
    }
    let roughness = gb_roughness(px.texel);
    let alpha = roughness * roughness;
    let basis = tr_basis(s.normal);
    // The view direction in the tangent frame, kept above the surface (normal maps and
    // interpolated normals can face away from the eye).
    var v = s.to_eye * basis;
    v = normalize(vec3<f32>(v.xy, max(v.z, 1e-4)));
    var rng = tr_rng(px.texel);
    let u = vec2<f32>(tr_next(&rng), tr_next(&rng));
    var h = vec3<f32>(0.0, 0.0, 1.0);
    if alpha > 1e-7 {
        h = tr_ggx_vndf(v, alpha, u);
    }
    var l = reflect(-v, h);
    if l.z <= 0.0 {
        // Reflected below the surface: fall back to the mirror direction.
        l = reflect(-v, vec3<f32>(0.0, 0.0, 1.0));
    }
    let dir = normalize(basis * l);
    let origin = tr_origin(s.position, s.normal, s.view_distance);
    let traced = tr_incoming(origin, dir, tr_t_min(s.view_distance));
    var radiance = traced.radiance;
    if tr_flag(TR_FLAG_DEMODULATE) {
        let albedo = tr_specular_albedo(gb_specular(px.texel).xyz, v.z, roughness);
        radiance = radiance / max(albedo, vec3<f32>(1e-3));
        tr_store_second(px.texel, vec4<f32>(albedo, 1.0));
    }
    textureStore(out0, px.texel, vec4<f32>(radiance, traced.t));
}

// Normalised Disney diffuse (Burley 2012, renormalised as in Lagarde & de Rousiers, "Moving
// Frostbite to PBR", 2014) relative to Lambert: the weight of a cosine-sampled ray.
fn tr_disney_weight(n_dot_v: f32, n_dot_l: f32, l_dot_h: f32, roughness: f32) -> f32 {
    let energy_bias = 0.5 * roughness;
    let energy_factor = mix(1.0, 1.0 / 1.51, roughness);
    let fd90 = energy_bias + 2.0 * l_dot_h * l_dot_h * roughness;
    let light = 1.0 + (fd90 - 1.0) * pow(1.0 - n_dot_l, 5.0);
    let view = 1.0 + (fd90 - 1.0) * pow(1.0 - n_dot_v, 5.0);
    return light * view * energy_factor;
}

@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn diffuse(
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
        textureStore(out0, px.texel, vec4<f32>(0.0));
        if tr_flag(TR_FLAG_AO) {
            tr_store_second(px.texel, vec4<f32>(1.0));
        }
        return;
    }
    var rng = tr_rng(px.texel);
    let u = vec2<f32>(tr_next(&rng), tr_next(&rng));
    let dir = tr_cosine(s.normal, u);
    let origin = tr_origin(s.position, s.normal, s.view_distance);
    let traced = tr_incoming(origin, dir, tr_t_min(s.view_distance));
    if tr_flag(TR_FLAG_AO) {
        // The AO task's output for this cosine-weighted ray: the hit distance over the radius,
        // 1 where nothing is hit within it (trace/ao.wgsl).
        let radius = tp.lengths.y;
        var ao = 1.0;
        if traced.hit && traced.t <= radius {
            ao = clamp(traced.t / radius, 0.0, 1.0);
        }
        tr_store_second(px.texel, vec4<f32>(ao));
    }
    var radiance = traced.radiance;
    if tr_flag(TR_FLAG_DISNEY) {
        let n_dot_v = clamp(dot(s.normal, s.to_eye), 1e-4, 1.0);
        let n_dot_l = clamp(dot(s.normal, dir), 0.0, 1.0);
        let l_dot_h = clamp(dot(dir, normalize(dir + s.to_eye)), 0.0, 1.0);
        radiance = radiance * tr_disney_weight(n_dot_v, n_dot_l, l_dot_h, gb_roughness(px.texel));
    }
    textureStore(out0, px.texel, vec4<f32>(radiance, traced.t));
}
