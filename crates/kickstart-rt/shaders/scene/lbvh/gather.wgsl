// The triangles of each build of a batch in its sorted order (leaf refs are sorted positions):
// BLAS triangle k of a build is its staged triangle order[k].

#import scene/lbvh/common

@compute @workgroup_size(256)
fn lbvh_gather(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g)];
    let k = g - seg.key_base;
    if g >= params.count || k >= seg.count {
        return;
    }
    let s = 3u * (seg.tri_src_base + order[seg.order_base + k]);
    let d = 3u * (seg.tri_dst_base + k);
    refit_dst[d] = refit_src[s];
    refit_dst[d + 1u] = refit_src[s + 1u];
    refit_dst[d + 2u] = refit_src[s + 2u];
}
