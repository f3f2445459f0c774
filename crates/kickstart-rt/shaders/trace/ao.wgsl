// TraceAmbientOcclusionTask: one cosine-weighted ray per pixel within ao_radius; writes the
// closest hit distance / ao_radius, 1 where nothing is hit within the radius (the reference's
// format; the AO denoiser reads it). The output is a distance, so the rays take the closest hit
// (an any-hit query could report a farther occluder); t_max = radius keeps traversal short.
// The G-buffer is at group 1 (trace/common).

#import trace/common
#param OUTPUT0_FORMAT

@group(2) @binding(4) var out0: texture_storage_2d<{{OUTPUT0_FORMAT}}, write>;

@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn main(
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
        textureStore(out0, px.texel, vec4<f32>(1.0));
        return;
    }
    var rng = tr_rng(px.texel);
    let u = vec2<f32>(tr_next(&rng), tr_next(&rng));
    let dir = tr_cosine(s.normal, u);
    let radius = tp.lengths.y;
    let t_max = min(radius, tp.lengths.x);
    let origin = tr_origin(s.position, s.normal, s.view_distance);
    // Only the distance: rt_find skips the barycentrics.
    let hit = rt_find(RtRay(origin, tr_t_min(s.view_distance), dir, t_max), tp.misc.z, false);
    var v = 1.0;
    if hit.instance != RT_NO_INDEX {
        v = clamp(hit.t / radius, 0.0, 1.0);
    }
    textureStore(out0, px.texel, vec4<f32>(v));
}
