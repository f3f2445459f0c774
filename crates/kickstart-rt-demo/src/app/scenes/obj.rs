//! OBJ/MTL loading through `tobj`: faces triangulated, one mesh per OBJ object/group (one
//! identity instance each), the material's diffuse colour `Kd` as the base colour.

use std::path::Path;

use glam::{Affine3A, Vec3};

use kickstart_rt_renderer::scene::{
    check_indices, compute_normals, drop_non_finite_triangles, Instance, Material, Mesh, Scene,
    Texture,
};

use super::SceneError;

/// Colour of meshes without a material (or whose MTL file is missing): a light grey, so they
/// still show shading in the images.
const DEFAULT_COLOR: Vec3 = Vec3::splat(0.8);

/// Loads an `.obj` file and its `.mtl` libraries.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    // tobj reports a missing file only as "OpenFileFailed"; check first to say which and why.
    std::fs::metadata(path).map_err(|e| SceneError::new(path, format!("cannot read: {e}")))?;
    let options = tobj::LoadOptions {
        triangulate: true,
        // One index for position and normal, so file normals (when there are any) line up with
        // positions the way the SDK and the demo's meshes expect.
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // tobj is third-party code fed arbitrary files: a panic inside it becomes an error too.
    let (models, materials) = super::guard::guarded(|| tobj::load_obj(path, &options))
        .map_err(|panic| {
            SceneError::new(
                path,
                format!("the OBJ reader failed on malformed data ({panic})"),
            )
        })?
        .map_err(|e| SceneError::new(path, format!("not a valid OBJ file: {e}")))?;
    let materials = materials.unwrap_or_else(|e| {
        log::warn!(
            "{}: material library not loaded ({e}); using a grey base colour",
            path.display()
        );
        Vec::new()
    });
    let mut scene = Scene::default();
    let mut textures = std::collections::HashMap::new();
    for model in models {
        let m = model.mesh;
        if m.indices.is_empty() {
            continue;
        }
        let positions: Vec<[f32; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        check_indices(&model.name, positions.len(), &m.indices)
            .map_err(|e| SceneError::new(path, e))?;
        let indices = drop_non_finite_triangles(&model.name, &positions, m.indices);
        let normals = if m.normals.len() == m.positions.len() {
            m.normals
                .chunks_exact(3)
                .map(|n| [n[0], n[1], n[2]])
                .collect()
        } else {
            compute_normals(&positions, &indices)
        };
        let mtl = m.material_id.and_then(|i| materials.get(i));
        let color = mtl
            .and_then(|mat| mat.diffuse)
            .map_or(DEFAULT_COLOR, Vec3::from);
        let mut material = mtl.map_or_else(Material::default, material_of);
        if let Some(file) = mtl.and_then(|m| m.diffuse_texture.as_deref()) {
            material.base_color_texture = Some(texture(path, file, &mut scene, &mut textures)?);
        }
        let uvs = if m.texcoords.len() / 2 == positions.len() {
            // OBJ's v runs up, textures' rows run down.
            m.texcoords
                .chunks_exact(2)
                .map(|t| [t[0], 1.0 - t[1]])
                .collect()
        } else {
            Vec::new()
        };
        scene.instances.push(Instance {
            mesh: scene.meshes.len(),
            transform: Affine3A::IDENTITY,
        });
        scene.meshes.push(Mesh {
            name: model.name,
            positions,
            normals,
            indices,
            color,
            uvs,
            material,
            deform: Default::default(),
        });
    }
    Ok(scene)
}

/// The metallic-roughness reading of an MTL material: `Ke` is the emission; the Phong exponent
/// `Ns` becomes a roughness through the usual Blinn-Phong ↔ GGX match (α² = 2 / (Ns + 2), α =
/// roughness²); `Pm`/`Pr` (the PBR extension of MTL) win where present. Textures: `map_Kd`
/// (the base colour, loaded by [`load`]).
fn material_of(mtl: &tobj::Material) -> Material {
    let param = |k: &str| {
        mtl.unknown_param
            .get(k)
            .and_then(|v| v.trim().parse::<f32>().ok())
            .filter(|v| v.is_finite())
    };
    let roughness = param("Pr").unwrap_or_else(|| {
        mtl.shininess
            .filter(|ns| ns.is_finite() && *ns >= 0.0)
            .map_or(Material::default().roughness, |ns| {
                (2.0 / (ns + 2.0)).sqrt().sqrt()
            })
    });
    let emissive = mtl.emissive.map_or(Vec3::ZERO, Vec3::from);
    Material {
        metallic: param("Pm").unwrap_or(0.0).clamp(0.0, 1.0),
        roughness: roughness.clamp(0.0, 1.0),
        emissive: emissive.max(Vec3::ZERO),
        ..Material::default()
    }
}

/// The scene texture of the MTL map `file` (relative to the OBJ's folder), decoded once.
fn texture(
    obj: &Path,
    file: &str,
    scene: &mut Scene,
    decoded: &mut std::collections::HashMap<String, usize>,
) -> Result<usize, SceneError> {
    if let Some(&k) = decoded.get(file) {
        return Ok(k);
    }
    let full = obj.parent().unwrap_or_else(|| Path::new(".")).join(file);
    let err = |e: String| SceneError::new(obj, format!("base colour texture {file}: {e}"));
    let bytes =
        std::fs::read(&full).map_err(|e| err(format!("cannot read {}: {e}", full.display())))?;
    let image = super::texture::decode_rgba8(&bytes).map_err(err)?;
    scene.textures.push(Texture {
        name: file.to_string(),
        image,
        nearest: false,
    });
    decoded.insert(file.to_string(), scene.textures.len() - 1);
    Ok(scene.textures.len() - 1)
}
