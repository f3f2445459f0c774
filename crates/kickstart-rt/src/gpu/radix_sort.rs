//! Stable GPU LSD radix sort of (u32 key, u32 value) pairs (`shaders/gpu/radix_sort.wgsl`).
//!
//! Portable by construction: WebGPU default limits, no subgroup operations, no inter-workgroup
//! communication inside a dispatch (so no reliance on forward progress between workgroups).
//!
//! On a large GPU the sorts the SDK does (a BLAS's primitives) cost their dispatch count more
//! than their work, so the design minimises dispatches: 8-bit digits (a 31-bit key takes 4
//! passes, not 8) and 3 dispatches per pass at any size: histogram → prefix sum of each digit's
//! row (one workgroup per digit, so no multi-level scan) → stable scatter, which scans the 256
//! digit totals itself. 31-bit keys: 12 dispatches (40 with the former 4-bit digits and
//! multi-level scan). Up to [`SUMMING_MAX_BLOCKS`] blocks (65536 pairs) a pass is 2 dispatches:
//! the scatter sums the histogram rows itself (`scatter_summing`). A caller whose own pass
//! writes the keys can count their first digit into the histogram too
//! ([`RadixSort::first_histogram`], with `shaders/gpu/digit_histogram.wgsl`), saving the first
//! pass's `histogram` dispatch. The scatter ranks a block by two 4-bit splits in workgroup memory:
//! per-thread counters for all 256 digit values would not fit in 16 KiB, those of 16 nibble
//! values (two 16-bit lanes per word) take 8 KiB and rank in O(1) per element.
//! Counts up to [`SMALL_SORT_MAX`] take a one-workgroup bitonic network over (key, position)
//! instead: the same stable result in one dispatch, since small sorts (small BLASes, TLASes) are
//! bound by dispatch count. An odd number of digit passes ends in the scratch buffers, which
//! [`RadixSort::record`] returns to the caller instead of copying them back (a dispatch saved).

use super::reflect::{ReflectedPipeline, ReflectedShader};
use super::Recorder;

/// Largest count sorted by the one-workgroup path (its workgroup arrays' length).
pub(crate) const SMALL_SORT_MAX: u32 = 1024;
/// Largest count [`RadixSort::record_positions`] sorts in one workgroup (`SMALL_POS_N`): with
/// the values known to be the positions, keys and values of 2048 pairs fill WebGPU's 16 KiB.
pub(crate) const SMALL_POSITIONS_SORT_MAX: u32 = 2048;

/// Bits of one digit (one pass each). `RADIX` must match the shader's.
const DIGIT_BITS: u32 = 8;
/// Digit values per pass: the histogram's rows and `scan_rows`' workgroups.
const RADIX: u32 = 1 << DIGIT_BITS;
/// Elements per workgroup in `histogram` / `scatter` (256 threads × 4). Must match `BLOCK`.
const BLOCK: u32 = 1024;
/// Most blocks a pass sorts with two dispatches (`histogram`, `scatter_summing`: each block
/// sums the histogram rows itself) instead of three. Must match the shader's
/// `SUMMING_MAX_BLOCKS`. The dispatch saved (`scan_rows` and the gap before the next one) is
/// worth a fixed time a pass, while each block summing the rows costs more the more blocks
/// there are; on the H100 the two broke even near 100 blocks, so the limit sits below that
/// (see docs/decisions/tlas-build.md).
pub(crate) const SUMMING_MAX_BLOCKS: u32 = 64;

/// Per-dispatch parameters; layout of `Params` in the shader.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    count: u32,
    shift: u32,
    bits: u32,
    nblocks: u32,
}

/// The WGSL of the sort's two shaders, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    ["gpu/radix_sort", "gpu/radix_sort_small"]
        .iter()
        .map(|&m| {
            (
                m.to_string(),
                ReflectedShader::compose(&[m], &[]).source().to_string(),
            )
        })
        .collect()
}

/// Entries of the `hist` buffer for `nblocks` blocks: RADIX rows of per-block counts, then the
/// RADIX row totals.
fn hist_len(nblocks: u32) -> u32 {
    (nblocks + 1) * RADIX
}

/// Stable GPU LSD radix sort of (u32 key, u32 value) pairs.
pub(crate) struct RadixSort {
    histogram: ReflectedPipeline,
    scan_rows: ReflectedPipeline,
    scatter: ReflectedPipeline,
    /// `scan_rows` and `scatter` in one, for at most [`SUMMING_MAX_BLOCKS`] blocks.
    scatter_summing: ReflectedPipeline,
    /// The one-workgroup path for counts up to [`SMALL_SORT_MAX`].
    small: ReflectedPipeline,
    /// The one-workgroup path of [`Self::record_positions`], up to [`SMALL_POSITIONS_SORT_MAX`].
    small_positions: ReflectedPipeline,
    /// Ping-pong keys/values (the other half is the caller's buffers) and the histogram with
    /// its row totals; created on first use, grown when a sort needs more.
    keys_tmp: Option<wgpu::Buffer>,
    vals_tmp: Option<wgpu::Buffer>,
    hist: Option<wgpu::Buffer>,
}

impl RadixSort {
    /// Compiles the sort's pipelines; scratch buffers are created by the first [`Self::record`].
    pub fn new(device: &wgpu::Device) -> Self {
        // Every kernel of the sort (it imports the digit counting it shares with the LBVH's
        // morton pass), and the one-workgroup stable sort for small inputs.
        let shader = ReflectedShader::compose(&["gpu/radix_sort"], &[]);
        let pipeline = |entry| shader.pipeline(device, "radix sort", entry);
        let small = ReflectedShader::compose(&["gpu/radix_sort_small"], &[]);
        RadixSort {
            histogram: pipeline("histogram"),
            scan_rows: pipeline("scan_rows"),
            scatter: pipeline("scatter"),
            scatter_summing: pipeline("scatter_summing"),
            small: small.pipeline(device, "radix sort (small)", "sort_small"),
            small_positions: small.pipeline(device, "radix sort (small)", "sort_small_positions"),
            keys_tmp: None,
            vals_tmp: None,
            hist: None,
        }
    }

    /// Sorts the `count` pairs `keys[0..count]`, `values[0..count]` (whole buffers bound at
    /// offset 0; STORAGE usage is all they need) ascending by key, stable (equal keys keep their
    /// input order, so their values do too), into the returned buffers (see below).
    ///
    /// Only the low `key_bits` bits of each key are sorted on: keys must be `< 2^key_bits`
    /// (bits above are carried along but do not affect the order). `key_bits` is clamped to
    /// 1..=32 except that 0 sorts nothing; fewer bits mean fewer passes (`ceil(key_bits / 8)`
    /// of 3 dispatches each, 2 up to [`SUMMING_MAX_BLOCKS`] blocks). `count` ≤ 1 records
    /// nothing. `count` is limited by the device's `max_storage_buffer_binding_size / 4` (32M
    /// with default limits).
    ///
    /// Everything is recorded into `rec.encoder` (no submit); the scratch buffers stay in use
    /// until that work has run, so record sorts with one `RadixSort` sequentially.
    ///
    /// Returns the buffers holding the sorted pairs. Each digit pass moves the pairs between the
    /// caller's buffers and this sorter's scratch, so after an odd number of passes they are in
    /// the scratch: no copy back is recorded (it would cost a dispatch), the caller binds the
    /// returned buffers instead. The scratch stays as sorted until the next sort recorded with
    /// this `RadixSort` runs, so read it before recording another sort (the returned handles
    /// keep the buffers alive even if a later sort replaces the scratch). After an even number
    /// of passes, the one-workgroup path, or a sort of nothing, they are `keys` and `values`.
    #[must_use = "the sorted pairs may be in the returned scratch buffers, not in `keys`"]
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count: u32,
        key_bits: u32,
    ) -> (wgpu::Buffer, wgpu::Buffer) {
        self.record_passes(rec, keys, values, count, key_bits, false)
    }

    /// [`Self::record`] of pairs whose values are their input positions (`values[i] == i`, as
    /// the LBVH's Morton pass writes them): the same result, and counts up to
    /// [`SMALL_POSITIONS_SORT_MAX`] take one dispatch (ties broken by the value, which is the
    /// position). With other values the order of equal keys is unspecified.
    #[must_use = "the sorted pairs may be in the returned scratch buffers, not in `keys`"]
    pub fn record_positions(
        &mut self,
        rec: &mut Recorder<'_>,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count: u32,
        key_bits: u32,
    ) -> (wgpu::Buffer, wgpu::Buffer) {
        if count > SMALL_SORT_MAX && count <= SMALL_POSITIONS_SORT_MAX && key_bits > 0 {
            Self::record_one_workgroup(rec, &self.small_positions, keys, values, count);
            return (keys.clone(), values.clone());
        }
        self.record(rec, keys, values, count, key_bits)
    }

    /// Records `pass`, a one-workgroup sort of the `count` pairs in place.
    fn record_one_workgroup(
        rec: &mut Recorder<'_>,
        pass: &ReflectedPipeline,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count: u32,
    ) {
        let uniform = rec.uniform("radix sort (small) params", &[count, 0u32, 0, 0]);
        let bg = pass.bind_group(
            rec.device,
            "radix sort (small)",
            0,
            &[("small", &uniform), ("s_keys", keys), ("s_vals", values)],
        );
        rec.dispatch("radix sort (small)", &pass.pipeline, &[&bg], 1);
    }

    /// For a sort that will run the digit passes (more than [`SMALL_SORT_MAX`] pairs, at least
    /// 8 key bits): the histogram buffer, reserved, and the block count, so the caller's pass
    /// that writes the keys can also count their first digit (`key & 255`) into it with
    /// `shaders/gpu/digit_histogram.wgsl` (as `lbvh_morton_histogram` does). Then
    /// [`Self::record_after_first_histogram`] sorts.
    pub fn first_histogram(
        &mut self,
        device: &wgpu::Device,
        count: u32,
        key_bits: u32,
    ) -> Option<(wgpu::Buffer, u32)> {
        if count <= SMALL_SORT_MAX || key_bits < DIGIT_BITS {
            return None;
        }
        let nblocks = count.div_ceil(BLOCK);
        self.reserve(device, count, hist_len(nblocks));
        self.hist.clone().map(|h| (h, nblocks))
    }

    /// [`Self::record`] whose first digit pass takes its histogram as the caller wrote it (see
    /// [`Self::first_histogram`]): one dispatch fewer.
    #[must_use = "the sorted pairs may be in the returned scratch buffers, not in `keys`"]
    pub fn record_after_first_histogram(
        &mut self,
        rec: &mut Recorder<'_>,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count: u32,
        key_bits: u32,
    ) -> (wgpu::Buffer, wgpu::Buffer) {
        self.record_passes(rec, keys, values, count, key_bits, true)
    }

    /// [`Self::record`], skipping the first pass's histogram when `first_counted`.
    fn record_passes(
        &mut self,
        rec: &mut Recorder<'_>,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count: u32,
        key_bits: u32,
        first_counted: bool,
    ) -> (wgpu::Buffer, wgpu::Buffer) {
        let in_place = (keys.clone(), values.clone());
        if count <= 1 || key_bits == 0 {
            return in_place;
        }
        if count <= SMALL_SORT_MAX {
            // Same result (stable, ascending) in one dispatch instead of 3 per digit pass.
            Self::record_one_workgroup(rec, &self.small, keys, values, count);
            return in_place;
        }
        let key_bits = key_bits.min(32);
        let nblocks = count.div_ceil(BLOCK);
        self.reserve(rec.device, count, hist_len(nblocks));
        let (Some(keys_tmp), Some(vals_tmp), Some(hist)) =
            (&self.keys_tmp, &self.vals_tmp, &self.hist)
        else {
            return in_place; // reserve always creates them
        };

        let params = Params {
            count,
            shift: 0,
            bits: 0,
            nblocks,
        };
        // A copy of the device reference, so the closure does not borrow `rec` (dispatch needs it
        // mutably).
        let device = rec.device;
        let bind = |pipeline: &ReflectedPipeline, buffers: &[(&str, &wgpu::Buffer)]| {
            pipeline.bind_group(device, "radix sort", 0, buffers)
        };

        let passes = key_bits.div_ceil(DIGIT_BITS);
        for pass in 0..passes {
            let shift = pass * DIGIT_BITS;
            let p = Params {
                shift,
                bits: (key_bits - shift).min(DIGIT_BITS),
                ..params
            };
            let uniform = rec.uniform("radix sort pass params", &p);
            // Even passes read the caller's buffers, odd passes write them back.
            let (src, dst) = if pass % 2 == 0 {
                ((keys, values), (keys_tmp, vals_tmp))
            } else {
                ((keys_tmp, vals_tmp), (keys, values))
            };
            let buffers = [
                ("params", &uniform),
                ("keys_in", src.0),
                ("vals_in", src.1),
                ("keys_out", dst.0),
                ("vals_out", dst.1),
                ("hist", hist),
            ];
            if !(first_counted && pass == 0) {
                let hist_group = bind(&self.histogram, &buffers);
                rec.dispatch(
                    "radix sort histogram",
                    &self.histogram.pipeline,
                    &[&hist_group],
                    nblocks,
                );
            }
            let scatter = if nblocks <= SUMMING_MAX_BLOCKS {
                &self.scatter_summing
            } else {
                let scan_group = bind(&self.scan_rows, &buffers);
                rec.dispatch(
                    "radix sort scan",
                    &self.scan_rows.pipeline,
                    &[&scan_group],
                    RADIX,
                );
                &self.scatter
            };
            let scatter_group = bind(scatter, &buffers);
            rec.dispatch(
                "radix sort scatter",
                &scatter.pipeline,
                &[&scatter_group],
                nblocks,
            );
        }
        if passes % 2 == 1 {
            (keys_tmp.clone(), vals_tmp.clone())
        } else {
            in_place
        }
    }

    /// Bytes of scratch it holds now (for the SDK's memory accounting).
    pub fn scratch_bytes(&self) -> u64 {
        [&self.keys_tmp, &self.vals_tmp, &self.hist]
            .iter()
            .filter_map(|b| b.as_ref().map(|b| b.size()))
            .sum()
    }

    /// Drops its scratch (the next sort allocates what it needs).
    pub fn release_scratch(&mut self) {
        self.keys_tmp = None;
        self.vals_tmp = None;
        self.hist = None;
    }

    /// Makes the scratch hold `count` pairs and `hist_len` histogram entries. Growing drops the
    /// old buffers: wgpu keeps them alive while already recorded commands use them.
    fn reserve(&mut self, device: &wgpu::Device, count: u32, hist_len: u32) {
        let storage = |label, entries: u32| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: u64::from(entries.max(1)) * 4,
                // COPY_SRC: a result left in the scratch can be read back (tests, tools).
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let too_small = |b: &Option<wgpu::Buffer>, entries: u32| {
            b.as_ref().is_none_or(|b| b.size() < u64::from(entries) * 4)
        };
        if too_small(&self.keys_tmp, count) || too_small(&self.vals_tmp, count) {
            // Whole blocks: a later sort of a slightly larger count reuses them.
            let entries = count.checked_next_multiple_of(BLOCK).unwrap_or(count);
            self.keys_tmp = Some(storage("kickstart-rt radix sort keys scratch", entries));
            self.vals_tmp = Some(storage("kickstart-rt radix sort values scratch", entries));
        }
        if too_small(&self.hist, hist_len) {
            self.hist = Some(storage("kickstart-rt radix sort histogram", hist_len));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::testing;

    /// Both shaders composed and validated with naga without a device; the uniform and the
    /// constants the Rust side mirrors checked against them.
    #[test]
    fn the_shaders_validate_and_match_the_rust_side() {
        use crate::gpu::compose::compose;
        use crate::gpu::wgsl_check::{assert_wgsl_layout, const_u32, validate};
        let sort = validate("gpu/radix_sort", &compose(&["gpu/radix_sort"], &[]));
        assert_wgsl_layout!(
            sort,
            "Params",
            Params {
                count,
                shift,
                bits,
                nblocks
            }
        );
        assert_eq!(const_u32(&sort, "RADIX"), RADIX);
        assert_eq!(const_u32(&sort, "SUMMING_MAX_BLOCKS"), SUMMING_MAX_BLOCKS);
        let small = validate(
            "gpu/radix_sort_small",
            &compose(&["gpu/radix_sort_small"], &[]),
        );
        assert_eq!(const_u32(&small, "SMALL_N"), SMALL_SORT_MAX);
        assert_eq!(const_u32(&small, "SMALL_POS_N"), SMALL_POSITIONS_SORT_MAX);
    }

    /// Deterministic xorshift generator (tests need no `rand`).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 32) as u32
        }
    }

    fn to_u32s(bytes: &[u8]) -> Vec<u32> {
        bytemuck::pod_collect_to_vec(bytes)
    }

    /// Sorts `keys` (values = a scrambled original index) on the GPU with `sorter` and asserts
    /// both arrays equal a CPU stable sort by the key's low `key_bits` bits (the whole keys,
    /// higher bits included, are what must come back).
    fn check_with(sorter: &mut RadixSort, keys: &[u32], key_bits: u32) {
        let n = keys.len();
        let values: Vec<u32> = (0..n as u32)
            .map(|i| i.wrapping_mul(0x9e37_79b9) ^ 7)
            .collect();
        // Buffers of at least 4 bytes (wgpu rejects empty bindings); only the first n count.
        let pad = |v: &[u32]| {
            let mut v = v.to_vec();
            v.push(0xdead_beef);
            v
        };
        let kb = testing::buffer_with(bytemuck::cast_slice(&pad(keys)));
        let vb = testing::buffer_with(bytemuck::cast_slice(&pad(&values)));
        let mut sorted = None;
        testing::run(|rec| sorted = Some(sorter.record(rec, &kb, &vb, n as u32, key_bits)));
        let (sk, sv) = sorted.expect("recorded");
        // An odd number of digit passes leaves the pairs in the scratch (no copy back); an even
        // number, the one-workgroup path and no sort at all leave them in the caller's buffers.
        let passes = key_bits.min(32).div_ceil(DIGIT_BITS);
        let in_scratch = n as u32 > SMALL_SORT_MAX && passes % 2 == 1;
        assert_eq!(
            (sk != kb, sv != vb),
            (in_scratch, in_scratch),
            "where the pairs are, n = {n}, key_bits = {key_bits}"
        );
        // At least one word: a read-back of nothing is not a copy wgpu accepts.
        let words = (n as u64).max(1) * 4;
        let got_keys = to_u32s(&testing::read_back(&sk, 0, words));
        let got_vals = to_u32s(&testing::read_back(&sv, 0, words));

        let mut expected: Vec<(u32, u32)> = keys.iter().copied().zip(values).collect();
        let mask = u32::MAX.checked_shr(32 - key_bits.min(32)).unwrap_or(0);
        expected.sort_by_key(|&(k, _)| k & mask); // stable
        let (exp_keys, exp_vals): (Vec<u32>, Vec<u32>) = expected.into_iter().unzip();
        assert_eq!(
            got_keys[..n],
            exp_keys[..],
            "keys, n = {n}, key_bits = {key_bits}"
        );
        assert_eq!(
            got_vals[..n],
            exp_vals[..],
            "values, n = {n}, key_bits = {key_bits}"
        );
        // The caller's buffers past `count` are never written (in the scratch they are
        // unspecified).
        let tail = |b: &wgpu::Buffer| to_u32s(&testing::read_back(b, n as u64 * 4, 4));
        assert_eq!(tail(&kb), [0xdead_beef], "wrote past count");
        assert_eq!(tail(&vb), [0xdead_beef], "wrote past count");
    }

    fn check(keys: &[u32], key_bits: u32) {
        check_with(&mut RadixSort::new(&testing::gpu().device), keys, key_bits);
    }

    /// `n` keys below 2^bits drawn from about `n / 8` distinct values (many duplicates).
    fn random_keys(n: usize, bits: u32, seed: u64) -> Vec<u32> {
        let mut rng = Rng(seed);
        let mask = if bits == 32 {
            u32::MAX
        } else {
            (1 << bits) - 1
        };
        let pool: Vec<u32> = (0..n / 8 + 1).map(|_| rng.next() & mask).collect();
        (0..n)
            .map(|_| pool[rng.next() as usize % pool.len()])
            .collect()
    }

    #[test]
    fn radix_sort_of_positions_takes_one_workgroup_up_to_2048() {
        // Values that are the positions (as the LBVH's Morton pass writes them): the same
        // stable order as a CPU sort, in the caller's buffers, in one dispatch from 1025 to
        // 2048 pairs; past that the digit passes (24-bit keys: 3, ending in the scratch).
        let mut sorter = RadixSort::new(&testing::gpu().device);
        for (n, seed) in [
            (1000, 1),
            (1025, 2),
            (1500, 3),
            (2047, 4),
            (2048, 5),
            (2049, 6),
        ] {
            let keys = random_keys(n, 24, seed);
            let values: Vec<u32> = (0..n as u32).collect();
            let kb = testing::buffer_with(bytemuck::cast_slice(&keys));
            let vb = testing::buffer_with(bytemuck::cast_slice(&values));
            let mut out = None;
            let mut dispatches = 0;
            testing::run(|rec| {
                out = Some(sorter.record_positions(rec, &kb, &vb, n as u32, 24));
                dispatches = rec.dispatches;
            });
            let (sk, sv) = out.expect("recorded");
            let one_workgroup = n as u32 <= SMALL_POSITIONS_SORT_MAX;
            assert_eq!(
                dispatches == 1,
                one_workgroup,
                "n = {n}: {dispatches} dispatches"
            );
            assert_eq!(
                (sk == kb, sv == vb),
                (one_workgroup, one_workgroup),
                "n = {n}"
            );
            let got_keys = to_u32s(&testing::read_back(&sk, 0, n as u64 * 4));
            let got_vals = to_u32s(&testing::read_back(&sv, 0, n as u64 * 4));
            let mut expected: Vec<(u32, u32)> = keys.iter().copied().zip(values).collect();
            expected.sort_by_key(|&(k, _)| k); // stable
            let (exp_keys, exp_vals): (Vec<u32>, Vec<u32>) = expected.into_iter().unzip();
            assert_eq!(got_keys, exp_keys, "keys, n = {n}");
            assert_eq!(got_vals, exp_vals, "values, n = {n}");
        }
    }

    #[test]
    fn radix_sort_random_30_bit_sizes_around_block_multiples() {
        // One sorter for all sizes: also exercises growing the scratch between sorts.
        let mut sorter = RadixSort::new(&testing::gpu().device);
        for (i, n) in [0usize, 1, 2, 255, 256, 257, 1023, 1024, 1025, 4097, 100_003]
            .into_iter()
            .enumerate()
        {
            check_with(&mut sorter, &random_keys(n, 30, 1 + i as u64), 30);
        }
        assert!(sorter.scratch_bytes() >= 2 * 100_003 * 4);
    }

    #[test]
    fn radix_sort_all_equal_keys_keep_input_order() {
        check(&vec![12345u32; 5000], 30);
        check(&vec![0u32; 3000], 32);
        // The one-workgroup path: equal keys, including keys equal to its padding key.
        check(&vec![7u32; 1000], 30);
        check(&vec![u32::MAX; 700], 32);
        check(&[u32::MAX, 0, u32::MAX, 5, 0, u32::MAX, 5], 32);
    }

    #[test]
    fn radix_sort_sorted_and_reversed_input() {
        let sorted: Vec<u32> = (0..20_000u32).map(|i| i * 37).collect();
        check(&sorted, 30);
        let reversed: Vec<u32> = sorted.iter().rev().copied().collect();
        check(&reversed, 30);
    }

    #[test]
    fn radix_sort_full_32_bit_keys() {
        let mut rng = Rng(99);
        let mut keys: Vec<u32> = (0..30_000).map(|_| rng.next()).collect();
        keys.extend([u32::MAX, 0, u32::MAX, 1 << 31, 0]);
        check(&keys, 32);
    }

    #[test]
    fn radix_sort_fewer_key_bits() {
        // 6, 5 and 1 bits: one pass (ends in the scratch), a single nibble split; 13 bits: two passes, the
        // last of 5 bits; 30 bits: four.
        for (bits, n) in [(6, 10_000), (5, 3000), (13, 7000), (1, 2500), (30, 70_000)] {
            check(&random_keys(n, bits, u64::from(bits) * 7 + 3), bits);
        }
    }

    #[test]
    fn radix_sort_key_bits_not_a_multiple_of_8() {
        // 31 (the LBVH's): 4 passes, the last of 7 bits. 12: 8 + 4, the last pass a single
        // nibble split. 20: 3 passes (ending in the scratch), the last of 4 bits. 7: one pass.
        // 9: a last pass of 1 bit. Sizes not multiples of the block: a partial last block.
        for (bits, n) in [
            (31, 50_001),
            (12, 9_000),
            (20, 6_001),
            (7, 4_100),
            (9, 3_333),
        ] {
            check(&random_keys(n, bits, u64::from(bits) * 11 + 1), bits);
        }
        // Every key the largest of its key_bits, in a partial last block: the block's padding
        // has the largest digit too and must still rank after them.
        check(&vec![(1 << 31) - 1; 2_500], 31);
        check(&vec![u32::MAX; 3_000], 32);
        check(&vec![0xfff; 1_500], 12);
    }

    #[test]
    fn radix_sort_tlas_key_bits_end_in_the_scratch() {
        // The LBVH's TLAS keys: 24 bits (8 Morton bits per axis; empty primitives all ones),
        // 3 passes whose result stays in the scratch; 22 bits, a last pass of 6 bits. One sorter
        // for all sizes, so a later sort overwrites (or grows) the scratch an earlier one
        // returned.
        let mut sorter = RadixSort::new(&testing::gpu().device);
        for (i, (n, bits)) in [(1025usize, 24), (4096, 24), (10_007, 22), (100_003, 24)]
            .into_iter()
            .enumerate()
        {
            let mut keys = random_keys(n, bits, 50 + i as u64);
            // Every 9th the "empty" key, which must sort after every other key.
            for k in keys.iter_mut().step_by(9) {
                *k = (1 << bits) - 1;
            }
            check_with(&mut sorter, &keys, bits);
        }
        check_with(&mut sorter, &vec![(1 << 24) - 1; 3_001], 24);
        check_with(&mut sorter, &vec![0; 2_048], 24);
    }

    #[test]
    fn radix_sort_bits_above_key_bits_are_carried_not_sorted() {
        // Random high bits over 12-bit sort keys: the order is by the low 12 bits alone (stable),
        // the keys come back whole.
        let mut rng = Rng(77);
        let keys: Vec<u32> = random_keys(20_000, 12, 78)
            .into_iter()
            .map(|k| k | (rng.next() << 12))
            .collect();
        check(&keys, 12);
        // Same with 8 bits (one pass, ending in the scratch) and 16 bits (two full passes).
        let keys: Vec<u32> = (0..5_000u32).map(|i| rng.next() ^ (i % 3)).collect();
        check(&keys, 8);
        check(&keys, 16);
        // 0 bits sort nothing (input order is the stable order of equal keys); more than 32 are
        // 32.
        check(&keys, 0);
        check(&keys, 40);
    }

    #[test]
    fn radix_sort_stable_with_many_duplicate_digits() {
        // Every key shares its low digit with many others (and nibbles within a digit repeat), so
        // the within-block ranking of both nibble splits and the global offsets decide the order
        // of long runs of equal digits; values reveal any reordering of equal keys.
        let mut rng = Rng(4_321);
        let digits = [0x00u32, 0x0f, 0xf0, 0xff, 0x11, 0x80, 0x08];
        let keys: Vec<u32> = (0..40_000)
            .map(|_| {
                let lo = digits[rng.next() as usize % digits.len()];
                let hi = digits[rng.next() as usize % digits.len()];
                (hi << 8) | lo
            })
            .collect();
        check(&keys, 16);
        check(&keys, 31);
        // Two keys only, alternating in runs of irregular length across block boundaries.
        let keys: Vec<u32> = (0..12_345u32)
            .map(|i| if (i / 97) % 2 == 0 { 0x0102 } else { 0x0201 })
            .collect();
        check(&keys, 16);
    }

    #[test]
    fn radix_sort_both_scatters_at_the_summing_limit() {
        // Up to SUMMING_MAX_BLOCKS blocks the scatter sums the histogram rows itself; one
        // element more takes scan_rows and the plain scatter. Both must sort alike.
        let mut sorter = RadixSort::new(&testing::gpu().device);
        let at = (SUMMING_MAX_BLOCKS * BLOCK) as usize;
        for (n, seed) in [(at - 1, 77), (at, 78), (at + 1, 79)] {
            check_with(&mut sorter, &random_keys(n, 24, seed), 24);
            check_with(&mut sorter, &random_keys(n, 31, seed + 100), 31);
        }
    }

    #[test]
    fn radix_sort_histogram_rows_longer_than_one_scan_chunk() {
        // `scan_rows` scans a row (one digit over all blocks) 1024 blocks per loop iteration:
        // 1024 blocks is exactly one chunk, 1025 the smallest that needs two (the carry between
        // them).
        let mut sorter = RadixSort::new(&testing::gpu().device);
        for (n, seed) in [(1024 * 1024, 4_242), (1024 * 1024 + 1, 4_243)] {
            check_with(&mut sorter, &random_keys(n, 31, seed), 31);
        }
    }

    /// Rough GPU timing of 1M 30-bit keys (run on real GPUs:
    /// `cargo test --lib radix_sort_bench -- --ignored --nocapture`). Records several sorts in
    /// one submission so per-submit overhead is amortised; also checks the result.
    #[test]
    #[ignore]
    fn radix_sort_bench_1m_30_bit() {
        let n = 1 << 20;
        let keys = random_keys(n, 30, 5);
        let g = testing::gpu();
        let mut sorter = RadixSort::new(&g.device);
        check_with(&mut sorter, &keys, 30); // warm-up and correctness
        let kb = testing::buffer_with(bytemuck::cast_slice(&keys));
        let vb = testing::buffer(n as u64 * 4);
        // Record first (wgpu's CPU cost, large in debug builds), then time only submit + wait.
        let reps = 20;
        let mut enc = g.device.create_command_encoder(&Default::default());
        let record_start = std::time::Instant::now();
        {
            let mut rec = crate::gpu::Recorder::new(&g.device, &mut enc);
            for _ in 0..reps {
                // 4 passes: the pairs end in `kb`/`vb` again.
                let _ = sorter.record(&mut rec, &kb, &vb, n as u32, 30);
            }
        }
        let commands = enc.finish();
        let recorded = record_start.elapsed() / reps;
        let start = std::time::Instant::now();
        g.queue.submit([commands]);
        g.device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
        let per_sort = start.elapsed() / reps;
        println!(
            "radix sort of {n} pairs (30-bit keys): GPU {per_sort:?} per sort (submit to idle), \
             recording {recorded:?} per sort"
        );
        // The brief's upper size: 16M pairs (histogram rows of 16384 blocks: 16 chunks each).
        check_with(&mut sorter, &random_keys(16 << 20, 30, 6), 30);
    }
}
