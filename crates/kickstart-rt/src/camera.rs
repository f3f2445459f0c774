//! The camera of primary rays, derived from a view's matrices only (so normal and reverse Z,
//! finite and infinite far planes and both handednesses work): used by the debug views and by
//! the lighting cache's injection, which unprojects the G-buffer.

use glam::{DVec3, DVec4};

use crate::tasks::ViewInfo;

/// Camera parameters of the shader, computed in f64 (inverting a reverse-Z or infinite
/// projection in f32 loses digits the debug views show).
pub(crate) fn camera(view: &ViewInfo) -> ([[f32; 4]; 4], [f32; 4], u32, f32, f32) {
    let v2c = view.view_to_clip.as_dmat4();
    let w2v = view.world_to_view.as_dmat4();
    let clip_to_world = (v2c * w2v).inverse().as_mat4().to_cols_array_2d();
    let eye = w2v.inverse() * DVec4::new(0.0, 0.0, 0.0, 1.0);
    let eye = (eye.truncate() / eye.w).as_vec3();
    let w_row = v2c.row(3);
    let perspective = w_row.x != 0.0 || w_row.y != 0.0 || w_row.z != 0.0;
    if perspective {
        (clip_to_world, eye.extend(1.0).to_array(), 0, 0.0, 0.5)
    } else {
        let clip_to_view = v2c.inverse();
        let z0 = clip_to_view
            .project_point3(DVec3::new(0.0, 0.0, 0.0))
            .z
            .abs();
        let z1 = clip_to_view
            .project_point3(DVec3::new(0.0, 0.0, 1.0))
            .z
            .abs();
        let (z_origin, z_target) = if z0 <= z1 { (0.0, 1.0) } else { (1.0, 0.0) };
        (
            clip_to_world,
            eye.extend(1.0).to_array(),
            1,
            z_origin,
            z_target,
        )
    }
}
