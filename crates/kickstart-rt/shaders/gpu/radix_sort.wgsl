// Stable LSD radix sort of (u32 key, u32 value) pairs: one 8-bit digit per pass.
//
// The cost that matters is the number of dispatches (each one a full barrier between kernels),
// not the work: hence 8-bit digits (a 31-bit key takes 4 passes, not 8) and three dispatches per
// pass at every size. None of them communicates between workgroups (no reliance on forward
// progress) and none uses subgroup operations:
//   1. `histogram`: every block of BLOCK elements counts its digits into
//      hist[digit * nblocks + block] (digit-major, block-minor: row d is digit d over all blocks).
//   2. `scan_rows`: workgroup d turns row d into its exclusive prefix sum in place and writes the
//      row total to hist[RADIX * nblocks + d]. One workgroup per row, looping over the row, rather
//      than a multi-level scan over the whole array: a row has only count / BLOCK entries, so one
//      dispatch suffices at any size where a multi-level scan needs two or three more.
//   3. `scatter`: every block scans the RADIX row totals itself (one workgroup scan, cheaper than
//      another dispatch), ranks its elements stably by digit in workgroup memory and writes them
//      out as runs of consecutive addresses.
// Up to SUMMING_MAX_BLOCKS blocks, `scatter_summing` replaces 2 and 3: each block sums the rows
// it needs itself, so a pass is two dispatches (a TLAS of up to 65536 instance refs).
// Passes alternate between the caller's buffers and the scratch; after an odd number the result
// stays in the scratch and the host hands that to the caller (no copy dispatch).
//
// Workgroup linear index = wid.y * nwg.x + wid.x (the host splits big 1-D counts into 2-D).
// Workgroup memory per entry point (WebGPU's default limit is 16384 bytes): histogram 8192,
// scan_rows 1024, scatter 10240.

#import gpu/digit_histogram

const WG: u32 = 256u;
// Elements per thread: a thread owns EPT consecutive elements of its block, so ranking
// "thread-major, then element" is the block's index order, which is what stability needs.
const EPT: u32 = 4u;
const BLOCK: u32 = DIGIT_BLOCK; // WG * EPT (gpu/digit_histogram.wgsl)
// Digit values of one pass. Equal to WG: thread t handles digit t wherever there is one per digit.
const RADIX: u32 = 256u;
// Entries of a row that `scan_rows` scans per loop iteration.
const SCAN_CHUNK: u32 = 1024u; // WG * 4

struct Params {
    // Elements to sort (histogram, scatter).
    count: u32,
    // Digit of this pass: (key >> shift) & ((1 << bits) - 1), bits in 1..=8.
    shift: u32,
    bits: u32,
    // Blocks of BLOCK elements (the histogram's row length).
    nblocks: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> vals_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> vals_out: array<u32>;
// RADIX rows of nblocks per-block digit counts, then the RADIX row totals.
@group(0) @binding(5) var<storage, read_write> hist: array<u32>;

fn digit_of(key: u32) -> u32 {
    return (key >> params.shift) & ((1u << params.bits) - 1u);
}

// ---------------------------------------------------------------------------------------------
// Histogram

// Counts in workgroup memory and the histogram's layout: gpu/digit_histogram (imported).
@compute @workgroup_size(256)
fn histogram(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let block = wid.y * nwg.x + wid.x;
    if block >= params.nblocks {
        return;
    }
    digit_bins_clear(t);
    let base = block * BLOCK;
    // Strided loads (coalesced): the order does not matter for counting.
    for (var j = 0u; j < EPT; j++) {
        let i = base + j * WG + t;
        if i < params.count {
            digit_bins_count(digit_of(keys_in[i]), t);
        }
    }
    // Every digit's count is written, zeros included: no clearing pass needed.
    hist[digit_hist_at(t, block, params.nblocks)] = digit_bins_total(t);
}

// ---------------------------------------------------------------------------------------------
// Prefix sum over each histogram row

var<workgroup> wg_scan: array<u32, 256>;

// Inclusive prefix sum of wg_scan[0..256] in place (Hillis-Steele; every thread calls it).
fn workgroup_inclusive_scan(t: u32) {
    for (var off = 1u; off < WG; off <<= 1u) {
        var x = wg_scan[t];
        if t >= off {
            x += wg_scan[t - off];
        }
        workgroupBarrier();
        wg_scan[t] = x;
        workgroupBarrier();
    }
}

// Row d (digit d in every block) becomes its exclusive prefix sum; its total goes after the rows.
@compute @workgroup_size(256)
fn scan_rows(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let row = wid.y * nwg.x + wid.x;
    if row >= RADIX {
        return;
    }
    let start = row * params.nblocks;
    var carry = 0u;
    for (var chunk = 0u; chunk < params.nblocks; chunk += SCAN_CHUNK) {
        // Thread t owns 4 consecutive entries, so its serial sum plus the workgroup scan is the
        // prefix in index order.
        var v: array<u32, 4>;
        var sum = 0u;
        for (var j = 0u; j < 4u; j++) {
            let b = chunk + t * 4u + j;
            v[j] = 0u;
            if b < params.nblocks {
                v[j] = hist[start + b];
            }
            sum += v[j];
        }
        wg_scan[t] = sum;
        workgroupBarrier();
        workgroup_inclusive_scan(t);
        var running = carry + wg_scan[t] - sum;
        for (var j = 0u; j < 4u; j++) {
            let b = chunk + t * 4u + j;
            if b < params.nblocks {
                hist[start + b] = running;
            }
            running += v[j];
        }
        carry += wg_scan[WG - 1u];
        // The next iteration overwrites wg_scan, which slower threads may still be reading.
        workgroupBarrier();
    }
    if t == 0u {
        hist[RADIX * params.nblocks + row] = carry;
    }
}

// ---------------------------------------------------------------------------------------------
// Scatter

// An 8-bit digit has too many values for per-thread counters in 16 KiB (256 digits × 256
// threads), so the block is ranked by two stable 4-bit splits, low nibble then high nibble: after
// both it is sorted stably by the whole digit (LSD within the block).
//
// During a split: packed per-thread nibble counters (two 16-bit lanes per word; a block holds at
// most 1024 elements, so a lane never overflows): nibble n of thread t lives at word
// (n % 8) * 256 + t, lane n / 8. Scanning the words in index order therefore visits, per lane,
// nibble-major then thread-minor, which is exactly the stable rank order within the block.
// After a split, the same memory holds the block's keys [0, BLOCK) and values [BLOCK, 2 BLOCK)
// in the split's order.
var<workgroup> wg_counters: array<u32, 2048>;
// Per digit: global destination of the block's first element of that digit minus its position
// in the block's sorted order.
var<workgroup> wg_dest: array<u32, 256>;

// This thread's EPT elements in the current order of the block.
var<private> pk: array<u32, 4>;
var<private> pv: array<u32, 4>;

// Stable split of the block (pk/pv of every thread, in block order) by the nibble
// (digit >> nib_shift) & 15; leaves the reordered keys and values in wg_counters.
fn split_by_nibble(t: u32, nib_shift: u32) {
    // Only thread t touches column t until the barrier: no atomics needed.
    for (var r = 0u; r < 8u; r++) {
        wg_counters[r * WG + t] = 0u;
    }
    // Count per thread; the count before the increment is the rank among this thread's own
    // elements of that nibble.
    var n: array<u32, 4>;
    var rank: array<u32, 4>;
    for (var j = 0u; j < EPT; j++) {
        n[j] = (digit_of(pk[j]) >> nib_shift) & 15u;
        let w = (n[j] & 7u) * WG + t;
        let lane = (n[j] >> 3u) * 16u;
        let c = wg_counters[w];
        rank[j] = (c >> lane) & 0xffffu;
        wg_counters[w] = c + (1u << lane);
    }
    workgroupBarrier();

    // Exclusive scan of the 2048 packed words in index order (both lanes at once): thread t
    // scans words 8t..8t+7 serially on top of the workgroup scan of the 256 per-thread sums.
    var words: array<u32, 8>;
    var sum = 0u;
    for (var q = 0u; q < 8u; q++) {
        words[q] = wg_counters[t * 8u + q];
        sum += words[q];
    }
    wg_scan[t] = sum;
    workgroupBarrier();
    workgroup_inclusive_scan(t);
    var running = wg_scan[t] - sum;
    for (var q = 0u; q < 8u; q++) {
        wg_counters[t * 8u + q] = running;
        running += words[q];
    }
    // Low lane total = elements with nibbles 0..7: the high lane (8..15) starts after them.
    let low_total = wg_scan[WG - 1u] & 0xffffu;
    workgroupBarrier();

    for (var j = 0u; j < EPT; j++) {
        let w = (n[j] & 7u) * WG + t;
        let hi = n[j] >> 3u;
        rank[j] += ((wg_counters[w] >> (hi * 16u)) & 0xffffu) + hi * low_total;
    }
    // Every rank is read before the counters are overwritten by the reordered elements.
    workgroupBarrier();
    for (var j = 0u; j < EPT; j++) {
        wg_counters[rank[j]] = pk[j];
        wg_counters[BLOCK + rank[j]] = pv[j];
    }
    workgroupBarrier();
}

@compute @workgroup_size(256)
fn scatter(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let block = wid.y * nwg.x + wid.x;
    if block >= params.nblocks {
        return;
    }
    // Digit t's total and its count in earlier blocks, from scan_rows.
    scatter_block(block, t, hist[RADIX * params.nblocks + t],
                  hist[digit_hist_at(t, block, params.nblocks)]);
}

// Blocks up to which `scatter_summing` replaces scan_rows + scatter (src/gpu/radix_sort.rs).
// Thread t then reads row t whole: at most this many loads, all from L2.
const SUMMING_MAX_BLOCKS: u32 = 64u;

// scatter for few blocks, without a scan_rows dispatch before it: thread t sums digit t's row of
// the histogram itself (its total, and its count in the blocks before this one). Each block
// repeats those sums; with at most SUMMING_MAX_BLOCKS entries a row that costs less than the
// dependent dispatch it saves.
@compute @workgroup_size(256)
fn scatter_summing(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let block = wid.y * nwg.x + wid.x;
    if block >= params.nblocks {
        return;
    }
    let blocks = min(params.nblocks, SUMMING_MAX_BLOCKS);
    var before = 0u;
    var total = 0u;
    for (var b = 0u; b < blocks; b++) {
        let c = hist[digit_hist_at(t, b, params.nblocks)];
        before += select(0u, c, b < block);
        total += c;
    }
    scatter_block(block, t, total, before);
}

// Scatters block `block`, given digit t's total over all blocks and its count in the blocks
// before this one (thread t passes digit t's). Every thread of the workgroup calls it.
fn scatter_block(block: u32, t: u32, total: u32, before: u32) {
    let base = block * BLOCK;
    let valid = min(BLOCK, params.count - base);

    // Where digit t's elements of this block start globally: all elements of smaller digits
    // (exclusive prefix of the row totals) plus digit t's elements in earlier blocks. No barrier
    // after it: thread t reads only its own wg_scan entry here, and the first split rewrites
    // wg_scan only after a barrier.
    wg_scan[t] = total;
    workgroupBarrier();
    workgroup_inclusive_scan(t);
    wg_dest[t] = wg_scan[t] - total + before;

    // Load this thread's consecutive elements. Elements past the end get key 0xffffffff, the
    // largest digit of any pass: being last in the block's order too, they rank after every
    // valid element in both splits and are never written.
    for (var j = 0u; j < EPT; j++) {
        let i = t * EPT + j;
        pk[j] = 0xffffffffu;
        pv[j] = 0u;
        if i < valid {
            pk[j] = keys_in[base + i];
            pv[j] = vals_in[base + i];
        }
    }
    split_by_nibble(t, 0u);
    // A digit of at most 4 bits (only in a last pass) is already sorted by its low nibble.
    if params.bits > 4u {
        for (var j = 0u; j < EPT; j++) {
            pk[j] = wg_counters[t * EPT + j];
            pv[j] = wg_counters[BLOCK + t * EPT + j];
        }
        workgroupBarrier();
        split_by_nibble(t, 4u);
    }

    // The block is sorted by digit. Strided positions, so neighbouring threads write neighbouring
    // addresses within a digit's run. The first element of each digit's run turns wg_dest[digit]
    // into destination minus position (wrapping u32 arithmetic: every position of the run is at
    // least the first). One thread per digit writes it, as the run has one first element.
    var key: array<u32, 4>;
    var dig: array<u32, 4>;
    for (var j = 0u; j < EPT; j++) {
        let i = j * WG + t;
        key[j] = wg_counters[i];
        dig[j] = digit_of(key[j]);
        if i < valid && (i == 0u || digit_of(wg_counters[i - 1u]) != dig[j]) {
            wg_dest[dig[j]] -= i;
        }
    }
    workgroupBarrier();
    for (var j = 0u; j < EPT; j++) {
        let i = j * WG + t;
        if i < valid {
            let dest = wg_dest[dig[j]] + i;
            keys_out[dest] = key[j];
            vals_out[dest] = wg_counters[BLOCK + i];
        }
    }
}
