// Sort of at most SMALL_N (key, value) pairs in one workgroup: a bitonic network in workgroup
// memory over (key, input position), so equal keys keep their input order (stable, like the
// radix sort it stands in for). One dispatch instead of the radix sort's 12 (31-bit keys):
// small BLASes and small TLASes are bound by dispatch count, not by work.

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
                let i = 2u * t - (t & (stride - 1u));
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
