//! Random numbers of the trace tasks: the blue-noise tile the SDK generates (void and cluster,
//! Ulichney 1993), uploaded once per context. The WGSL side (`tr_next` in
//! `shaders/trace/common.wgsl`) reads dimension `d` of a pixel from the tile at a fixed toroidal
//! shift of `d` and adds `frame_index × (golden ratio − 1)`: every frame is spatially blue, frames
//! are a low-discrepancy sequence per pixel, and the same frame index gives the same numbers.

use std::sync::OnceLock;

/// Side of the square blue-noise tile, texels (`TR_BN_SIZE` in the WGSL).
pub(crate) const BLUE_NOISE_SIZE: usize = 64;

/// Standard deviation of the void-and-cluster energy filter, texels (Ulichney's 1.5).
const SIGMA: f32 = 1.5;

/// The tile: `BLUE_NOISE_SIZE²` values `(rank + 0.5) / n`, row-major; every rank appears once.
pub(crate) fn blue_noise() -> &'static [f32] {
    static TILE: OnceLock<Vec<f32>> = OnceLock::new();
    TILE.get_or_init(|| {
        let n = BLUE_NOISE_SIZE * BLUE_NOISE_SIZE;
        void_and_cluster(BLUE_NOISE_SIZE)
            .into_iter()
            .map(|r| (r as f32 + 0.5) / n as f32)
            .collect()
    })
}

/// The toroidal Gaussian energy kernel, indexed by (dy × size + dx) with wrapped offsets.
fn kernel(size: usize) -> Vec<f32> {
    let mut k = vec![0.0; size * size];
    for dy in 0..size {
        for dx in 0..size {
            let wx = dx.min(size - dx) as f32;
            let wy = dy.min(size - dy) as f32;
            k[dy * size + dx] = (-(wx * wx + wy * wy) / (2.0 * SIGMA * SIGMA)).exp();
        }
    }
    k
}

/// Energy field of a binary pattern, updated as points are added or removed.
struct Field {
    size: usize,
    kernel: Vec<f32>,
    energy: Vec<f32>,
    on: Vec<bool>,
}

impl Field {
    fn toggle(&mut self, at: usize, on: bool) {
        let s = self.size;
        let (x0, y0) = (at % s, at / s);
        let sign = if on { 1.0 } else { -1.0 };
        for y in 0..s {
            let dy = (y + s - y0) % s;
            for x in 0..s {
                let dx = (x + s - x0) % s;
                self.energy[y * s + x] += sign * self.kernel[dy * s + dx];
            }
        }
        self.on[at] = on;
    }

    /// The set point of highest energy (tightest cluster) or the unset point of lowest energy
    /// (largest void); ties to the lowest index, so the tile is deterministic.
    fn extreme(&self, cluster: bool) -> usize {
        let mut best = usize::MAX;
        for i in 0..self.energy.len() {
            if self.on[i] != cluster {
                continue;
            }
            let better = best == usize::MAX
                || if cluster {
                    self.energy[i] > self.energy[best]
                } else {
                    self.energy[i] < self.energy[best]
                };
            if better {
                best = i;
            }
        }
        best
    }
}

/// Ranks 0..size² of a void-and-cluster blue-noise tile.
fn void_and_cluster(size: usize) -> Vec<u32> {
    let n = size * size;
    let mut field = Field {
        size,
        kernel: kernel(size),
        energy: vec![0.0; n],
        on: vec![false; n],
    };
    // Initial pattern: a tenth of the texels from a fixed-seed generator, then relaxed by moving
    // the tightest cluster into the largest void until that changes nothing.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let initial = n / 10;
    let mut placed = 0;
    while placed < initial {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        let i = (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 33) as usize % n;
        if !field.on[i] {
            field.toggle(i, true);
            placed += 1;
        }
    }
    for _ in 0..n {
        let c = field.extreme(true);
        field.toggle(c, false);
        let v = field.extreme(false);
        if v == c {
            field.toggle(c, true);
            break;
        }
        field.toggle(v, true);
    }
    let mut rank = vec![0u32; n];
    // Phase 1: rank the initial points by removing the tightest cluster.
    let saved = (field.energy.clone(), field.on.clone());
    for r in (0..initial).rev() {
        let c = field.extreme(true);
        field.toggle(c, false);
        rank[c] = r as u32;
    }
    (field.energy, field.on) = saved;
    // Phases 2 and 3: fill the largest void until every texel is ranked.
    for r in initial..n {
        let v = field.extreme(false);
        field.toggle(v, true);
        rank[v] = r as u32;
    }
    rank
}

/// The blue-noise tile as an `R32Float` texture (created with its data: nothing reads it before
/// it exists, so the queue write cannot race an earlier encoder).
pub(crate) fn blue_noise_texture(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::TextureView {
    use wgpu::util::DeviceExt;
    let size = BLUE_NOISE_SIZE as u32;
    device
        .create_texture_with_data(
            queue,
            &wgpu::TextureDescriptor {
                label: Some("kickstart-rt blue noise"),
                size: wgpu::Extent3d {
                    width: size,
                    height: size,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(blue_noise()),
        )
        .create_view(&Default::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blue_noise_is_a_permutation_of_ranks() {
        let tile = blue_noise();
        let n = BLUE_NOISE_SIZE * BLUE_NOISE_SIZE;
        let mut ranks: Vec<usize> = tile
            .iter()
            .map(|v| (v * n as f32 - 0.5).round() as usize)
            .collect();
        ranks.sort_unstable();
        assert!(ranks.iter().enumerate().all(|(i, r)| i == *r));
    }

    /// Blue noise has little low-frequency energy: thresholded at any level, the count of set
    /// texels in each 4×4 block varies far less than for white noise (binomial variance
    /// 16·p·(1−p)).
    #[test]
    fn blue_noise_thresholds_are_evenly_spread() {
        let tile = blue_noise();
        let s = BLUE_NOISE_SIZE;
        for p in [0.1f32, 0.25, 0.5, 0.75] {
            let mut counts = Vec::new();
            for by in (0..s).step_by(4) {
                for bx in (0..s).step_by(4) {
                    let mut c = 0.0;
                    for y in by..by + 4 {
                        for x in bx..bx + 4 {
                            if tile[y * s + x] < p {
                                c += 1.0;
                            }
                        }
                    }
                    counts.push(c);
                }
            }
            let mean = counts.iter().sum::<f32>() / counts.len() as f32;
            let var = counts.iter().map(|c| (c - mean).powi(2)).sum::<f32>() / counts.len() as f32;
            let white = 16.0 * p * (1.0 - p);
            assert!((mean - 16.0 * p).abs() < 0.2, "p {p}: mean {mean}");
            assert!(
                var < 0.35 * white,
                "p {p}: variance {var}, white noise {white}"
            );
        }
    }
}
