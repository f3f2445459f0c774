//! Cutouts (glTF `alphaMode: MASK`) on the CPU: the test exactly as the SDK bakes it into its
//! opacity micro-maps and the rasteriser runs it per fragment (the texel of mip 0 the
//! coordinates fall in, repeating, its alpha times the factor against the cutoff), and rays on
//! the CPU reference BVH that pass through transparent texels as the SDK's traversal does.
//!
//! One rule in three places is the point: the G-buffer, the shadow map, the SDK's traces and the
//! CPU reference must agree on which texels are holes, so none of them uses filtered sampling.

use glam::Vec3;
use kickstart_rt::cpu::{intersect_triangle, CpuBvh, Hit, Ray};

use super::{AlphaMode, Mesh, Scene, Texture};

/// The parameters of a mesh's MASK test: opaque where `factor` × alpha ≥ `cutoff`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaskTest {
    /// Multiplies the texture's alpha (glTF `baseColorFactor.a`).
    pub factor: f32,
    /// The threshold (glTF `alphaCutoff`).
    pub cutoff: f32,
}

impl MaskTest {
    /// Whether a texel of `alpha` (0..=1) is opaque. The same f32 product and comparison as the
    /// SDK's bake and the G-buffer shader, so a texel right at the cutoff falls the same way.
    pub fn opaque(self, alpha: f32) -> bool {
        self.factor * alpha >= self.cutoff
    }
}

impl Mesh {
    /// The mesh's MASK test, or `None` where it is opaque ([`AlphaMode::Opaque`], and
    /// [`AlphaMode::Blend`], which `ksrt` draws opaque).
    pub fn mask(&self) -> Option<MaskTest> {
        match self.material.alpha {
            AlphaMode::Mask { factor, cutoff } => Some(MaskTest { factor, cutoff }),
            AlphaMode::Opaque | AlphaMode::Blend => None,
        }
    }

    /// The texture coordinates at barycentrics `(u, v)` of triangle `triangle` (weights of its
    /// second and third vertex). Coordinates a file leaves out (or not one a vertex), or that are
    /// not finite, read as (0, 0): what the SDK reads for a non-finite coordinate and what the
    /// upload gives the rasteriser and the SDK.
    pub fn uv_at(&self, triangle: usize, u: f32, v: f32) -> [f32; 2] {
        let complete = self.uvs.len() == self.positions.len();
        let corner = |k: usize| {
            self.indices
                .get(triangle * 3 + k)
                .and_then(|&i| self.uvs.get(i as usize))
                .filter(|_| complete)
                .filter(|c| c[0].is_finite() && c[1].is_finite())
                .copied()
                .unwrap_or([0.0; 2])
        };
        let (a, b, c) = (corner(0), corner(1), corner(2));
        let w = 1.0 - u - v;
        [
            w * a[0] + u * b[0] + v * c[0],
            w * a[1] + u * b[1] + v * c[1],
        ]
    }
}

/// The texel of `image` that `uv` falls in, repeating outside 0..1 (u across, v down from row 0),
/// as the SDK finds it: `min(floor(fract(uv) × size), size − 1)`.
pub fn texel_of(image: &image::RgbaImage, uv: [f32; 2]) -> (u32, u32) {
    let (w, h) = image.dimensions();
    let index = |c: f32, n: u32| {
        let f = c - c.floor();
        // A non-finite coordinate has no texel: the SDK reads such coordinates as 0.
        let f = if f.is_finite() { f } else { 0.0 };
        ((f * n as f32) as u32).min(n.saturating_sub(1))
    };
    (index(uv[0], w), index(uv[1], h))
}

/// The alpha (0..=1) of the texel of `image` that `uv` falls in ([`texel_of`]); 1 for an
/// image without texels.
pub fn texel_alpha(image: &image::RgbaImage, uv: [f32; 2]) -> f32 {
    if image.width() == 0 || image.height() == 0 {
        return 1.0;
    }
    let (x, y) = texel_of(image, uv);
    f32::from(image.get_pixel(x, y).0[3]) / 255.0
}

impl Scene {
    /// The texture `mesh`'s MASK test reads: its base colour texture, when the scene has it and
    /// it has texels. `None`: the factor alone decides (a texture of alpha 1).
    pub fn mask_texture(&self, mesh: &Mesh) -> Option<&Texture> {
        mesh.material
            .base_color_texture
            .and_then(|i| self.textures.get(i))
            .filter(|t| t.image.width() > 0 && t.image.height() > 0)
    }

    /// Whether any mesh is a cutout.
    pub fn has_cutouts(&self) -> bool {
        self.meshes.iter().any(|m| m.mask().is_some())
    }

    /// Whether mesh `mesh` is opaque at barycentrics `(u, v)` of its triangle `triangle`: always
    /// for a mesh without a MASK test, else the test at the interpolated coordinates.
    pub fn opaque_at(&self, mesh: usize, triangle: usize, u: f32, v: f32) -> bool {
        let Some(m) = self.meshes.get(mesh) else {
            return true;
        };
        let Some(test) = m.mask() else {
            return true;
        };
        let alpha = self
            .mask_texture(m)
            .map_or(1.0, |t| texel_alpha(&t.image, m.uv_at(triangle, u, v)));
        test.opaque(alpha)
    }
}

/// The scene's world-space triangles in a CPU reference BVH (`kickstart_rt::cpu`), traced the way
/// the SDK traces the scene: hits on a cutout's transparent texels are passed through.
pub struct CutoutCaster<'a> {
    scene: &'a Scene,
    /// World-space triangles of every instance, in instance order.
    pub triangles: Vec<[Vec3; 3]>,
    /// The instance of each triangle.
    pub owner: Vec<u32>,
    /// First world triangle of each instance.
    starts: Vec<usize>,
    /// The BVH over `triangles`.
    pub bvh: CpuBvh,
    /// Whether any mesh is a cutout; without, the BVH's own traversal answers (the same hits,
    /// and scenes without cutouts keep exactly the results they had).
    cutouts: bool,
}

impl<'a> CutoutCaster<'a> {
    /// Builds the BVH over `scene`'s world triangles.
    pub fn new(scene: &'a Scene) -> Self {
        let (triangles, owner) = scene.world_triangles();
        let bvh = CpuBvh::build(&triangles);
        let starts = scene
            .instances
            .iter()
            .scan(0, |n, i| {
                let first = *n;
                *n += scene.meshes.get(i.mesh).map_or(0, Mesh::triangle_count);
                Some(first)
            })
            .collect();
        CutoutCaster {
            scene,
            triangles,
            owner,
            starts,
            bvh,
            cutouts: scene.has_cutouts(),
        }
    }

    /// The instance of world triangle `primitive` and the triangle's index in its mesh.
    pub fn locate(&self, primitive: u32) -> Option<(usize, usize)> {
        let instance = *self.owner.get(primitive as usize)? as usize;
        let first = *self.starts.get(instance)?;
        Some((instance, (primitive as usize).checked_sub(first)?))
    }

    /// Whether `hit` lands on an opaque point (always, off the cutouts).
    pub fn opaque(&self, hit: &Hit) -> bool {
        let Some((instance, triangle)) = self.locate(hit.primitive) else {
            return true;
        };
        let mesh = self.scene.instances[instance].mesh;
        self.scene.opaque_at(mesh, triangle, hit.u, hit.v)
    }

    /// The closest opaque hit in `[t_min, t_max]`; ties in `t` go to the lowest primitive index.
    pub fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        if self.cutouts {
            self.traverse(ray, false)
        } else {
            self.bvh.closest_hit(&self.triangles, ray)
        }
    }

    /// Whether any opaque point is hit in `[t_min, t_max]`.
    pub fn any_hit(&self, ray: &Ray) -> bool {
        if self.cutouts {
            self.traverse(ray, true).is_some()
        } else {
            self.bvh.any_hit(&self.triangles, ray)
        }
    }

    /// A stack traversal of the BVH (its public nodes) that offers each triangle hit to the
    /// cutout test before keeping it: the SDK's leaf loop, on the CPU. `CpuBvh`'s own traversal
    /// keeps every hit, so a filtered one is needed here.
    fn traverse(&self, ray: &Ray, any: bool) -> Option<Hit> {
        let nodes = &self.bvh.nodes;
        if nodes.is_empty() || self.bvh.primitive_indices.is_empty() {
            return None;
        }
        let inv = ray.dir.recip();
        let mut best: Option<Hit> = None;
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let Some(node) = nodes.get(n as usize) else {
                continue;
            };
            let t_max = best.map_or(ray.t_max, |h| h.t);
            if !slab(node.min, node.max, ray.origin, inv, ray.t_min, t_max) {
                continue;
            }
            if node.count == 0 {
                stack.extend([node.first, node.first + 1]);
                continue;
            }
            let leaf = node.first as usize..(node.first + node.count) as usize;
            for &p in self.bvh.primitive_indices.get(leaf).unwrap_or(&[]) {
                let Some(&[a, b, c]) = self.triangles.get(p as usize) else {
                    continue;
                };
                let t_max = best.map_or(ray.t_max, |h| h.t);
                let Some(h) = intersect_triangle(&Ray { t_max, ..*ray }, a, b, c) else {
                    continue;
                };
                let hit = Hit {
                    t: h.t,
                    primitive: p,
                    u: h.u,
                    v: h.v,
                };
                let better =
                    best.is_none_or(|cur| h.t < cur.t || (h.t == cur.t && p < cur.primitive));
                if better && self.opaque(&hit) {
                    best = Some(hit);
                    if any {
                        return best;
                    }
                }
            }
        }
        best
    }
}

/// Whether the ray `o + t / inv` meets the box `[min, max]` within `[t_min, t_max]`. The far
/// bound is widened by 4 ulps, as the SDK's CPU BVH does, so that rays grazing a face are not
/// culled by rounding; an axis where the ray lies in a slab's plane (0 × ∞ = NaN) does not
/// constrain the interval.
fn slab(min: Vec3, max: Vec3, o: Vec3, inv: Vec3, t_min: f32, t_max: f32) -> bool {
    let t0 = (min - o) * inv;
    let t1 = (max - o) * inv;
    let lo = |a: f32| if a.is_nan() { f32::NEG_INFINITY } else { a };
    let hi = |a: f32| if a.is_nan() { f32::INFINITY } else { a };
    let (mut near, mut far) = (t_min, t_max);
    for k in 0..3 {
        near = near.max(lo(t0[k]).min(lo(t1[k])));
        far = far.min(hi(t0[k]).max(hi(t1[k])));
    }
    near <= far * 1.000_000_4
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Material};
    use glam::Affine3A;

    /// A 2×2 texture: alpha 0 in the left column, 255 in the right (rows alike).
    fn half_texture() -> Texture {
        let image = image::RgbaImage::from_fn(2, 2, |x, _| {
            image::Rgba([10, 200, 10, if x == 0 { 0 } else { 255 }])
        });
        Texture {
            name: "half".into(),
            image,
            nearest: true,
        }
    }

    /// A unit quad in the XY plane at `z` (u along x), MASK with `half_texture`, seen along −z.
    fn quad(z: f32, mask: bool) -> Mesh {
        let positions = vec![[0.0, 0.0, z], [1.0, 0.0, z], [1.0, 1.0, z], [0.0, 1.0, z]];
        let mut m = Mesh::new("card", positions, vec![0, 1, 2, 0, 2, 3], Vec3::ONE)
            .unwrap_or_else(|e| panic!("{e}"));
        m.uvs = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        m.material = Material {
            base_color_texture: Some(0),
            alpha: if mask {
                AlphaMode::Mask {
                    factor: 1.0,
                    cutoff: 0.5,
                }
            } else {
                AlphaMode::Opaque
            },
            ..Material::default()
        };
        m
    }

    #[test]
    fn texels_repeat_and_clamp_to_the_last_one() {
        let img = half_texture().image;
        assert_eq!(texel_of(&img, [0.25, 0.75]), (0, 1));
        assert_eq!(texel_of(&img, [1.75, -0.25]), (1, 1));
        assert_eq!(texel_of(&img, [-0.25, 0.0]), (1, 0));
        assert_eq!(texel_of(&img, [f32::NAN, 0.6]), (0, 1));
        // Just below 1: the last texel, never one past it.
        assert_eq!(texel_of(&img, [0.999_999_94, 0.5]), (1, 1));
        assert_eq!(texel_alpha(&img, [0.25, 0.5]), 0.0);
        assert_eq!(texel_alpha(&img, [1.75, 0.5]), 1.0);
    }

    #[test]
    fn rays_pass_through_transparent_texels_only() {
        // A cutout card in front of an opaque one: through its left half the ray reaches the
        // back card, through its right half it stops.
        let scene = Scene {
            meshes: vec![quad(1.0, true), quad(0.0, false)],
            instances: vec![
                Instance {
                    mesh: 0,
                    transform: Affine3A::IDENTITY,
                },
                Instance {
                    mesh: 1,
                    transform: Affine3A::IDENTITY,
                },
            ],
            textures: vec![half_texture()],
            ..Default::default()
        };
        let caster = CutoutCaster::new(&scene);
        let ray = |x: f32| Ray {
            origin: Vec3::new(x, 0.4, 5.0),
            dir: -Vec3::Z,
            t_min: 0.0,
            t_max: f32::INFINITY,
        };
        let through = caster.closest_hit(&ray(0.25)).expect("hits the back card");
        assert_eq!(caster.locate(through.primitive).map(|l| l.0), Some(1));
        assert!((through.t - 5.0).abs() < 1e-5);
        let stopped = caster.closest_hit(&ray(0.75)).expect("hits the cutout");
        assert_eq!(caster.locate(stopped.primitive).map(|l| l.0), Some(0));
        assert!((stopped.t - 4.0).abs() < 1e-5);
        assert!(caster.any_hit(&ray(0.25)));
        // Without the back card, the hole lets the ray out.
        let alone = Scene {
            meshes: vec![quad(1.0, true)],
            instances: vec![Instance {
                mesh: 0,
                transform: Affine3A::IDENTITY,
            }],
            textures: vec![half_texture()],
            ..Default::default()
        };
        let caster = CutoutCaster::new(&alone);
        assert!(caster.closest_hit(&ray(0.25)).is_none());
        assert!(!caster.any_hit(&ray(0.25)));
        assert!(caster.any_hit(&ray(0.75)));
    }

    #[test]
    fn a_mask_without_texture_is_decided_by_its_factor() {
        let mut scene = Scene {
            meshes: vec![quad(0.0, true)],
            ..Default::default()
        };
        scene.meshes[0].material.base_color_texture = None;
        assert!(scene.opaque_at(0, 0, 0.2, 0.2));
        scene.meshes[0].material.alpha = AlphaMode::Mask {
            factor: 0.4,
            cutoff: 0.5,
        };
        assert!(!scene.opaque_at(0, 0, 0.2, 0.2));
        scene.meshes[0].material.alpha = AlphaMode::Blend;
        assert!(scene.opaque_at(0, 0, 0.2, 0.2));
    }
}
