//! The view of a scene whose file names no camera or no light: framed from the side its
//! surfaces face (inside an enclosed interior, outside an object) and lit where the camera
//! looks, so that no scene renders as a closed box seen from outside, or black.

use glam::Vec3;
use kickstart_rt::cpu::{CpuBvh, Ray};

use super::{Camera, Light, Scene};

/// At most this many triangles (the largest) stand for the scene in the interior test: walls,
/// floors and ceilings are what encloses a room, and the test stays quick on big files.
const MAX_PROBE_TRIANGLES: usize = 50_000;
/// Fraction of the probe rays from an eye that must meet a surface from its front side for the
/// eye to count as inside an enclosed interior. Measured on the shared scenes' best eyes: the
/// apartment 0.82 (windows and doorways let some out), the open Cornell boxes 1.0; around the
/// bunny at most 0.45 and the dragon 0.23.
pub const ENCLOSED: f32 = 0.6;

/// World triangles with their outward normals (the side the file's vertex normals face).
pub struct Probe {
    tris: Vec<[Vec3; 3]>,
    normals: Vec<Vec3>,
    bvh: CpuBvh,
}

/// Unit directions spread evenly over the sphere (a Fibonacci lattice).
fn sphere_directions(n: u32) -> impl Iterator<Item = Vec3> {
    (0..n).map(move |k| {
        let z = 1.0 - (2.0 * k as f32 + 1.0) / n as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = k as f32 * 2.399_963;
        Vec3::new(r * phi.cos(), z, r * phi.sin())
    })
}

impl Probe {
    /// The largest `MAX_PROBE_TRIANGLES` triangles of `scene` and a CPU BVH over them.
    pub fn new(scene: &Scene) -> Probe {
        let mut faces: Vec<([Vec3; 3], Vec3, f32)> = Vec::new();
        for inst in &scene.instances {
            let mesh = &scene.meshes[inst.mesh];
            let normal_matrix = inst.transform.matrix3.inverse().transpose();
            for t in mesh.indices.chunks_exact(3) {
                let p = |k: usize| {
                    inst.transform
                        .transform_point3(Vec3::from(mesh.positions[t[k] as usize]))
                };
                let tri = [p(0), p(1), p(2)];
                let cross = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
                let Some(geometric) = cross.try_normalize() else {
                    continue;
                };
                // The vertex normals say which side is the front (files' windings disagree).
                let shading: Vec3 = t
                    .iter()
                    .map(|&i| Vec3::from(mesh.normals[i as usize]))
                    .sum();
                let shading = Vec3::from(normal_matrix * glam::Vec3A::from(shading));
                let n = if shading.dot(geometric) < 0.0 {
                    -geometric
                } else {
                    geometric
                };
                faces.push((tri, n, cross.length()));
            }
        }
        if faces.len() > MAX_PROBE_TRIANGLES {
            faces.select_nth_unstable_by(MAX_PROBE_TRIANGLES, |a, b| b.2.total_cmp(&a.2));
            faces.truncate(MAX_PROBE_TRIANGLES);
        }
        let tris: Vec<[Vec3; 3]> = faces.iter().map(|f| f.0).collect();
        let normals = faces.iter().map(|f| f.1).collect();
        let bvh = CpuBvh::build(&tris);
        Probe { tris, normals, bvh }
    }

    /// The closest surface along `dir` from `eye`: its distance and whether the ray meets its
    /// front side.
    fn cast(&self, eye: Vec3, dir: Vec3) -> Option<(f32, bool)> {
        let ray = Ray {
            origin: eye,
            dir,
            t_min: 0.0,
            t_max: f32::INFINITY,
        };
        let h = self.bvh.closest_hit(&self.tris, &ray)?;
        Some((h.t, self.normals[h.primitive as usize].dot(dir) < 0.0))
    }

    /// The median distance from `eye` to the surfaces 64 rays meet (0 when none does): how much
    /// space is around it.
    fn typical_distance(&self, eye: Vec3) -> f32 {
        let mut hits: Vec<f32> = sphere_directions(64)
            .filter_map(|d| self.cast(eye, d).map(|(t, _)| t))
            .collect();
        hits.sort_by(f32::total_cmp);
        hits.get(hits.len() / 2).copied().unwrap_or(0.0)
    }

    /// Fraction of 64 rays from `eye` that meet a front side no nearer than `min_distance`: near
    /// 1 inside an enclosed room, low outside (rays escape) and inside solid furniture or walls
    /// (they meet back sides or are blocked at once).
    pub fn enclosure(&self, eye: Vec3, min_distance: f32) -> f32 {
        let n = 64;
        let front = sphere_directions(n)
            .filter(|&d| matches!(self.cast(eye, d), Some((t, true)) if t >= min_distance))
            .count();
        front as f32 / n as f32
    }
}

impl Scene {
    /// A camera inside the scene when it is an enclosed interior: of eyes spread over the bounds
    /// at standing heights, the one whose surroundings face it most ([`Probe::enclosure`], at
    /// least [`ENCLOSED`]; ties to the one with the most space around it), looking a little downwards along its
    /// longest view of a surface's front. `None` for an object or an open scene: no point sees mostly front faces
    /// (around an object, rays escape or meet its inside's back faces).
    pub fn interior_camera(&self) -> Option<Camera> {
        if self.instances.is_empty() {
            return None;
        }
        let probe = Probe::new(self);
        let (lo, hi) = self.bounds();
        let extent = hi - lo;
        // Clear of the nearest surface by a little: not inside a wall or a table.
        let clearance = self.size() * 0.01;
        // The most enclosed eye; of those equally enclosed, the one with the most space around
        // it (the largest typical distance to its surfaces): a room's middle, not a corner.
        let mut best: Option<((f32, f32), Vec3)> = None;
        let steps = [0.5, 0.3, 0.7, 0.1, 0.9];
        for (fx, fz) in steps.iter().flat_map(|&x| steps.map(|z| (x, z))) {
            for fy in [0.5, 0.35, 0.65] {
                let eye = lo + extent * Vec3::new(fx, fy, fz);
                let enclosure = probe.enclosure(eye, clearance);
                if enclosure < ENCLOSED {
                    continue;
                }
                let key = (enclosure, probe.typical_distance(eye));
                if best.is_none_or(|(k, _)| key > k) {
                    best = Some((key, eye));
                }
            }
        }
        let ((_, typical), eye) = best?;
        // A little downwards, along the farthest surface seen from its front (escaping rays count
        // as nothing, so an open side is not looked out of): the most of the room.
        let dir = (0..16)
            .map(|k| {
                let a = k as f32 / 16.0 * std::f32::consts::TAU;
                let d = Vec3::new(a.cos(), -0.15, a.sin()).normalize();
                let seen = probe.cast(eye, d).filter(|&(_, front)| front);
                (d, seen.map_or(0.0, |(t, _)| t))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))?
            .0;
        // The target at the room's typical distance, which [`Self::light_the_view`] lights.
        Some(Camera {
            eye,
            at: eye + dir * typical.max(clearance),
            up: Vec3::Y,
            fov_y_deg: 70.0,
        })
    }

    /// The camera to render with when none is given: the file's, else one inside an enclosed
    /// interior ([`Self::interior_camera`]), else one framing the scene from outside
    /// ([`Self::default_camera`]).
    pub fn view_camera(&self) -> Camera {
        self.camera
            .or_else(|| self.interior_camera())
            .unwrap_or_else(|| self.default_camera())
    }

    /// Lights what `camera` sees when the file has none: the default sun
    /// ([`Self::lights_or_default`]), which stays the shadow-mapped light, and a point light just
    /// above the camera (a headlight that reaches into an interior the sun cannot), bright
    /// enough to give an irradiance of 1 (a third of the sun's) at the point the camera looks
    /// at, the room's typical distance inside or the centre outside. A file's own lights are
    /// kept as they are.
    pub fn light_the_view(&mut self, camera: &Camera) {
        if !self.lights.is_empty() {
            return;
        }
        let mut lights = self.lights_or_default();
        let distance = (camera.at - camera.eye).length().max(self.size() * 0.05);
        lights.push(Light::Point {
            position: camera.eye + Vec3::Y * distance * 0.05,
            intensity: Vec3::splat(distance * distance),
            range: distance * 4.0,
        });
        self.lights = lights;
    }

    /// The view `ksrt render` and `ksrt view` show: `camera` when given, else
    /// [`Self::view_camera`]; and the scene lit for it ([`Self::light_the_view`]).
    pub fn prepare_view(&mut self, camera: Option<Camera>) -> Camera {
        let camera = camera.unwrap_or_else(|| self.view_camera());
        self.light_the_view(&camera);
        camera
    }
}
