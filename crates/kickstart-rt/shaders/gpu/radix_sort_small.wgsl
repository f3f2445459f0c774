// Sort of at most SMALL_N (key, value) pairs in one workgroup: a bitonic network in workgroup
// memory over (key, input position), so equal keys keep their input order (stable, like the
// radix sort it stands in for). One dispatch instead of the radix sort's 12 (31-bit keys):
// small BLASes and small TLASes are bound by dispatch count, not by work.
//
// sort_small_positions: the same for at most SMALL_POS_N pairs whose values are their input
// positions (0, 1, 2, ...: the LBVH's sorts of one build), so the value itself breaks ties and
// no position array is needed: keys and values of 2048 pairs fill the 16 KiB exactly.

struct SmallParams {
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> small: SmallParams;
@group(0) @binding(1) var<storage, read_write> s_keys: array<u32>;
@group(0) @binding(2) var<storage, read_write> s_vals: array<u32>;

const SMALL_N: u32 = 1024u;
const SMALL_WG: u32 = 256u;

// 12 KiB: within the 16 KiB WebGPU default.
var<workgroup> w_key: array<u32, 1024>;
var<workgroup> w_pos: array<u32, 1024>;
var<workgroup> w_val: array<u32, 1024>;

// The lower element of compare-exchange pair t at `stride` of a bitonic stage.
fn pair_low(t: u32, stride: u32) -> u32 {
    return 2u * t - (t & (stride - 1u));
}

// Strict order on (key, position); padding (key and position 0xffffffff) sorts last.
fn before(i: u32, j: u32) -> bool {
    return w_key[i] < w_key[j] || (w_key[i] == w_key[j] && w_pos[i] < w_pos[j]);
}

@compute @workgroup_size(256)
fn sort_small(@builtin(local_invocation_index) lid: u32) {
    for (var e = 0u; e < SMALL_N / SMALL_WG; e += 1u) {
        let i = lid + e * SMALL_WG;
        if i < small.count {
            w_key[i] = s_keys[i];
            w_val[i] = s_vals[i];
            w_pos[i] = i;
        } else {
            w_key[i] = 0xffffffffu;
            w_val[i] = 0u;
            w_pos[i] = 0xffffffffu;
        }
    }
    workgroupBarrier();
    for (var size = 2u; size <= SMALL_N; size <<= 1u) {
        for (var stride = size >> 1u; stride > 0u; stride >>= 1u) {
            // SMALL_N / 2 compare-exchange pairs, two per invocation.
            for (var e = 0u; e < SMALL_N / (2u * SMALL_WG); e += 1u) {
                let t = lid + e * SMALL_WG;
                let i = pair_low(t, stride);
                let j = i + stride;
                let ascending = (i & size) == 0u;
                if select(before(i, j), before(j, i), ascending) {
                    let k = w_key[i];
                    let p = w_pos[i];
                    let v = w_val[i];
                    w_key[i] = w_key[j];
                    w_pos[i] = w_pos[j];
                    w_val[i] = w_val[j];
                    w_key[j] = k;
                    w_pos[j] = p;
                    w_val[j] = v;
                }
            }
            workgroupBarrier();
        }
    }
    for (var e = 0u; e < SMALL_N / SMALL_WG; e += 1u) {
        let i = lid + e * SMALL_WG;
        if i < small.count {
            s_keys[i] = w_key[i];
            s_vals[i] = w_val[i];
        }
    }
}

const SMALL_POS_N: u32 = 2048u;
// Pairs each invocation holds in registers for the stages of strides below WP_RUN.
const WP_RUN: u32 = SMALL_POS_N / SMALL_WG;

// 16 KiB: the WebGPU default, exactly.
var<workgroup> wp_key: array<u32, 2048>;
var<workgroup> wp_val: array<u32, 2048>;

// Order: (key, value) ascending; padding (key and value 0xffffffff) sorts last.

// Compare-exchange of pairs a < b of a run starting at position `base`, in the direction of the
// bitonic sequence of length `size` the run lies in.
fn wp_exchange(run: ptr<function, array<vec2<u32>, WP_RUN>>, a: u32, b: u32, base: u32, size: u32) {
    let x = (*run)[a];
    let y = (*run)[b];
    let a_after_b = x.x > y.x || (x.x == y.x && x.y > y.y);
    if a_after_b == (((base + a) & size) == 0u) {
        (*run)[a] = y;
        (*run)[b] = x;
    }
}

@compute @workgroup_size(256)
fn sort_small_positions(@builtin(local_invocation_index) lid: u32) {
    for (var e = 0u; e < SMALL_POS_N / SMALL_WG; e += 1u) {
        let i = lid + e * SMALL_WG;
        if i < small.count {
            wp_key[i] = s_keys[i];
            wp_val[i] = s_vals[i];
        } else {
            wp_key[i] = 0xffffffffu;
            wp_val[i] = 0xffffffffu;
        }
    }
    workgroupBarrier();
    for (var size = 2u; size <= SMALL_POS_N; size <<= 1u) {
        // Strides of 8 and more across invocations, in workgroup memory.
        for (var stride = size >> 1u; stride >= WP_RUN; stride >>= 1u) {
            for (var e = 0u; e < SMALL_POS_N / (2u * SMALL_WG); e += 1u) {
                let i = pair_low(lid + e * SMALL_WG, stride);
                let j = i + stride;
                // Each pair's four words loaded once; the values differ, so i after j is the
                // strict order's negation of j after i.
                let ki = wp_key[i];
                let kj = wp_key[j];
                let vi = wp_val[i];
                let vj = wp_val[j];
                let i_after_j = ki > kj || (ki == kj && vi > vj);
                if i_after_j == ((i & size) == 0u) {
                    wp_key[i] = kj;
                    wp_val[i] = vj;
                    wp_key[j] = ki;
                    wp_val[j] = vi;
                }
            }
            workgroupBarrier();
        }
        // Strides 4, 2 and 1 stay within each invocation's run of WP_RUN pairs: in registers,
        // one barrier for the three stages.
        let base = lid * WP_RUN;
        var run: array<vec2<u32>, WP_RUN>;
        for (var a = 0u; a < WP_RUN; a++) {
            run[a] = vec2<u32>(wp_key[base + a], wp_val[base + a]);
        }
        // Written out (WP_RUN is 8), so every index is a constant and `run` stays in registers.
        if size >= 8u {
            wp_exchange(&run, 0u, 4u, base, size);
            wp_exchange(&run, 1u, 5u, base, size);
            wp_exchange(&run, 2u, 6u, base, size);
            wp_exchange(&run, 3u, 7u, base, size);
        }
        if size >= 4u {
            wp_exchange(&run, 0u, 2u, base, size);
            wp_exchange(&run, 1u, 3u, base, size);
            wp_exchange(&run, 4u, 6u, base, size);
            wp_exchange(&run, 5u, 7u, base, size);
        }
        wp_exchange(&run, 0u, 1u, base, size);
        wp_exchange(&run, 2u, 3u, base, size);
        wp_exchange(&run, 4u, 5u, base, size);
        wp_exchange(&run, 6u, 7u, base, size);
        for (var a = 0u; a < WP_RUN; a++) {
            wp_key[base + a] = run[a].x;
            wp_val[base + a] = run[a].y;
        }
        workgroupBarrier();
    }
    for (var e = 0u; e < SMALL_POS_N / SMALL_WG; e += 1u) {
        let i = lid + e * SMALL_WG;
        if i < small.count {
            s_keys[i] = wp_key[i];
            s_vals[i] = wp_val[i];
        }
    }
}
