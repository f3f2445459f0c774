//! Scene files for `ksrt`: the scene names `--scene` accepts, the scenes folder, and loading
//! glTF 2.0 / OBJ files into the renderer's [`Scene`] (built-in scenes are the renderer's).

mod gltf;
mod gltf_accessor;
mod gltf_alpha;
mod gltf_anim;
mod gltf_skin;
mod gltf_write;
mod guard;
mod obj;
mod texture;

use std::path::{Path, PathBuf};

use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::{builtin, character, crowd, grove, statue, town, Scene};

/// A loading error: which file and what is wrong with it.
#[derive(Debug, Clone)]
pub struct SceneError {
    /// The file (or scene name) the error is about.
    pub path: PathBuf,
    /// What went wrong.
    pub what: String,
}

impl SceneError {
    /// An error about `path`.
    pub fn new(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        SceneError {
            path: path.into(),
            what: what.into(),
        }
    }
}

impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.what)
    }
}

impl std::error::Error for SceneError {}

/// The scene names `--scene` accepts, with the file each resolves to in the scenes folder
/// (`None`: built in).
pub const SCENE_NAMES: &[(&str, Option<&str>)] = &[
    ("default", None),
    ("cornell", None),
    ("window-room", None),
    ("grove", None),
    ("dancers", None),
    ("town", None),
    ("crowd", None),
    ("statue", None),
    ("dragon", Some("stanford_dragon/dragon_vrip.glb")),
    ("apartment", Some("dream_apartment/dream_apartment.gltf")),
    ("bunny", Some("stanford_bunny/bunny.obj")),
    (
        "cornell-obj",
        Some("cornell_box/obj_mcguire/CornellBox-Original.obj"),
    ),
    ("cornell-gltf", Some("cornell_box/gltf_kajiya/scene.gltf")),
];

/// The repository's own `scenes/` folder, where this program was built from (found from the
/// crate's location, so `ksrt` and the tests find it from any working directory).
pub fn repository_scenes_dir() -> PathBuf {
    // The crate sits at `crates/<name>/` of the repository.
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    crate_dir.parent().and_then(Path::parent).map_or_else(
        || crate_dir.join("../../scenes"),
        |root| root.join("scenes"),
    )
}

/// The scenes folder: `--scenes` when given, else `$KSRT_SCENES` when set and not empty, else
/// the repository's `scenes/` ([`repository_scenes_dir`]) when it exists (a binary copied off
/// the machine that built it has none), else `scenes` in the working directory.
pub fn scenes_dir(arg: Option<PathBuf>) -> PathBuf {
    scenes_dir_from(arg, std::env::var_os("KSRT_SCENES"))
}

/// [`scenes_dir`] with the environment variable's value passed in.
fn scenes_dir_from(arg: Option<PathBuf>, env: Option<std::ffi::OsString>) -> PathBuf {
    arg.or_else(|| env.filter(|v| !v.is_empty()).map(PathBuf::from))
        .unwrap_or_else(|| {
            let repo = repository_scenes_dir();
            if repo.is_dir() {
                repo
            } else {
                PathBuf::from("scenes")
            }
        })
}

/// Loads `--scene NAME|PATH`: a name of [`SCENE_NAMES`] (files looked up in `scenes_dir`) or a
/// path to a `.gltf`, `.glb` or `.obj` file.
pub fn load(name_or_path: &str, scenes_dir: &Path) -> Result<Scene, SceneError> {
    match name_or_path {
        "default" => return Ok(builtin::default_scene()),
        "cornell" => return Ok(builtin::cornell_box()),
        "window-room" => return Ok(builtin::window_room()),
        "grove" => return Ok(grove::grove()),
        "dancers" => return dancers(),
        "town" => return Ok(town::town()),
        "crowd" => return Ok(crowd::crowd()),
        "statue" => return Ok(statue::statue()),
        _ => {}
    }
    if let Some((name, Some(file))) = SCENE_NAMES.iter().find(|(n, _)| *n == name_or_path) {
        let path = scenes_dir.join(file);
        if !path.exists() {
            return Err(SceneError::new(
                &path,
                format!(
                    "scene {name:?} not found (scenes folder {}; set --scenes DIR or KSRT_SCENES){}",
                    scenes_dir.display(),
                    if matches!(*name, "dragon" | "bunny") {
                        "; the Stanford scans are not in the repository (their terms forbid \
                         shipping them): use a folder that has them, or the built-in `statue`"
                    } else {
                        ""
                    }
                ),
            ));
        }
        let mut scene = load_file(&path)?;
        scene.name = name.to_string();
        return Ok(scene);
    }
    let path = Path::new(name_or_path);
    let known = SCENE_NAMES
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ");
    if path.extension().is_none() && !path.exists() {
        return Err(SceneError::new(
            path,
            format!("no such scene; use one of {known}, or a path to a .gltf, .glb or .obj file"),
        ));
    }
    load_file(path)
}

/// The built-in `dancers`: the generated skinned characters ([`character::dancers`]) written
/// as a `.gltf` by [`gltf_write::to_gltf`] and read back by the glTF loader, so that what a
/// file's skins, morph targets and animations go through is what this scene shows; the
/// generator's floor comes through the file too, its sun and camera are taken as generated.
pub fn dancers() -> Result<Scene, SceneError> {
    let path = Path::new("dancers (generated).gltf");
    let generated = character::dancers().map_err(|e| SceneError::new(path, e))?;
    let bytes = gltf_write::to_gltf(&generated).map_err(|e| SceneError::new(path, e))?;
    let mut scene = gltf::load_from_bytes(path, &bytes)?;
    scene.name = generated.name;
    scene.lights = generated.lights;
    scene.camera = generated.camera;
    Ok(scene)
}

/// Loads a `.gltf`, `.glb` or `.obj` file by its extension.
pub fn load_file(path: &Path) -> Result<Scene, SceneError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let mut scene = match ext.as_deref() {
        Some("gltf" | "glb") => gltf::load(path)?,
        Some("obj") => obj::load(path)?,
        _ => {
            return Err(SceneError::new(
                path,
                "unknown scene format (expected .gltf, .glb or .obj)",
            ))
        }
    };
    if scene.name.is_empty() {
        scene.name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into());
    }
    if scene.instances.is_empty() {
        log::warn!("{}: the scene has no triangles", path.display());
    }
    Ok(scene)
}

/// Loads `--scene NAME|PATH` from the scenes folder `scenes` (see [`scenes_dir`]), with a
/// spinner, logging how long it took.
pub fn load_scene(name: &str, scenes: Option<PathBuf>) -> AnyResult<Scene> {
    let start = std::time::Instant::now();
    let dir = scenes_dir(scenes);
    let scene =
        crate::app::progress::with_spinner(true, format!("loading {name}"), || load(name, &dir))?;
    log::info!(
        "loaded {name} ({} triangles) in {:.2} s",
        scene.triangle_count(),
        start.elapsed().as_secs_f64()
    );
    Ok(scene)
}

#[cfg(test)]
mod asset_tests;
#[cfg(test)]
mod fuzz_tests;
#[cfg(test)]
mod skin_tests;
#[cfg(test)]
mod tests;
