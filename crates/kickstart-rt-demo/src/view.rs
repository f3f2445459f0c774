//! `ksrt view`: a window on a scene.

use std::path::PathBuf;

use crate::AnyResult;

/// `ksrt view`'s options.
pub struct ViewArgs {
    pub scene: String,
    pub scenes_dir: PathBuf,
    pub size: String,
    pub effects: String,
    pub camera: Option<String>,
    pub frames: Option<u32>,
    pub screenshot: Option<PathBuf>,
}

/// Runs the viewer.
pub fn run(_args: ViewArgs) -> AnyResult<()> {
    Err("ksrt view: not implemented yet".into())
}
