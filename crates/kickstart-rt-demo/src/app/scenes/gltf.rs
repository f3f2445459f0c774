//! glTF 2.0 (`.gltf` + buffers, `.glb`) loading: the default scene's node hierarchy, every
//! triangle primitive as a mesh, one instance per node that uses it, materials (factors,
//! textures, alpha mode: `MASK` cutouts), the first perspective camera, and the
//! `KHR_lights_punctual` lights; skins, morph targets and animations ([`gltf_skin`],
//! [`gltf_anim`]) for the meshes they deform.

use std::collections::HashMap;
use std::path::Path;

use glam::{Affine3A, Mat4, Vec3};
use gltf::mesh::Mode;

use kickstart_rt_renderer::scene::{
    check_indices, compute_normals, drop_non_finite_triangles, AlphaMode, Camera, Instance, Light,
    Material, Mesh, Scene, Texture,
};

use kickstart_rt_renderer::scene::rig::Rig;

use super::gltf_accessor::check_accessor;
use super::SceneError;
use super::{gltf_alpha, gltf_anim, gltf_skin};

/// Loads a `.gltf` or `.glb` file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let bytes =
        std::fs::read(path).map_err(|e| SceneError::new(path, format!("cannot read: {e}")))?;
    load_from_bytes(path, &bytes)
}

/// Loads a glTF from its bytes (`path` names it in errors and locates external buffers).
/// The gltf crate validates the JSON and reads accessors through bounds-checked slices, and
/// [`check_accessor`] checks every accessor this loader reads before it is read; but the crate
/// is third-party code fed arbitrary files (its validator indexes arrays a damaged file leaves
/// empty): a panic inside it must still become an error that names the file rather than abort
/// `ksrt`.
pub(super) fn load_from_bytes(path: &Path, bytes: &[u8]) -> Result<Scene, SceneError> {
    super::guard::guarded(|| load_bytes(path, bytes)).unwrap_or_else(|panic| {
        Err(SceneError::new(
            path,
            format!("the glTF reader failed on malformed data ({panic})"),
        ))
    })
}

fn load_bytes(path: &Path, bytes: &[u8]) -> Result<Scene, SceneError> {
    let err = |what: String| SceneError::new(path, what);
    let invalid = |e: gltf::Error| err(format!("not a valid glTF 2.0 file: {e}"));
    let raw = gltf::Gltf::from_slice_without_validation(bytes).map_err(invalid)?;
    let json = raw.document.into_json();
    check_attribute_accessors(&json).map_err(err)?;
    let file = gltf::Gltf {
        document: gltf::Document::from_json(json).map_err(invalid)?,
        blob: raw.blob,
    };
    let buffers = file
        .buffers()
        .map(|b| load_buffer(path, &b, file.blob.as_deref()))
        .collect::<Result<Vec<_>, _>>()?;

    let mut load = Load {
        path,
        buffers: &buffers,
        scene: Scene::default(),
        textures: TextureCache::default(),
        converted: HashMap::new(),
        skipped: 0,
    };
    let roots = root_nodes(&file);
    let mut visited = vec![false; file.nodes().len()];
    let mut stack: Vec<(gltf::Node, Affine3A)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, Affine3A::IDENTITY))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        // A valid hierarchy is a forest: a node seen twice means a cycle or two parents, which
        // would otherwise loop forever.
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(err(format!(
                "node {} appears twice in the hierarchy (a cycle or two parents)",
                node.index()
            )));
        }
        let local = Affine3A::from_mat4(Mat4::from_cols_array_2d(&node.transform().matrix()));
        let world = parent * local;
        if !world.is_finite() {
            return Err(err(format!(
                "node {} has a non-finite transform",
                node.index()
            )));
        }
        if let Some(mesh) = node.mesh() {
            load.add_mesh_node(&node, &mesh, world)?;
        }
        let scene = &mut load.scene;
        if scene.camera.is_none() {
            if let Some(cam) = node.camera() {
                match cam.projection() {
                    gltf::camera::Projection::Perspective(p) => {
                        scene.camera = Some(perspective_camera(&cam, &p, world).map_err(err)?);
                    }
                    gltf::camera::Projection::Orthographic(_) => log::warn!(
                        "{}: orthographic camera of node {} ignored",
                        path.display(),
                        node.index()
                    ),
                }
            }
        }
        if let Some(light) = node.light() {
            scene
                .lights
                .push(punctual_light(&light, world).map_err(err)?);
        }
        for child in node.children().collect::<Vec<_>>().into_iter().rev() {
            stack.push((child, world));
        }
    }
    let Load {
        mut scene,
        textures,
        skipped,
        ..
    } = load;
    bound_light_ranges(&mut scene);
    textures.log_blended(path);
    if scene.instances.is_empty() && skipped > 0 {
        return Err(err(format!(
            "no triangles to render: all {skipped} primitive(s) the scene uses are points or lines (or lack positions)"
        )));
    }
    read_rigs(&file, &buffers, &mut scene).map_err(err)?;
    Ok(scene)
}

/// The node hierarchy, skins and animations of the file into `scene`, kept only where a rig
/// (a skinned or morphing mesh) uses them, then every rig checked against its mesh and skin.
fn read_rigs(file: &gltf::Document, buffers: &[Vec<u8>], scene: &mut Scene) -> Result<(), String> {
    if scene.rigs.is_empty() {
        return Ok(());
    }
    scene.nodes = gltf_skin::read_nodes(file)?;
    scene.skins = gltf_skin::read_skins(file, buffers)?;
    scene.animations = gltf_anim::read_animations(file, buffers)?;
    scene.check_rigs()
}

/// A glTF being loaded: the scene so far and what its meshes share.
struct Load<'a> {
    path: &'a Path,
    buffers: &'a [Vec<u8>],
    scene: Scene,
    textures: TextureCache,
    /// glTF mesh index → the scene meshes of its triangle primitives, converted on first use
    /// so meshes no node references cost nothing (rigid meshes only: a deformed one is posed
    /// per node, so each node gets its own copy).
    converted: HashMap<usize, Vec<usize>>,
    /// Primitives without triangles.
    skipped: usize,
}

impl Load<'_> {
    /// The instances of glTF mesh `mesh` on `node`, placed at `world`: a rigid mesh's shared
    /// scene meshes, or, for a node with a skin or a mesh with morph targets, a copy of each
    /// primitive with its deformation and a rig that poses it.
    fn add_mesh_node(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        world: Affine3A,
    ) -> Result<(), SceneError> {
        let path = self.path;
        let err = |what: String| SceneError::new(path, what);
        let morphs = mesh.primitives().any(|p| p.morph_targets().len() > 0);
        let skin = node.skin().map(|s| s.index());
        if skin.is_none() && !morphs {
            let ids = match self.converted.get(&mesh.index()) {
                Some(ids) => ids.clone(),
                None => {
                    let ids = self.convert_mesh(mesh, None)?;
                    self.converted.insert(mesh.index(), ids.clone());
                    ids
                }
            };
            self.scene
                .instances
                .extend(ids.into_iter().map(|mesh| Instance {
                    mesh,
                    transform: world,
                }));
            return Ok(());
        }
        // The pose is computed in the mesh's space through the inverse of this transform.
        if world.matrix3.determinant().abs() < f32::MIN_POSITIVE {
            return Err(err(format!(
                "node {}: the transform of a skinned or morphing mesh is singular",
                node.index()
            )));
        }
        for id in self.convert_mesh(mesh, Some(skin.is_some()))? {
            self.scene.instances.push(Instance {
                mesh: id,
                transform: world,
            });
            self.scene.rigs.push(Rig {
                instance: self.scene.instances.len() - 1,
                node: node.index(),
                skin,
            });
        }
        Ok(())
    }

    /// Converts the triangle primitives of `mesh` into scene meshes with their materials;
    /// `deform: Some(skinned)` reads their deformation too. Returns their indices.
    fn convert_mesh(
        &mut self,
        mesh: &gltf::Mesh,
        deform: Option<bool>,
    ) -> Result<Vec<usize>, SceneError> {
        let path = self.path;
        let err = |what: String| SceneError::new(path, what);
        let mut ids = Vec::new();
        for prim in mesh.primitives() {
            let Some(mut m) = convert_primitive(mesh, &prim, self.buffers).map_err(err)? else {
                self.skipped += 1;
                continue;
            };
            if let Some(skinned) = deform {
                m.deform = gltf_skin::read_deform(&m.name, mesh, &prim, self.buffers, skinned)
                    .map_err(err)?;
            }
            m.material = self.textures.material(
                self.path,
                &prim.material(),
                self.buffers,
                &mut self.scene,
            )?;
            ids.push(self.scene.meshes.len());
            self.scene.meshes.push(m);
        }
        Ok(ids)
    }
}

/// The nodes the hierarchy starts from: the default scene's (else the first scene's), or, in a
/// file without scenes, every node that is nobody's child.
fn root_nodes(file: &gltf::Gltf) -> Vec<gltf::Node<'_>> {
    match file.default_scene().or_else(|| file.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => {
            let children: std::collections::HashSet<usize> = file
                .nodes()
                .flat_map(|n| n.children().map(|c| c.index()).collect::<Vec<_>>())
                .collect();
            file.nodes()
                .filter(|n| !children.contains(&n.index()))
                .collect()
        }
    }
}

/// The scene camera of a glTF perspective camera placed by its node's `world` transform (it
/// looks down its local −Z with +Y up), or what is wrong with it: a `yfov` outside (0, π), or
/// a transform that flattens the view or up direction to nothing or makes them parallel.
fn perspective_camera(
    cam: &gltf::Camera,
    p: &gltf::camera::Perspective,
    world: Affine3A,
) -> Result<Camera, String> {
    let yfov = p.yfov();
    if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
        return Err(format!(
            "camera {}: yfov {yfov} must be in (0, π) radians",
            cam.index()
        ));
    }
    let eye = world.transform_point3(Vec3::ZERO);
    let at = eye + world.transform_vector3(Vec3::NEG_Z);
    let up = world.transform_vector3(Vec3::Y);
    // The direction as stored (`at − eye`): far out, a unit step vanishes in the rounding.
    let side = (at - eye).normalize_or_zero().cross(up.normalize_or_zero());
    if !at.is_finite() || side.length_squared() < 1e-12 {
        return Err(format!(
            "camera {}: its node's transform leaves no view direction and up (singular, or \
             too far out for a unit step to register)",
            cam.index()
        ));
    }
    Ok(Camera {
        eye,
        at,
        up,
        fov_y_deg: yfov.to_degrees(),
    })
}

/// Refuses a primitive attribute naming an accessor the file lacks, by its place in the file.
/// The gltf crate's validator reads a primitive's POSITION accessor by index before checking
/// that it exists: without this, such a file ends in a panic inside the crate.
fn check_attribute_accessors(root: &gltf::json::Root) -> Result<(), String> {
    let accessors = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &primitive.attributes {
                if index.value() >= accessors {
                    let name = match semantic {
                        gltf::json::validation::Checked::Valid(s) => s.to_string(),
                        gltf::json::validation::Checked::Invalid => "?".to_string(),
                    };
                    return Err(format!(
                        "meshes[{m}].primitives[{p}].attributes.{name}: accessor {} does not \
                         exist (the file has {accessors})",
                        index.value()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The scene textures made from the file's images, each decoded once however many materials use
/// it, and the `BLEND` materials met on the way.
#[derive(Default)]
struct TextureCache {
    /// glTF image index → index in `Scene::textures`.
    decoded: HashMap<usize, usize>,
    /// Names of the `BLEND` materials the scene uses, for one log line.
    blended: std::collections::BTreeSet<String>,
}

impl TextureCache {
    /// Says once for the file that its `BLEND` materials are drawn opaque (`ksrt` has no
    /// transparency pass), naming them.
    fn log_blended(&self, path: &Path) {
        if self.blended.is_empty() {
            return;
        }
        let names: Vec<&str> = self.blended.iter().map(String::as_str).collect();
        log::warn!(
            "{}: alphaMode BLEND is rasterised and traced as opaque ({} material(s): {})",
            path.display(),
            names.len(),
            names.join(", ")
        );
    }

    /// The metallic-roughness material of a glTF material, decoding the textures it references.
    fn material(
        &mut self,
        path: &Path,
        m: &gltf::Material,
        buffers: &[Vec<u8>],
        scene: &mut Scene,
    ) -> Result<Material, SceneError> {
        let pbr = m.pbr_metallic_roughness();
        let mut texture = |info: Option<gltf::texture::Info>, what: &str| {
            info.map(|i| self.texture(path, &i.texture(), buffers, scene, what))
                .transpose()
        };
        let base_color_texture = texture(pbr.base_color_texture(), "base colour")?;
        let metallic_roughness_texture =
            texture(pbr.metallic_roughness_texture(), "metallic-roughness")?;
        let emissive_texture = texture(m.emissive_texture(), "emissive")?;
        let alpha = gltf_alpha::alpha_mode(m).map_err(|e| SceneError::new(path, e))?;
        if alpha == AlphaMode::Blend {
            self.blended.insert(gltf_alpha::material_name(m));
        }
        Ok(Material {
            base_color_texture,
            alpha,
            metallic: pbr.metallic_factor().clamp(0.0, 1.0),
            roughness: pbr.roughness_factor().clamp(0.0, 1.0),
            metallic_roughness_texture,
            emissive: Vec3::from(m.emissive_factor()).max(Vec3::ZERO),
            emissive_texture,
        })
    }

    /// Decodes the image of `texture` (PNG or JPEG: from a buffer view, a data URI or a file
    /// next to the glTF) into `scene.textures` and returns its index.
    fn texture(
        &mut self,
        path: &Path,
        texture: &gltf::Texture,
        buffers: &[Vec<u8>],
        scene: &mut Scene,
        what: &str,
    ) -> Result<usize, SceneError> {
        let img = texture.source();
        if let Some(&k) = self.decoded.get(&img.index()) {
            return Ok(k);
        }
        let name = img
            .name()
            .map_or_else(|| format!("image {}", img.index()), str::to_string);
        let err = |e: String| SceneError::new(path, format!("{what} texture {name}: {e}"));
        let bytes: Vec<u8> = match img.source() {
            gltf::image::Source::View { view, .. } => {
                let buf = buffers
                    .get(view.buffer().index())
                    .ok_or_else(|| err("its buffer is missing".into()))?;
                let end = view.offset().checked_add(view.length());
                end.and_then(|end| buf.get(view.offset()..end))
                    .ok_or_else(|| {
                        err(format!(
                            "its buffer view {} ({} bytes at offset {}) is out of its buffer of {} bytes",
                            view.index(),
                            view.length(),
                            view.offset(),
                            buf.len()
                        ))
                    })?
                    .to_vec()
            }
            gltf::image::Source::Uri { uri, .. } if uri.starts_with("data:") => uri
                .split_once(";base64,")
                .and_then(|(_, p)| decode_base64(p))
                .ok_or_else(|| err("invalid data URI (only base64 is supported)".into()))?,
            gltf::image::Source::Uri { uri, .. } => {
                let file = path
                    .parent()
                    .unwrap_or_else(|| Path::new("."))
                    .join(percent_decode(uri));
                std::fs::read(&file)
                    .map_err(|e| err(format!("cannot read {}: {e}", file.display())))?
            }
        };
        let decoded = super::texture::decode_rgba8(&bytes).map_err(err)?;
        let k = scene.textures.len();
        scene.textures.push(Texture {
            name,
            image: decoded,
            nearest: texture.sampler().mag_filter() == Some(gltf::texture::MagFilter::Nearest),
        });
        self.decoded.insert(img.index(), k);
        Ok(k)
    }
}

/// The bytes of one buffer: the GLB binary chunk, a file next to the `.gltf`, or a base64
/// `data:` URI.
fn load_buffer(path: &Path, b: &gltf::Buffer, blob: Option<&[u8]>) -> Result<Vec<u8>, SceneError> {
    let data = match b.source() {
        gltf::buffer::Source::Bin => blob
            .ok_or_else(|| {
                SceneError::new(
                    path,
                    format!("buffer {} refers to a missing GLB binary chunk", b.index()),
                )
            })?
            .to_vec(),
        gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
            let payload = uri.split_once(";base64,").map(|(_, p)| p).ok_or_else(|| {
                SceneError::new(
                    path,
                    format!("buffer {}: only base64 data URIs are supported", b.index()),
                )
            })?;
            decode_base64(payload).ok_or_else(|| {
                SceneError::new(
                    path,
                    format!("buffer {}: invalid base64 data URI", b.index()),
                )
            })?
        }
        gltf::buffer::Source::Uri(uri) => {
            let file = path
                .parent()
                .unwrap_or_else(|| Path::new("."))
                .join(percent_decode(uri));
            std::fs::read(&file).map_err(|e| {
                SceneError::new(
                    &file,
                    format!(
                        "buffer {} of {}: cannot read: {e}",
                        b.index(),
                        path.display()
                    ),
                )
            })?
        }
    };
    if data.len() < b.length() {
        return Err(SceneError::new(
            path,
            format!(
                "buffer {} has {} bytes, the file declares {}",
                b.index(),
                data.len(),
                b.length()
            ),
        ));
    }
    Ok(data)
}

/// Relative URIs in glTF are percent-encoded (a space is `%20`).
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Standard base64 (RFC 4648, padding optional); `None` on any other character.
pub(super) fn decode_base64(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    for c in s.bytes().filter(|&c| c != b'=') {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Some(out)
}

/// One primitive as a triangle-list mesh, or `None` (with a warning) for modes that have no
/// triangles. Strips and fans are converted to lists.
fn convert_primitive(
    mesh: &gltf::Mesh,
    prim: &gltf::Primitive,
    buffers: &[Vec<u8>],
) -> Result<Option<Mesh>, String> {
    let name = format!(
        "{}#{}",
        mesh.name()
            .map_or_else(|| format!("mesh {}", mesh.index()), str::to_string),
        prim.index()
    );
    let mode = prim.mode();
    if matches!(
        mode,
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
    ) {
        log::warn!("{name}: primitive mode {mode:?} has no triangles; skipped");
        return Ok(None);
    }
    // The reader assumes each accessor has the type the specification gives its semantic (an
    // index accessor of floats reaches an `unreachable!`, a position accessor of bytes is
    // misread): check before reading.
    use gltf::accessor::{DataType, Dimensions};
    let typed = |a: &gltf::Accessor, types: &[DataType], dims: Dimensions| {
        if types.contains(&a.data_type()) && a.dimensions() == dims {
            Ok(())
        } else {
            Err(format!(
                "{name}: accessor {} holds {:?} {:?}, expected {types:?} {dims:?}",
                a.index(),
                a.data_type(),
                a.dimensions()
            ))
        }
    };
    for (semantic, accessor) in prim.attributes() {
        match semantic {
            gltf::Semantic::Positions | gltf::Semantic::Normals => {
                typed(&accessor, &[DataType::F32], Dimensions::Vec3)?
            }
            gltf::Semantic::TexCoords(_) => typed(
                &accessor,
                &[DataType::F32, DataType::U8, DataType::U16],
                Dimensions::Vec2,
            )?,
            _ => {}
        }
        check_accessor(&accessor, buffers)
            .map_err(|e| format!("{name}: attribute {semantic:?}: {e}"))?;
    }
    if let Some(accessor) = prim.indices() {
        typed(
            &accessor,
            &[DataType::U8, DataType::U16, DataType::U32],
            Dimensions::Scalar,
        )?;
        check_accessor(&accessor, buffers).map_err(|e| format!("{name}: indices: {e}"))?;
    }
    let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let Some(positions) = reader.read_positions() else {
        log::warn!("{name}: no readable POSITION attribute; skipped");
        return Ok(None);
    };
    let positions: Vec<[f32; 3]> = positions.collect();
    let raw: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None if prim.indices().is_some() => {
            return Err(format!(
                "{name}: the index accessor's data is out of its buffer"
            ))
        }
        None => (0..positions.len() as u32).collect(),
    };
    let indices = match mode {
        Mode::TriangleStrip => strip_to_list(&raw),
        Mode::TriangleFan => fan_to_list(&raw),
        _ => raw,
    };
    check_indices(&name, positions.len(), &indices)?;
    let indices = drop_non_finite_triangles(&name, &positions, indices);
    let normals = match reader.read_normals() {
        Some(n) => {
            let n: Vec<[f32; 3]> = n.collect();
            if n.len() == positions.len() {
                n
            } else {
                compute_normals(&positions, &indices)
            }
        }
        None => compute_normals(&positions, &indices),
    };
    let [r, g, b, _] = prim.material().pbr_metallic_roughness().base_color_factor();
    let uvs = read_uvs(&reader, &prim.material(), positions.len());
    Ok(Some(Mesh {
        name: prim
            .material()
            .name()
            .map_or(name.clone(), |m| format!("{name} ({m})")),
        positions,
        normals,
        indices,
        color: Vec3::new(r, g, b),
        uvs,
        material: Material::default(),
        deform: Default::default(),
    }))
}

/// The texture coordinates of a primitive of `material`, one per vertex (`vertices`), or none.
/// Every texture of a material uses one coordinate set here: the one its base colour texture
/// names (`texCoord`, or `KHR_texture_transform`'s override), with that texture's transform
/// applied, since the base colour's alpha is what a cutout tests.
fn read_uvs<'a, 's, F>(
    reader: &gltf::mesh::Reader<'a, 's, F>,
    material: &gltf::Material,
    vertices: usize,
) -> Vec<[f32; 2]>
where
    F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    let (set, transform) = gltf_alpha::base_color_coordinates(material);
    let uvs: Vec<[f32; 2]> = reader
        .read_tex_coords(set)
        .map(|t| t.into_f32().collect())
        .filter(|t: &Vec<[f32; 2]>| t.len() == vertices)
        .unwrap_or_default();
    match transform {
        Some(t) => uvs.into_iter().map(|uv| t.apply(uv)).collect(),
        None => uvs,
    }
}

/// Triangle `k` of a strip is `(k, k+1, k+2)`, with every odd one's first two vertices swapped so
/// that all keep the strip's winding.
fn strip_to_list(s: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(s.len().saturating_sub(2) * 3);
    for k in 0..s.len().saturating_sub(2) {
        if k % 2 == 0 {
            out.extend([s[k], s[k + 1], s[k + 2]]);
        } else {
            out.extend([s[k + 1], s[k], s[k + 2]]);
        }
    }
    out
}

/// Triangle `k` of a fan is `(k+1, k+2, 0)` (the glTF 2.0 specification's order).
fn fan_to_list(s: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(s.len().saturating_sub(2) * 3);
    for k in 0..s.len().saturating_sub(2) {
        out.extend([s[k + 1], s[k + 2], s[0]]);
    }
    out
}

/// Gives every point and spot light without a range (glTF: infinite) one: twice the scene's size,
/// past which the windowed falloff has nothing left to light.
fn bound_light_ranges(scene: &mut Scene) {
    // At least 1 (a scene of lights alone has size 0) and finite (a scene reaching ±3e38 has
    // an infinite size): the renderer windows the falloff by the range.
    let reach = scene.size() * 2.0;
    let reach = if reach.is_finite() {
        reach.max(1.0)
    } else {
        1.0e18
    };
    for light in &mut scene.lights {
        if let Light::Point { range, .. } | Light::Spot { range, .. } = light {
            if !range.is_finite() || *range <= 0.0 {
                *range = reach;
            }
        }
    }
}

/// A `KHR_lights_punctual` light placed by its node's `world` transform (it shines along its
/// local −Z). glTF's photometric units (lux, candela) are taken as the rasteriser's irradiance
/// and radiant intensity at exposure 1, so a file lit for a physically based viewer looks about
/// as bright here. Refused, with the reason: a colour or intensity that is negative or not
/// finite, a range not above 0, or spot cone angles outside 0 ≤ inner < outer ≤ π/2 (the
/// extension's own rules).
fn punctual_light(
    light: &gltf::khr_lights_punctual::Light,
    world: Affine3A,
) -> Result<Light, String> {
    use gltf::khr_lights_punctual::Kind;
    let name = || format!("light {}", light.index());
    let colour = Vec3::from(light.color()) * light.intensity();
    if !colour.is_finite() || colour.min_element() < 0.0 {
        return Err(format!(
            "{}: colour {:?} × intensity {} must be finite and ≥ 0",
            name(),
            light.color(),
            light.intensity()
        ));
    }
    let range = light.range().unwrap_or(f32::INFINITY);
    if range.is_nan() || range <= 0.0 {
        return Err(format!("{}: range {range} must be > 0", name()));
    }
    let position = world.transform_point3(Vec3::ZERO);
    let direction = world
        .transform_vector3(Vec3::NEG_Z)
        .normalize_or(Vec3::NEG_Y);
    Ok(match light.kind() {
        Kind::Directional => Light::Sun {
            direction,
            irradiance: colour,
            angular_diameter: 0.0093,
        },
        Kind::Point => Light::Point {
            position,
            intensity: colour,
            range,
        },
        Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            let ordered = 0.0 <= inner_cone_angle && inner_cone_angle < outer_cone_angle;
            if !(ordered && outer_cone_angle <= std::f32::consts::FRAC_PI_2) {
                return Err(format!(
                    "{}: spot cone angles {inner_cone_angle} (inner) and {outer_cone_angle} \
                     (outer) must satisfy 0 ≤ inner < outer ≤ π/2",
                    name()
                ));
            }
            Light::Spot {
                position,
                direction,
                intensity: colour,
                range,
                inner_angle: inner_cone_angle,
                outer_angle: outer_cone_angle,
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_become_lists() {
        assert_eq!(strip_to_list(&[0, 1, 2, 3]), vec![0, 1, 2, 2, 1, 3]);
        assert_eq!(fan_to_list(&[0, 1, 2, 3]), vec![1, 2, 0, 2, 3, 0]);
        assert!(strip_to_list(&[0, 1]).is_empty());
    }

    #[test]
    fn base64_and_percent_decoding() {
        assert_eq!(decode_base64("aGVsbG8=").as_deref(), Some(&b"hello"[..]));
        assert_eq!(decode_base64("a?"), None);
        assert_eq!(percent_decode("my%20scene.bin"), "my scene.bin");
        assert_eq!(percent_decode("100%"), "100%");
    }
}
