//! Scenes: meshes in geometry space and the instances that place them, their materials,
//! textures and lights, plus an optional camera; the built-in scenes. (Reading scene files is the
//! application's: `ksrt` loads glTF 2.0 and OBJ files into these types.)
//!
//! Meshes and instances are kept apart on purpose: the SDK registers one geometry (one BLAS) per
//! [`Mesh`] and one instance per [`Instance`], so a glTF mesh used by several nodes is built once.

pub mod animation;
pub mod builtin;
pub mod character;
pub mod crowd;
pub mod cutout;
mod framing;
pub mod grove;
pub mod pose;
pub mod rig;
pub mod statue;
pub mod town;

use glam::{Affine3A, Vec3};

use animation::Animation;
use rig::{Deform, Node, Rig, Skin};

/// One triangle mesh in its own (geometry) space: what the SDK builds one BLAS from.
#[derive(Debug, Clone)]
pub struct Mesh {
    /// A name for logs (file mesh/material names where there are any).
    pub name: String,
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals, one per position: the file's, or area-weighted ones computed here.
    pub normals: Vec<[f32; 3]>,
    /// Triangle-list indices into `positions` (a multiple of 3, all in range).
    pub indices: Vec<u32>,
    /// Linear RGB base colour (glTF `baseColorFactor`, OBJ `Kd`).
    pub color: Vec3,
    /// Texture coordinates, one per position, or empty when the file has none (textures then
    /// read their texel at (0, 0)).
    pub uvs: Vec<[f32; 2]>,
    /// The rest of the surface description: metallic-roughness, emission, textures.
    pub material: Material,
    /// Joint influences and morph targets; empty for a rigid mesh. A mesh that deforms is
    /// posed through its [`Rig`]; `positions` are its rest (bind) pose.
    pub deform: Deform,
}

/// A metallic-roughness material (glTF 2.0's core model; OBJ/MTL maps onto it). Texture values
/// multiply the factors, as glTF specifies.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Index into [`Scene::textures`] of the sRGB base colour texture: RGB, and in A the alpha
    /// that [`AlphaMode::Mask`] tests (unused by the other modes).
    pub base_color_texture: Option<usize>,
    /// How the base colour's alpha is used (glTF `alphaMode`).
    pub alpha: AlphaMode,
    /// Metalness, 0..=1.
    pub metallic: f32,
    /// Perceptual roughness, 0..=1.
    pub roughness: f32,
    /// Index into [`Scene::textures`] of the linear metallic-roughness texture (glTF: roughness in
    /// G, metalness in B).
    pub metallic_roughness_texture: Option<usize>,
    /// Emitted radiance, linear RGB (glTF `emissiveFactor` × `emissive_strength`, OBJ `Ke`).
    pub emissive: Vec3,
    /// Index into [`Scene::textures`] of the sRGB emissive texture.
    pub emissive_texture: Option<usize>,
}

impl Default for Material {
    /// A rough dielectric: what a file without material data looks like best as.
    fn default() -> Self {
        Material {
            base_color_texture: None,
            alpha: AlphaMode::Opaque,
            metallic: 0.0,
            roughness: 0.6,
            metallic_roughness_texture: None,
            emissive: Vec3::ZERO,
            emissive_texture: None,
        }
    }
}

/// How a material's alpha is used: glTF 2.0's `alphaMode`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum AlphaMode {
    /// Alpha is ignored: the surface is opaque everywhere.
    #[default]
    Opaque,
    /// A cutout: opaque where `factor` × the base colour texture's alpha (the texel the
    /// coordinates fall in, mip 0, repeating; 1 without a texture) is at least `cutoff`, absent
    /// elsewhere, for the rasteriser, the SDK's traces and the CPU reference alike
    /// ([`cutout`]).
    Mask {
        /// glTF `baseColorFactor`'s alpha; finite and ≥ 0.
        factor: f32,
        /// glTF `alphaCutoff` (default 0.5); in 0..=1.
        cutoff: f32,
    },
    /// Blended transparency: `ksrt` has no transparency pass, so it rasterises and traces such
    /// a surface as [`AlphaMode::Opaque`] (the loader says so once per file).
    Blend,
}

/// A decoded texture: RGBA8 texels, row 0 at the top.
#[derive(Debug, Clone)]
pub struct Texture {
    /// A name for logs (the file or image index).
    pub name: String,
    /// The texels.
    pub image: image::RgbaImage,
    /// Magnified with nearest-texel sampling (glTF sampler `magFilter` NEAREST) rather than
    /// bilinear.
    pub nearest: bool,
}

/// A light of the rasteriser (and of the SDK's shadow task, for the sun). Radiometric values are
/// linear RGB; lengths in world units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// A directional light. `direction` is the way the light travels (unit); `irradiance` the
    /// illuminance on a surface facing it.
    Sun {
        /// Direction of travel (unit).
        direction: Vec3,
        /// Irradiance, linear RGB.
        irradiance: Vec3,
        /// Apparent angular diameter, radians (soft shadow size).
        angular_diameter: f32,
    },
    /// A point light with inverse-square falloff, windowed to zero at `range`.
    Point {
        /// Position.
        position: Vec3,
        /// Intensity (radiant intensity), linear RGB.
        intensity: Vec3,
        /// Distance at which it fades out.
        range: f32,
    },
    /// A spot light: a point light restricted to a cone, smoothly from `inner_angle` to
    /// `outer_angle` (half-angles, radians).
    Spot {
        /// Position.
        position: Vec3,
        /// Axis (unit), the way the light shines.
        direction: Vec3,
        /// Intensity on the axis, linear RGB.
        intensity: Vec3,
        /// Distance at which it fades out.
        range: f32,
        /// Full intensity inside this half-angle.
        inner_angle: f32,
        /// Zero outside this half-angle.
        outer_angle: f32,
    },
}

impl Mesh {
    /// A mesh with computed normals, checking that the indices are a triangle list in range.
    pub fn new(
        name: impl Into<String>,
        positions: Vec<[f32; 3]>,
        indices: Vec<u32>,
        color: Vec3,
    ) -> Result<Mesh, String> {
        let name = name.into();
        check_indices(&name, positions.len(), &indices)?;
        let normals = compute_normals(&positions, &indices);
        Ok(Mesh {
            name,
            positions,
            normals,
            indices,
            color,
            uvs: Vec::new(),
            material: Material::default(),
            deform: Deform::default(),
        })
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The triangles placed by `transform`.
    pub fn triangles(&self, transform: Affine3A) -> impl Iterator<Item = [Vec3; 3]> + '_ {
        self.indices.chunks_exact(3).map(move |t| {
            let p =
                |k: usize| transform.transform_point3(Vec3::from(self.positions[t[k] as usize]));
            [p(0), p(1), p(2)]
        })
    }
}

/// Checks that `indices` form a triangle list whose entries address `vertex_count` vertices.
/// The loaders call it because files can hold anything, and an out-of-range index would panic
/// later when the demo reads the mesh on the CPU.
pub fn check_indices(name: &str, vertex_count: usize, indices: &[u32]) -> Result<(), String> {
    if !indices.len().is_multiple_of(3) {
        return Err(format!(
            "mesh {name:?}: {} indices is not a multiple of 3",
            indices.len()
        ));
    }
    if let Some(i) = indices.iter().find(|&&i| i as usize >= vertex_count) {
        return Err(format!(
            "mesh {name:?}: index {i} is out of range ({vertex_count} vertices)"
        ));
    }
    Ok(())
}

/// `indices` without the triangles that use a vertex with a non-finite coordinate (NaN or ∞),
/// which no renderer can place; logs how many were dropped from mesh `name`. Requires indices
/// in range ([`check_indices`]).
pub fn drop_non_finite_triangles(
    name: &str,
    positions: &[[f32; 3]],
    indices: Vec<u32>,
) -> Vec<u32> {
    let finite = |i: &u32| positions[*i as usize].iter().all(|c| c.is_finite());
    if indices.iter().all(finite) {
        return indices;
    }
    let kept: Vec<u32> = indices
        .chunks_exact(3)
        .filter(|t| t.iter().all(finite))
        .flatten()
        .copied()
        .collect();
    log::warn!(
        "mesh {name:?}: {} of {} triangles use a vertex with a non-finite coordinate; dropped",
        (indices.len() - kept.len()) / 3,
        indices.len() / 3
    );
    kept
}

/// Area-weighted vertex normals: each triangle adds its unnormalised cross product (length =
/// twice its area) to its three vertices, so large faces dominate and slivers barely count.
/// Vertices no triangle uses (or whose triangles are all degenerate) get +Y, so every normal is
/// unit. Requires indices in range (see [`Mesh::new`]).
pub fn compute_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    let mut sum = vec![Vec3::ZERO; positions.len()];
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| Vec3::from(positions[i as usize]));
        let n = (b - a).cross(c - a);
        if !n.is_finite() {
            continue;
        }
        for &i in t {
            sum[i as usize] += n;
        }
    }
    sum.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Y).to_array())
        .collect()
}

/// One placement of a mesh in the world.
#[derive(Debug, Clone)]
pub struct Instance {
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// Object-to-world transform (glTF node hierarchy, composed).
    pub transform: Affine3A,
}

/// A pinhole camera, y up unless the file says otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: Vec3,
    /// Point looked at.
    pub at: Vec3,
    /// Up direction (need not be orthogonal to the view direction).
    pub up: Vec3,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
}

impl Camera {
    /// The orthonormal basis `(forward, right, up)` and `tan(fov/2)`, for generating rays.
    pub fn basis(&self) -> (Vec3, Vec3, Vec3, f32) {
        let fwd = (self.at - self.eye).normalize_or(Vec3::NEG_Z);
        // When up is parallel to the view direction, any perpendicular axis will do.
        let right = fwd
            .cross(self.up)
            .try_normalize()
            .unwrap_or_else(|| fwd.any_orthonormal_vector());
        let up = right.cross(fwd);
        (fwd, right, up, (self.fov_y_deg.to_radians() / 2.0).tan())
    }

    /// Direction (unit) of the primary ray through the centre of pixel `(x, y)` of a
    /// `width`×`height` image, row 0 at the top.
    pub fn primary_dir(&self, x: u32, y: u32, width: u32, height: u32) -> Vec3 {
        let (fwd, right, up, tan) = self.basis();
        let aspect = width as f32 / height as f32;
        let u = ((x as f32 + 0.5) / width as f32 * 2.0 - 1.0) * tan * aspect;
        let v = (1.0 - (y as f32 + 0.5) / height as f32 * 2.0) * tan;
        (fwd + right * u + up * v).normalize()
    }

    /// `world_to_view` and `view_to_clip` (right-handed, wgpu's 0..1 depth) for the SDK's
    /// `ViewInfo`; `near`/`far` in world units.
    pub fn matrices(&self, aspect: f32, near: f32, far: f32) -> (glam::Mat4, glam::Mat4) {
        let (fwd, _, up, _) = self.basis();
        (
            glam::Mat4::look_to_rh(self.eye, fwd, up),
            glam::Mat4::perspective_rh(self.fov_y_deg.to_radians(), aspect, near, far),
        )
    }
}

/// Parses `--camera eye_x,eye_y,eye_z,at_x,at_y,at_z,fov_deg` (y up).
pub fn parse_camera(s: &str) -> Result<Camera, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("--camera {s:?}: {:?} is not a finite number", p.trim()))
        })
        .collect::<Result<_, _>>()?;
    let [ex, ey, ez, ax, ay, az, fov] = v[..] else {
        return Err(format!(
            "--camera {s:?}: expected 7 numbers eye_x,eye_y,eye_z,at_x,at_y,at_z,fov_deg, got {}",
            v.len()
        ));
    };
    let (eye, at) = (Vec3::new(ex, ey, ez), Vec3::new(ax, ay, az));
    if eye == at {
        return Err(format!("--camera {s:?}: eye and target are the same point"));
    }
    if !(fov > 0.0 && fov < 180.0) {
        return Err(format!(
            "--camera {s:?}: fov {fov} must be in (0, 180) degrees"
        ));
    }
    Ok(Camera {
        eye,
        at,
        up: Vec3::Y,
        fov_y_deg: fov,
    })
}

/// A scene: meshes, their instances, and the file's camera if it has one.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// A name for output (the scene name or file stem).
    pub name: String,
    /// Geometries, each in its own space.
    pub meshes: Vec<Mesh>,
    /// Placements of the meshes.
    pub instances: Vec<Instance>,
    /// The file's camera, if any.
    pub camera: Option<Camera>,
    /// Decoded textures the materials index.
    pub textures: Vec<Texture>,
    /// The scene's lights (glTF `KHR_lights_punctual`, the built-in scenes'); empty:
    /// [`Scene::lights_or_default`] adds a sun, and [`Scene::light_the_view`] a light at the
    /// camera.
    pub lights: Vec<Light>,
    /// The node hierarchy skins and animations refer to (a file's nodes, in its order); empty
    /// for a scene without deformable meshes (instances carry their own transforms).
    pub nodes: Vec<Node>,
    /// The skins the rigs pose with.
    pub skins: Vec<Skin>,
    /// The deformable instances: skinned or morphing meshes, each posed every frame.
    pub rigs: Vec<Rig>,
    /// Keyframe animations; `ksrt` plays the first, looping ([`Scene::pose_at`]).
    pub animations: Vec<Animation>,
}

impl Scene {
    /// Triangles in the world (instanced meshes counted once per instance).
    pub fn triangle_count(&self) -> usize {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh].triangle_count())
            .sum()
    }

    /// World-space triangles of every instance, in instance order, with the instance index of
    /// each: what the CPU reference and the benchmark's CPU work need.
    pub fn world_triangles(&self) -> (Vec<[Vec3; 3]>, Vec<u32>) {
        let mut tris = Vec::with_capacity(self.triangle_count());
        let mut owner = Vec::with_capacity(self.triangle_count());
        for (k, inst) in self.instances.iter().enumerate() {
            for t in self.meshes[inst.mesh].triangles(inst.transform) {
                tris.push(t);
                owner.push(k as u32);
            }
        }
        (tris, owner)
    }

    /// The whole scene as one mesh in world space under one identity instance (instanced
    /// meshes repeated): what a renderer that bakes its scene into a single BVH traces, for
    /// `ksrt bench --flatten`. Materials and textures are dropped; lights and camera are kept.
    pub fn flattened(&self) -> Result<Scene, String> {
        // Checked once for the whole scene, so no vertex index below can overflow.
        let vertices: usize = self
            .instances
            .iter()
            .map(|inst| self.meshes[inst.mesh].positions.len())
            .sum();
        u32::try_from(vertices)
            .map_err(|_| format!("{}: too many vertices to flatten", self.name))?;
        let mut positions = Vec::with_capacity(vertices);
        let mut indices = Vec::with_capacity(self.triangle_count() * 3);
        for inst in &self.instances {
            let m = &self.meshes[inst.mesh];
            let base = positions.len() as u32;
            positions.extend(
                m.positions
                    .iter()
                    .map(|p| inst.transform.transform_point3(Vec3::from(*p)).to_array()),
            );
            indices.extend(m.indices.iter().map(|i| base + i));
        }
        let color = self.meshes.first().map_or(Vec3::splat(0.8), |m| m.color);
        let mesh = Mesh::new(
            format!("{} (flattened)", self.name),
            positions,
            indices,
            color,
        )?;
        Ok(Scene {
            name: self.name.clone(),
            meshes: vec![mesh],
            instances: vec![Instance {
                mesh: 0,
                transform: Affine3A::IDENTITY,
            }],
            camera: self.camera,
            lights: self.lights.clone(),
            ..Default::default()
        })
    }

    /// World-space bounds `(min, max)` of the finite vertices of every instance; a unit box at the
    /// origin when there are none (so cameras and offsets derived from it stay finite).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for inst in &self.instances {
            let m = &self.meshes[inst.mesh];
            for p in &m.positions {
                let w = inst.transform.transform_point3(Vec3::from(*p));
                if w.is_finite() {
                    lo = lo.min(w);
                    hi = hi.max(w);
                }
            }
        }
        if lo.x > hi.x {
            (Vec3::splat(-0.5), Vec3::splat(0.5))
        } else {
            (lo, hi)
        }
    }

    /// Length of the bounds' diagonal: the scene's size for offsets and clip planes.
    pub fn size(&self) -> f32 {
        let (lo, hi) = self.bounds();
        (hi - lo).length().max(f32::MIN_POSITIVE)
    }

    /// A camera that frames the whole scene from outside: looking at the centre of the bounds
    /// from the front (+Z) and above, far enough that the bounding sphere fits the 50° vertical field of view.
    pub fn default_camera(&self) -> Camera {
        let (lo, hi) = self.bounds();
        let centre = (lo + hi) * 0.5;
        let radius = (hi - lo).length() * 0.5;
        let fov_y_deg = 50.0f32;
        let distance = radius / (fov_y_deg.to_radians() / 2.0).sin() * 1.05;
        let dir = Vec3::new(0.0, 0.5, 1.0).normalize();
        Camera {
            eye: centre + dir * distance.max(1e-3),
            at: centre,
            up: Vec3::Y,
            fov_y_deg,
        }
    }

    /// The lights to render with: the scene's, or, when it has none (every file of the shared
    /// scenes), a white sun from above and slightly behind the default camera's right, so that
    /// shadows fall visibly onto the floor towards the viewer.
    pub fn lights_or_default(&self) -> Vec<Light> {
        if !self.lights.is_empty() {
            return self.lights.clone();
        }
        vec![Light::Sun {
            direction: Vec3::new(-0.4, -1.0, -0.3).normalize(),
            irradiance: Vec3::splat(3.0),
            angular_diameter: 0.0093,
        }]
    }

    /// The camera to render with: `override_camera`, else the file's, else one inside an
    /// enclosed interior, else one framing the scene from outside ([`Self::view_camera`]).
    pub fn camera_or_default(&self, override_camera: Option<Camera>) -> Camera {
        override_camera.unwrap_or_else(|| self.view_camera())
    }
}

/// The camera the benchmarks and the tests view a scene from, for the scenes that have one
/// (eye, target, vertical field of view): the dragon and the statue from the front, the
/// apartment from inside its living room.
pub fn benchmark_camera(scene: &str) -> Option<Camera> {
    let c = match scene {
        "dragon" => "-0.006,0.125,0.32,-0.006,0.125,-0.005,30",
        "statue" => "0.0,0.125,0.62,0.0,0.125,0.0,30",
        "apartment" => "9.2,1.6,-7.3,9.2,1.0,-3.0,75",
        _ => return None,
    };
    parse_camera(c).ok()
}
