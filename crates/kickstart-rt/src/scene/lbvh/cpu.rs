//! CPU helpers of the tests: what the GPU passes compute, the plain way.

/// The centroid-bounds words (`shaders/scene/centroid_bounds.wgsl`) of stored boxes `(min, max)`, as
/// the GPU merges them: the CPU oracle of both passes that merge them.
pub(crate) fn cpu_centroid_bounds(boxes: impl Iterator<Item = ([f32; 3], [f32; 3])>) -> [u32; 6] {
    // A float as a u32 that sorts like it (the shader's `enc`).
    let enc = |x: f32| {
        let b = x.to_bits();
        if b & 0x8000_0000 != 0 {
            !b
        } else {
            b | 0x8000_0000
        }
    };
    let mut words = [0u32; 6];
    for (lo, hi) in boxes {
        let empty = lo.iter().chain(&hi).any(|v| v.is_nan()) || lo[0] > hi[0];
        let c: [f32; 3] = std::array::from_fn(|a| lo[a] * 0.5 + hi[a] * 0.5);
        if empty || c.iter().any(|v| !v.is_finite()) {
            continue;
        }
        for a in 0..3 {
            words[a] = words[a].max(!enc(c[a]));
            words[3 + a] = words[3 + a].max(enc(c[a]));
        }
    }
    words
}
