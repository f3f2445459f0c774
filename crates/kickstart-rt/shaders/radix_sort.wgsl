// Stable LSD radix sort of (u32 key, u32 value) pairs: one 4-bit digit per pass.
//
// Each pass is classic multi-pass (no inter-workgroup communication within a dispatch, so no
// reliance on forward progress and no subgroup operations):
//   1. `histogram`: every block of BLOCK elements counts its digits into
//      hist[digit * nblocks + block] (digit-major, block-minor).
//   2. `reduce` / `scan_add`: exclusive prefix sum over that array (multi-level: chunk sums of one
//      level form the next level, up to one chunk that one workgroup scans). Afterwards
//      hist[digit * nblocks + block] is where the block's first element of that digit goes.
//   3. `scatter`: every block ranks its elements stably by digit in workgroup memory, reorders
//      them there (so global writes are runs of consecutive addresses) and writes them out.
// `copy_back` moves the result back into the caller's buffers after an odd number of passes.
//
// Workgroup linear index = wid.y * nwg.x + wid.x (the host splits big 1-D counts into 2-D).

const WG: u32 = 256u;
// Elements per thread: a thread owns EPT consecutive elements of its block, so ranking
// "thread-major, then element" is the block's index order, which is what stability needs.
const EPT: u32 = 4u;
const BLOCK: u32 = 1024u; // WG * EPT
const RADIX: u32 = 16u;
// Elements of the prefix-sum chunk of one workgroup in `reduce` / `scan_add`.
const SCAN_CHUNK: u32 = 1024u; // WG * 4

struct Params {
    // Elements to sort (histogram, scatter, copy).
    count: u32,
    // Digit of this pass: (key >> shift) & ((1 << bits) - 1), bits in 1..=4.
    shift: u32,
    bits: u32,
    // Blocks of BLOCK elements (the histogram's block dimension).
    nblocks: u32,
    // Scan level: its first entry in `hist`, its entry count, and where the next level
    // (the chunk sums / their exclusive prefixes) starts.
    level_base: u32,
    level_len: u32,
    next_base: u32,
    // scan_add: 1 = add the chunk's prefix from the next level, 0 = top level (no next level).
    has_next: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> vals_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> vals_out: array<u32>;
// Per-block digit counts followed by the upper scan levels.
@group(0) @binding(5) var<storage, read_write> hist: array<u32>;

fn digit_of(key: u32) -> u32 {
    return (key >> params.shift) & ((1u << params.bits) - 1u);
}

// ---------------------------------------------------------------------------------------------
// Histogram

// 16 copies of the 16 counters (replica = thread index % 16): fewer threads contend per atomic.
var<workgroup> wg_bins: array<atomic<u32>, 256>;

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
    atomicStore(&wg_bins[t], 0u);
    workgroupBarrier();
    let base = block * BLOCK;
    let replica = t & 15u;
    // Strided loads (coalesced): the order does not matter for counting.
    for (var j = 0u; j < EPT; j++) {
        let i = base + j * WG + t;
        if i < params.count {
            atomicAdd(&wg_bins[digit_of(keys_in[i]) * 16u + replica], 1u);
        }
    }
    workgroupBarrier();
    if t < RADIX {
        var sum = 0u;
        for (var c = 0u; c < 16u; c++) {
            sum += atomicLoad(&wg_bins[t * 16u + c]);
        }
        hist[t * params.nblocks + block] = sum;
    }
}

// ---------------------------------------------------------------------------------------------
// Prefix sum over hist (multi-level)

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

// Chunk c of the level gets its sum written to the next level's entry c.
@compute @workgroup_size(256)
fn reduce(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let chunk = wid.y * nwg.x + wid.x;
    let start = chunk * SCAN_CHUNK;
    if start >= params.level_len {
        return;
    }
    var sum = 0u;
    for (var j = 0u; j < 4u; j++) {
        let i = start + j * WG + t;
        if i < params.level_len {
            sum += hist[params.level_base + i];
        }
    }
    wg_scan[t] = sum;
    workgroupBarrier();
    for (var stride = WG / 2u; stride > 0u; stride >>= 1u) {
        if t < stride {
            wg_scan[t] += wg_scan[t + stride];
        }
        workgroupBarrier();
    }
    if t == 0u {
        hist[params.next_base + chunk] = wg_scan[0];
    }
}

// Exclusive prefix sum of chunk c of the level, in place, plus the next level's entry c (the
// exclusive prefix of the chunk sums, already computed) when there is a next level.
@compute @workgroup_size(256)
fn scan_add(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let chunk = wid.y * nwg.x + wid.x;
    let start = chunk * SCAN_CHUNK;
    if start >= params.level_len {
        return;
    }
    // Thread t owns 4 consecutive entries, so its serial sum plus the workgroup scan is the
    // prefix in index order.
    var v: array<u32, 4>;
    var sum = 0u;
    for (var j = 0u; j < 4u; j++) {
        let i = start + t * 4u + j;
        v[j] = 0u;
        if i < params.level_len {
            v[j] = hist[params.level_base + i];
        }
        sum += v[j];
    }
    wg_scan[t] = sum;
    workgroupBarrier();
    workgroup_inclusive_scan(t);
    var running = wg_scan[t] - sum;
    if params.has_next != 0u {
        running += hist[params.next_base + chunk];
    }
    for (var j = 0u; j < 4u; j++) {
        let i = start + t * 4u + j;
        if i < params.level_len {
            hist[params.level_base + i] = running;
        }
        running += v[j];
    }
}

// ---------------------------------------------------------------------------------------------
// Scatter

// Packed per-thread digit counters (two 16-bit lanes per word; a block holds at most 1024
// elements, so a lane never overflows): digit d of thread t lives at word (d % 8) * 256 + t,
// lane d / 8. Scanning the words in index order therefore visits, per lane, digit-major then
// thread-minor, which is exactly the stable rank order within the block. After ranking, the
// same memory holds the block's reordered keys, then its reordered values.
var<workgroup> wg_counters: array<u32, 2048>;
// Per digit: global destination of the block's first element of that digit minus its position
// in the block's reordered elements.
var<workgroup> wg_dest: array<u32, 16>;

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
    let base = block * BLOCK;
    let valid = min(BLOCK, params.count - base);

    for (var r = 0u; r < 8u; r++) {
        wg_counters[r * WG + t] = 0u;
    }

    // Load this thread's consecutive elements. Elements past the end get the last digit: being
    // last in the block's order too, they rank after every valid element and are never written.
    var k: array<u32, 4>;
    var v: array<u32, 4>;
    var d: array<u32, 4>;
    var rank: array<u32, 4>;
    for (var j = 0u; j < EPT; j++) {
        let i = t * EPT + j;
        k[j] = 0u;
        v[j] = 0u;
        d[j] = RADIX - 1u;
        if i < valid {
            k[j] = keys_in[base + i];
            v[j] = vals_in[base + i];
            d[j] = digit_of(k[j]);
        }
    }
    // Count per thread; the count before the increment is the rank among this thread's own
    // elements of that digit. Only thread t touches column t: no barrier or atomics needed.
    for (var j = 0u; j < EPT; j++) {
        let w = (d[j] & 7u) * WG + t;
        let lane = (d[j] >> 3u) * 16u;
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
    // Low lane total = elements with digits 0..7: the high lane (digits 8..15) starts after them.
    let low_total = wg_scan[WG - 1u] & 0xffffu;
    workgroupBarrier();

    for (var j = 0u; j < EPT; j++) {
        let w = (d[j] & 7u) * WG + t;
        let hi = d[j] >> 3u;
        rank[j] += ((wg_counters[w] >> (hi * 16u)) & 0xffffu) + hi * low_total;
    }
    if t < RADIX {
        // Thread 0's counter of digit t is the block position of the digit's first element.
        let hi = t >> 3u;
        let first = ((wg_counters[(t & 7u) * WG] >> (hi * 16u)) & 0xffffu) + hi * low_total;
        // Wrapping u32 arithmetic: destination = this + position, and position >= first.
        wg_dest[t] = hist[t * params.nblocks + block] - first;
    }
    workgroupBarrier();

    // Reorder keys in workgroup memory, then write runs of consecutive positions per digit.
    for (var j = 0u; j < EPT; j++) {
        wg_counters[rank[j]] = k[j];
    }
    workgroupBarrier();
    var dest: array<u32, 4>;
    for (var j = 0u; j < EPT; j++) {
        let i = j * WG + t;
        if i < valid {
            let key = wg_counters[i];
            dest[j] = wg_dest[digit_of(key)] + i;
            keys_out[dest[j]] = key;
        }
    }
    workgroupBarrier();
    for (var j = 0u; j < EPT; j++) {
        wg_counters[rank[j]] = v[j];
    }
    workgroupBarrier();
    for (var j = 0u; j < EPT; j++) {
        let i = j * WG + t;
        if i < valid {
            vals_out[dest[j]] = wg_counters[i];
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Copy (storage to storage, so the caller's buffers need no COPY_DST usage)

@compute @workgroup_size(256)
fn copy_back(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let i = (wid.y * nwg.x + wid.x) * WG + t;
    if i < params.count {
        keys_out[i] = keys_in[i];
        vals_out[i] = vals_in[i];
    }
}
