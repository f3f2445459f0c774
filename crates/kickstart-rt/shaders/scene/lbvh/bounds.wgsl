// Scene bounds of the valid centroids (scene/centroid_bounds.wgsl): workgroup reduce in shared atomics,
// then one device atomicMax per word into work[seg.work_base + 0..6]. Skipped when the caller's primitive pass
// merged them already (the TLAS's instance boxes): lbvh_morton then reads the caller's words.

#import scene/lbvh/common

@compute @workgroup_size(256)
fn lbvh_bounds(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    // A block of WG positions lies in one build of a batch (builds start at multiples of WG).
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g - lid)];
    let i = g - seg.key_base;
    wg_bounds_clear(lid);
    workgroupBarrier();
    // No early return: the barriers below must be reached by the whole workgroup.
    if i < seg.count {
        let b = prim_box(i);
        if !is_empty(b) {
            wg_bounds_add(b.lo, b.hi);
        }
    }
    workgroupBarrier();
    if lid < 6u {
        let v = wg_bounds_word(lid);
        if v != 0u {
            atomicMax(&work[seg.work_base + lid], v);
        }
    }
}
