// One block's counts of an 8-bit sort digit, in workgroup memory, and where they go in the radix
// sort's histogram. Shared by gpu/radix_sort.wgsl's `histogram` and scene/lbvh/morton.wgsl's
// `lbvh_morton_histogram` (which counts the first digit while it makes the keys), so the two
// write the same layout: imported by both (src/gpu/radix_sort.rs, src/scene/lbvh/).
// Every function here must be called by all 256 invocations of the workgroup, each passing its
// local index `t`.

// Keys per block: 256 invocations × 4, strided (key j * 256 + t of the block is invocation t's
// j-th). gpu/radix_sort.wgsl's BLOCK.
const DIGIT_BLOCK: u32 = 1024u;
// Digit values (8 bits).
const DIGIT_VALUES: u32 = 256u;
// DIGIT_REPLICAS copies of the counters (replica-major; replica = invocation index % replicas):
// fewer invocations contend per atomic when a block's keys share digits (sorted or clustered
// keys, e.g. the high digits of Morton codes).
const DIGIT_REPLICAS: u32 = 8u;
var<workgroup> wg_digit_bins: array<atomic<u32>, 2048>; // DIGIT_REPLICAS * DIGIT_VALUES

// Zeroes the counters; a workgroup barrier follows before the first count.
fn digit_bins_clear(t: u32) {
    for (var r = 0u; r < DIGIT_REPLICAS; r++) {
        atomicStore(&wg_digit_bins[r * DIGIT_VALUES + t], 0u);
    }
    workgroupBarrier();
}

// Counts one key's digit (any invocation, any number of times).
fn digit_bins_count(digit: u32, t: u32) {
    atomicAdd(&wg_digit_bins[(t % DIGIT_REPLICAS) * DIGIT_VALUES + digit], 1u);
}

// After every count: digit t's total over the replicas.
fn digit_bins_total(t: u32) -> u32 {
    workgroupBarrier();
    var sum = 0u;
    for (var r = 0u; r < DIGIT_REPLICAS; r++) {
        sum += atomicLoad(&wg_digit_bins[r * DIGIT_VALUES + t]);
    }
    return sum;
}

// Index of block `block`'s count of digit `digit` in the histogram of `nblocks` blocks:
// digit-major rows (row d = digit d over all blocks), as scan_rows and the scatters read it.
fn digit_hist_at(digit: u32, block: u32, nblocks: u32) -> u32 {
    return digit * nblocks + block;
}
