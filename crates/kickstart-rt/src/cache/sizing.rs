//! The sizing formulas of the module docs, on the CPU: the GPU allocation (`cache/alloc.wgsl`)
//! implements the same rules; these give tools and tests the expected surfel counts.

use super::CacheParams;
use glam::Vec3;

/// `tiles(L) = clamp(ceil(L / unit), 1, limit)`.
pub(crate) fn tiles_along(len: f32, p: &CacheParams) -> u32 {
    let n = (len / p.tile_unit_length).ceil();
    if n >= 1.0 {
        n.min(p.tile_resolution_limit as f32) as u32
    } else {
        1
    }
}

/// WarpedBarycentricStorage tiles per edge of a triangle (world-space corners).
pub(crate) fn wb_resolution(tri: [Vec3; 3], p: &CacheParams) -> u32 {
    if p.force_direct_tile_mapping {
        return 1;
    }
    let [a, b, c] = tri;
    let area = 0.5 * (b - a).cross(c - a).length();
    if area.is_nan() || area < p.direct_tile_mapping_threshold * p.tile_unit_length.powi(2) {
        return 1;
    }
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    tiles_along(longest, p)
}

/// MeshColors resolution of an edge of world length `len` (a power of two).
pub(crate) fn mc_edge_resolution(len: f32, p: &CacheParams) -> u32 {
    if p.force_direct_tile_mapping {
        return 1;
    }
    let max = 1u32 << (31 - p.tile_resolution_limit.max(1).leading_zeros());
    tiles_along(len, p).next_power_of_two().min(max)
}

/// MeshColors surfels of one triangle on its own (no neighbours): 3 vertices, its 3 edges'
/// interior samples and its interior samples.
pub(crate) fn mc_triangle_surfels(tri: [Vec3; 3], p: &CacheParams) -> u32 {
    let e: Vec<u32> = (0..3)
        .map(|k| mc_edge_resolution((tri[(k + 1) % 3] - tri[k]).length(), p))
        .collect();
    let r = e.iter().copied().max().unwrap_or(1);
    3 + e.iter().map(|e| e - 1).sum::<u32>() + (r - 1) * r.saturating_sub(2) / 2
}

/// Surfels of a whole mesh in the MeshColors layout: vertices and edges shared by position.
pub(crate) fn mc_mesh_surfels(tris: &[[Vec3; 3]], p: &CacheParams) -> u32 {
    use std::collections::HashSet;
    let key = |v: Vec3| (v + Vec3::ZERO).to_array().map(|x| (x + 0.0).to_bits());
    let mut verts = HashSet::new();
    let mut edges = HashSet::new();
    let mut total = 0;
    for t in tris {
        let mut r = 1;
        for k in 0..3 {
            let (a, b) = (key(t[k]), key(t[(k + 1) % 3]));
            verts.insert(a);
            let e = mc_edge_resolution((t[(k + 1) % 3] - t[k]).length(), p);
            r = r.max(e);
            if edges.insert(if a <= b { (a, b) } else { (b, a) }) {
                total += e - 1;
            }
        }
        total += (r - 1) * r.saturating_sub(2) / 2;
    }
    total + verts.len() as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(mesh_colors: bool) -> CacheParams {
        CacheParams {
            mesh_colors,
            tile_unit_length: 1.0,
            tile_resolution_limit: 64,
            direct_tile_mapping_threshold: 0.7,
            force_direct_tile_mapping: false,
        }
    }

    fn right(size: f32) -> [Vec3; 3] {
        [
            Vec3::ZERO,
            Vec3::new(size, 0.0, 0.0),
            Vec3::new(0.0, size, 0.0),
        ]
    }

    #[test]
    fn tiny_triangles_get_one_tile() {
        let p = params(false);
        assert_eq!(wb_resolution(right(1e-4), &p), 1);
        assert_eq!(mc_triangle_surfels(right(1e-4), &params(true)), 3);
        // Area 0.5 < 0.7 tiles: direct mapping although the hypotenuse spans 2 tiles.
        assert_eq!(wb_resolution(right(1.0), &p), 1);
        // Area 1.125 ≥ 0.7: the longest edge (2.12) needs 3 tiles.
        assert_eq!(wb_resolution(right(1.5), &p), 3);
    }

    #[test]
    fn huge_triangles_stop_at_the_resolution_limit() {
        let p = params(false);
        assert_eq!(wb_resolution(right(1e6), &p), 64);
        let mc = params(true);
        assert_eq!(mc_edge_resolution(1e6, &mc), 64);
        // R = 64: 3 vertices + 3·63 edge samples + 63·62/2 interior.
        assert_eq!(mc_triangle_surfels(right(1e6), &mc), 3 + 189 + 1953);
        let odd = CacheParams {
            tile_resolution_limit: 48,
            ..mc
        };
        assert_eq!(
            mc_edge_resolution(1e6, &odd),
            32,
            "largest power of two ≤ 48"
        );
    }

    #[test]
    fn slivers_follow_their_longest_edge() {
        let sliver = [
            Vec3::ZERO,
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(5.0, 1e-3, 0.0),
        ];
        // Area 0.005 tiles: direct mapping in the tile grid.
        assert_eq!(wb_resolution(sliver, &params(false)), 1);
        // MeshColors: edges of 10, ~5, ~5 → E = 16, 8, 8; R = 16.
        let mc = params(true);
        assert_eq!(mc_edge_resolution(10.0, &mc), 16);
        assert_eq!(mc_edge_resolution(5.0000001, &mc), 8);
        assert_eq!(
            mc_triangle_surfels(sliver, &mc),
            3 + 15 + 7 + 7 + 15 * 14 / 2
        );
    }

    #[test]
    fn force_direct_mapping_and_unit_length_scale() {
        let forced = CacheParams {
            force_direct_tile_mapping: true,
            ..params(true)
        };
        assert_eq!(mc_triangle_surfels(right(100.0), &forced), 3);
        assert_eq!(wb_resolution(right(100.0), &forced), 1);
        let fine = CacheParams {
            tile_unit_length: 0.25,
            ..params(false)
        };
        // Longest edge 1.414 / 0.25 = 5.66 → 6 tiles per edge.
        assert_eq!(wb_resolution(right(1.0), &fine), 6);
    }

    #[test]
    fn mesh_colors_share_vertices_and_edges_by_position() {
        let p = params(true);
        // A unit quad as two triangles with split vertices (distinct indices, same positions).
        let a = Vec3::ZERO;
        let b = Vec3::new(2.0, 0.0, 0.0);
        let c = Vec3::new(2.0, 2.0, 0.0);
        let d = Vec3::new(0.0, 2.0, 0.0);
        let n = mc_mesh_surfels(&[[a, b, c], [a, c, d]], &p);
        // 4 vertices; edges of 2 → E = 2 (1 sample), diagonal 2.83 → E = 4 (3 samples, shared);
        // both triangles R = 4 → 3 interior samples each.
        assert_eq!(n, 4 + 4 + 3 + 2 * 3);
    }
}
