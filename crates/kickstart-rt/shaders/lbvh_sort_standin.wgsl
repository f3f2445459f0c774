// TEMPORARY stand-in for crate::gpu::radix_sort (delete with `standin_sort` in scene/lbvh.rs).
// One step of a bitonic sorting network over (key, value) pairs, ascending by (key, value).
// Values are distinct primitive indices written in ascending order, so this equals the stable
// sort by key that the radix sort gives. Positions >= count act as +infinity and never move: the
// network used here only ever compares ascending (the first step of each stage compares i with
// its mirror in the block), so a pair with its upper element out of range is already in order.

struct SortParams {
    count: u32,
    block: u32,
    dist: u32,
    flip: u32,
}

@group(0) @binding(0) var<uniform> sp: SortParams;
@group(0) @binding(1) var<storage, read_write> skeys: array<u32>;
@group(0) @binding(2) var<storage, read_write> svalues: array<u32>;

@compute @workgroup_size(256)
fn sort_step(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
             @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = (wid.y * nwg.x + wid.x) * 256u + lid;
    let d = sp.dist;
    let lo = (t / d) * 2u * d + (t % d);
    var hi = lo + d;
    if sp.flip != 0u {
        hi = (lo / sp.block) * sp.block + sp.block - 1u - (lo % sp.block);
    }
    if hi >= sp.count {
        return;
    }
    let ka = skeys[lo];
    let kb = skeys[hi];
    let va = svalues[lo];
    let vb = svalues[hi];
    if ka > kb || (ka == kb && va > vb) {
        skeys[lo] = kb;
        skeys[hi] = ka;
        svalues[lo] = vb;
        svalues[hi] = va;
    }
}
