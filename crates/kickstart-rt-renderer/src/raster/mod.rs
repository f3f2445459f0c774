//! ksrt's small deferred rasteriser, in wgpu render passes: a G-buffer (depth, world normals,
//! emission, base colour + metalness, specular colour + roughness, view-space motion), a shadow
//! map for the first sun, and a direct lighting pass (sun, point and spot lights, emission). It
//! renders any number of views ([`ViewTargets`]): the main camera and the low-resolution "lidar"
//! camera that warms the SDK's lighting cache.
//!
//! Decisions an engine programmer would look for:
//! - **Jitter**: the rasterised projection is offset by a Halton(2, 3) sub-pixel jitter per frame
//!   ([`halton_jitter`]); the SDK gets the unjittered matrices and the jitter separately, as its
//!   denoisers expect. Jitter is in pixels, x right, y down, in (−0.5, 0.5).
//! - **Depth**: `Depth32Float`, wgpu's 0..1 clip depth, 1 = far (what the SDK's `RClipSpace`
//!   reads).
//! - **Normals**: world space, `Rgba16Float`, unencoded (the SDK's `NormalType::RgbVector`).
//! - **Roughness / specular**: one `Rgba8Unorm` target, RGB = the specular colour F0
//!   (mix(0.04, base colour, metalness)) and A = perceptual roughness: the SDK's roughness mask
//!   is its default (alpha) and the same texture is its specular input.
//! - **Motion**: `Rg16Float`, previous_uv − uv in viewport UV (the SDK's `RgViewSpace`, scale 1).

mod gpu_scene;
mod targets;

pub use gpu_scene::GpuScene;
pub use targets::ViewTargets;

use glam::{Mat4, Vec2, Vec3};

use crate::scene::Camera;

/// `Halton(index, base)`, the radical inverse of `index` in `base`: a low-discrepancy sequence.
pub fn halton(mut index: u32, base: u32) -> f32 {
    let (mut f, mut r) = (1.0f32, 0.0f32);
    while index > 0 {
        f /= base as f32;
        r += f * (index % base) as f32;
        index /= base;
    }
    r
}

/// The sub-pixel jitter of frame `frame`, pixels in (−0.5, 0.5): Halton(2, 3) over a cycle of 16
/// (the usual TAA choice; index 0 is skipped, it would be (−0.5, −0.5)).
pub fn halton_jitter(frame: u32) -> Vec2 {
    let i = frame % 16 + 1;
    Vec2::new(halton(i, 2) - 0.5, halton(i, 3) - 0.5)
}

/// One view of one frame: the camera's unjittered matrices, this frame's jitter, and the previous
/// frame's matrices (for motion vectors and the SDK's denoisers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameView {
    /// World → view.
    pub world_to_view: Mat4,
    /// View → clip, unjittered.
    pub view_to_clip: Mat4,
    /// The previous frame's world → view.
    pub prev_world_to_view: Mat4,
    /// The previous frame's view → clip (unjittered).
    pub prev_view_to_clip: Mat4,
    /// Sub-pixel jitter, pixels (x right, y down).
    pub jitter: Vec2,
    /// Eye position.
    pub eye: Vec3,
}

impl FrameView {
    /// The view of `camera` at `size`, with clip planes fit to a scene of diameter `scene_size`.
    /// `prev` is the previous frame's view of the same camera (`None` on the first frame or after
    /// a cut: no motion).
    pub fn new(
        camera: &Camera,
        size: (u32, u32),
        scene_size: f32,
        jitter: Vec2,
        prev: Option<&FrameView>,
    ) -> FrameView {
        let (near, far) = clip_planes(camera, scene_size);
        let (world_to_view, view_to_clip) =
            camera.matrices(size.0 as f32 / size.1 as f32, near, far);
        FrameView {
            world_to_view,
            view_to_clip,
            prev_world_to_view: prev.map_or(world_to_view, |p| p.world_to_view),
            prev_view_to_clip: prev.map_or(view_to_clip, |p| p.view_to_clip),
            jitter,
            eye: camera.eye,
        }
    }

    /// The jittered world → clip transform the rasteriser draws with: the projection moved by
    /// `jitter` pixels of a `size` viewport.
    pub fn jittered_view_proj(&self, size: (u32, u32)) -> Mat4 {
        let offset = Mat4::from_translation(Vec3::new(
            2.0 * self.jitter.x / size.0 as f32,
            -2.0 * self.jitter.y / size.1 as f32,
            0.0,
        ));
        offset * self.view_to_clip * self.world_to_view
    }

    /// The SDK's description of this view.
    pub fn sdk_view(&self) -> kickstart_rt::ViewInfo {
        kickstart_rt::ViewInfo {
            world_to_view: self.world_to_view,
            view_to_clip: self.view_to_clip,
            prev_world_to_view: self.prev_world_to_view,
            prev_view_to_clip: self.prev_view_to_clip,
            jitter: self.jitter,
        }
    }
}

/// Near and far planes that hold a scene of diameter `scene_size` seen from `camera`: far beyond
/// the farthest point, near 1/1000 of it: the lighting pass reconstructs positions from depth,
/// and a nearer plane makes grazing lights show the depth quantisation as stripes.
pub fn clip_planes(camera: &Camera, scene_size: f32) -> (f32, f32) {
    let far = (scene_size * 2.0 + (camera.at - camera.eye).length()).max(1e-3);
    (far * 1e-3, far)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halton_sequence_matches_its_definition() {
        assert_eq!(halton(1, 2), 0.5);
        assert_eq!(halton(2, 2), 0.25);
        assert_eq!(halton(3, 2), 0.75);
        assert!((halton(1, 3) - 1.0 / 3.0).abs() < 1e-6);
        assert!((halton(5, 3) - 7.0 / 9.0).abs() < 1e-6);
        // Jitter stays inside the pixel and averages to about its centre over a cycle.
        let mean: Vec2 = (0..16).map(halton_jitter).sum::<Vec2>() / 16.0;
        assert!(mean.abs().max_element() < 0.05, "{mean}");
        assert!((0..16).all(|f| halton_jitter(f).abs().max_element() < 0.5));
    }

    #[test]
    fn jitter_moves_the_projection_by_that_many_pixels() {
        let camera = Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            at: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 60.0,
        };
        let size = (64, 32);
        let mut v = FrameView::new(&camera, size, 2.0, Vec2::ZERO, None);
        let p = glam::Vec4::new(0.3, -0.2, 0.1, 1.0);
        let to_px = |m: Mat4| {
            let c = m * p;
            Vec2::new(
                (c.x / c.w * 0.5 + 0.5) * size.0 as f32,
                (0.5 - c.y / c.w * 0.5) * size.1 as f32,
            )
        };
        let base = to_px(v.jittered_view_proj(size));
        v.jitter = Vec2::new(0.25, -0.4);
        let moved = to_px(v.jittered_view_proj(size));
        assert!((moved - base - v.jitter).abs().max_element() < 1e-3);
    }
}

/// Bind group layout entries the composite shares with the lighting pass.
pub(crate) mod gpu_scene_entries {
    pub(crate) use crate::raster::gpu_scene::{texture_entry as texture, UNFILTERED};

    /// A uniform buffer visible to the vertex and fragment stages.
    pub fn uniform(binding: u32) -> wgpu::BindGroupLayoutEntry {
        crate::raster::gpu_scene::uniform_entry(binding, false)
    }
}
