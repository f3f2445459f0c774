//! The BVH4 node records that traversal reads, and their relation to the binary tree the LBVH
//! builds (layout: `docs/ray-tracing-core.md`, "BVH4 node").
//!
//! Binary inner node `i` owns record `i`: four slots holding its grandchildren, two per binary
//! child (a leaf or empty child fills its first slot and leaves the second empty). Traversal
//! starts at record 0 and follows inner refs to the records of grandchildren, so it tests four
//! boxes per fetch and visits half the levels; records of nodes at odd binary depth are written
//! (the refit needs no special case) but never reached. Each slot's `w` lanes carry its ref and,
//! in the first slot of each half, the binary child's ref, so the binary tree is recoverable on
//! the CPU for checks and SAH.

/// u32 words of one record (8 `vec4`, 128 bytes).
pub(crate) const NODE_WORDS: usize = 32;
/// Bytes of one record.
pub(crate) const NODE_BYTES: u64 = NODE_WORDS as u64 * 4;

/// Binary nodes (16 words each, the layout of one binary node: left box + ref, right box + ref,
/// as `docs/ray-tracing-core.md` describes the binary view) recovered from records: a binary
/// child's box is the union of its half's two slots (an empty slot stores min 1e30 / max −1e30,
/// which leaves the union exact), its ref is the half's `aux` lane.
pub(crate) fn binary_from_wide(words: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(words.len() / 2);
    for rec in words.chunks_exact(NODE_WORDS) {
        let half = |side: usize| -> ([f32; 3], [f32; 3], u32) {
            let h = &rec[16 * side..][..16];
            let f = |i: usize| f32::from_bits(h[i]);
            let lo = [0, 1, 2].map(|a| f(a).min(f(8 + a)));
            let hi = [0, 1, 2].map(|a| f(4 + a).max(f(12 + a)));
            (lo, hi, h[7])
        };
        let (llo, lhi, lref) = half(0);
        let (rlo, rhi, rref) = half(1);
        let bits = |v: [f32; 3]| v.map(f32::to_bits);
        out.extend(bits(llo));
        out.push(lref);
        out.extend(bits(lhi));
        out.push(rref);
        out.extend(bits(rlo));
        out.push(0);
        out.extend(bits(rhi));
        out.push(0);
    }
    out
}

/// Records from binary nodes (4 `vec4` each: left min + left ref, left max + right ref, right
/// min, right max), the inverse of [`binary_from_wide`]: for tests that pack a CPU-built tree in
/// the GPU layout.
#[cfg(test)]
pub(crate) fn wide_from_binary(binary: &[[u32; 4]]) -> Vec<[u32; 4]> {
    const LEAF: u32 = 0x8000_0000;
    let empty_lo = [1e30f32.to_bits(); 3];
    let empty_hi = [(-1e30f32).to_bits(); 3];
    // (min, max, ref) of binary node n's child `side`.
    let child = |n: usize, side: usize| -> ([u32; 3], [u32; 3], u32) {
        let e = &binary[4 * n..][..4];
        let (lo, hi) = (e[2 * side], e[2 * side + 1]);
        let r = if side == 0 { e[0][3] } else { e[1][3] };
        ([lo[0], lo[1], lo[2]], [hi[0], hi[1], hi[2]], r)
    };
    let v = |xyz: [u32; 3], w: u32| [xyz[0], xyz[1], xyz[2], w];
    let mut out = Vec::with_capacity(binary.len() * 2);
    for n in 0..binary.len() / 4 {
        for side in 0..2 {
            let (lo, hi, r) = child(n, side);
            if r & LEAF != 0 {
                out.extend([v(lo, r), v(hi, r), v(empty_lo, LEAF), v(empty_hi, 0)]);
            } else {
                let (alo, ahi, ar) = child(r as usize, 0);
                let (blo, bhi, br) = child(r as usize, 1);
                out.extend([v(alo, ar), v(ahi, r), v(blo, br), v(bhi, 0)]);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(lo: [f32; 3], hi: [f32; 3], r: u32) -> ([u32; 3], [u32; 3], u32) {
        (lo.map(f32::to_bits), hi.map(f32::to_bits), r)
    }

    fn node(l: ([u32; 3], [u32; 3], u32), r: ([u32; 3], [u32; 3], u32)) -> [[u32; 4]; 4] {
        [
            [l.0[0], l.0[1], l.0[2], l.2],
            [l.1[0], l.1[1], l.1[2], r.2],
            [r.0[0], r.0[1], r.0[2], 0],
            [r.1[0], r.1[1], r.1[2], 0],
        ]
    }

    #[test]
    fn binary_tree_survives_the_round_trip_through_records() {
        const LEAF: u32 = 0x8000_0000;
        // Root 0: inner 1 | leaf 2; node 1: leaf 0 | inner 2; node 2: leaf 1 | empty.
        let empty = b([1e30; 3], [-1e30; 3], LEAF);
        let n2 = node(b([2.0, 0.0, 0.0], [3.0, 1.0, 1.0], LEAF | 1), empty);
        let n1 = node(
            b([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], LEAF),
            b([2.0, 0.0, 0.0], [3.0, 1.0, 1.0], 2),
        );
        let n0 = node(
            b([0.0, 0.0, 0.0], [3.0, 1.0, 1.0], 1),
            b([-1.0, -2.0, 0.0], [0.0, 0.0, 5.0], LEAF | (1 << 28) | 2),
        );
        let binary: Vec<[u32; 4]> = [n0, n1, n2].concat();
        let wide = wide_from_binary(&binary);
        assert_eq!(wide.len(), 3 * 8);
        // Record 0's first half holds node 1's children: leaf 0 and inner 2, with aux = 1.
        assert_eq!(wide[0][3], LEAF);
        assert_eq!(wide[1][3], 1);
        assert_eq!(wide[2][3], 2);
        assert_eq!(f32::from_bits(wide[2][0]), 2.0);
        // Its second half: the leaf of two primitives and an empty slot.
        assert_eq!(wide[4][3], LEAF | (1 << 28) | 2);
        assert_eq!(f32::from_bits(wide[6][0]), 1e30);
        let flat: Vec<u32> = wide.iter().flatten().copied().collect();
        let back = binary_from_wide(&flat);
        let expect: Vec<u32> = binary.iter().flatten().copied().collect();
        assert_eq!(back, expect);
    }
}
