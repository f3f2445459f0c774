//! The G-buffer against analytic answers: a wall facing the camera, seen from two camera
//! positions, gives its normal, its clip depth, its base colour and the motion of a sideways
//! camera move (previous_uv − uv = dx / (2 · tan(fov/2) · aspect · distance) in u, 0 in v).

use crate::app::frames::RendererExt;
use glam::{Affine3A, Vec3};

use crate::app::readback::read_texture;
use crate::app::testing;
use kickstart_rt_renderer::scene::{Camera, Instance, Mesh, Scene};

fn wall_scene(distance: f32) -> Scene {
    let s = 50.0;
    let positions = vec![
        [-s, -s, -distance],
        [s, -s, -distance],
        [s, s, -distance],
        [-s, s, -distance],
    ];
    let mesh = Mesh::new(
        "wall",
        positions,
        vec![0, 1, 2, 0, 2, 3],
        Vec3::new(0.5, 0.25, 0.75),
    )
    .expect("valid mesh");
    Scene {
        name: "wall".into(),
        meshes: vec![mesh],
        instances: vec![Instance {
            mesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        ..Default::default()
    }
}

#[test]
fn gbuffer_normals_depth_colour_and_motion_match_the_analytic_wall() {
    let (device, queue) = testing::device();
    let distance = 5.0;
    let scene = wall_scene(distance);
    let size = (64, 32);
    let mut opts = crate::app::frames::renderer_options(size);
    opts.effects = kickstart_rt_renderer::frame::Effects::parse("none").expect("effects");
    let mut r = crate::app::frames::new_renderer(device, queue, &scene, &opts).expect("renderer");
    let fov = 60.0f32;
    let camera = |x: f32| Camera {
        eye: Vec3::new(x, 0.0, 0.0),
        at: Vec3::new(x, 0.0, -1.0),
        up: Vec3::Y,
        fov_y_deg: fov,
    };
    let dx = 0.3;
    r.render_frame(device, queue, &camera(0.0), false)
        .expect("frame 0");
    r.render_frame(device, queue, &camera(dx), false)
        .expect("frame 1");

    let aspect = size.0 as f32 / size.1 as f32;
    let want_u = dx / (2.0 * (fov.to_radians() / 2.0).tan() * aspect * distance);
    let motion = read_texture(device, queue, &r.main.motion).expect("motion");
    let normal = read_texture(device, queue, &r.main.normal).expect("normal");
    let depth = read_texture(device, queue, &r.main.depth).expect("depth");
    let base = read_texture(device, queue, &r.main.base_color).expect("base colour");
    // The clip depth of the wall with the renderer's own planes.
    let (near, far) = kickstart_rt_renderer::raster::clip_planes(&camera(dx), scene.size());
    let proj = glam::Mat4::perspective_rh(fov.to_radians(), aspect, near, far);
    let c = proj * glam::Vec4::new(0.0, 0.0, -distance, 1.0);
    let want_depth = c.z / c.w;
    let srgb = |l: f32| {
        if l <= 0.0031308 {
            l * 12.92
        } else {
            1.055 * l.powf(1.0 / 2.4) - 0.055
        }
    };
    for k in [0, 17, 500, 1000, 2047] {
        let m = motion.data[k];
        assert!(
            (m[0] - want_u).abs() < 2e-3,
            "pixel {k}: motion {m:?}, want u {want_u}"
        );
        assert!(m[1].abs() < 1e-3, "pixel {k}: motion {m:?}");
        let n = normal.data[k];
        assert!(
            (Vec3::new(n[0], n[1], n[2]) - Vec3::Z).length() < 1e-2,
            "pixel {k}: normal {n:?}"
        );
        assert!(
            (depth.data[k][0] - want_depth).abs() < 1e-4,
            "pixel {k}: depth {}",
            depth.data[k][0]
        );
        // Base colour (stored sRGB-encoded) and metalness 0 in A.
        let b = base.data[k];
        for (got, want) in [b[0], b[1], b[2]].iter().zip([0.5f32, 0.25, 0.75]) {
            assert!(
                (got - srgb(want)).abs() < 2.0 / 255.0,
                "pixel {k}: base {b:?}"
            );
        }
        assert_eq!(b[3], 0.0);
    }
}

#[test]
fn hdr_channels_are_written_as_linear_exr() {
    let t = crate::app::readback::Texels {
        width: 2,
        height: 1,
        data: vec![[2.5, 0.25, 0.0, 1.0], [-1.0, 0.0, 0.0, 1.0]],
    };
    let result = crate::app::lit::LitResult {
        channels: vec![crate::app::lit::Channel {
            name: "direct",
            texels: t,
            encoding: crate::app::readback::Encoding::Radiance,
        }],
        missing: vec![],
        refused: vec![],
        timings: vec![],
        frames: vec![],
        debug: vec![],
        memory: Default::default(),
        backend: kickstart_rt::BackendReport {
            backend: kickstart_rt::TraversalBackend::Software,
            reason: "test".into(),
        },
    };
    let dir = testing::temp_dir("exr");
    let written = crate::app::lit::write(&result, &dir, true).expect("write");
    assert_eq!(written.len(), 2);
    let exr = image::open(dir.join("direct.exr"))
        .expect("read exr")
        .to_rgb32f();
    assert_eq!(exr.get_pixel(0, 0).0, [2.5, 0.25, 0.0]);
    let png = image::open(dir.join("direct.png"))
        .expect("read png")
        .to_rgb8();
    // ACES fit: 2.5 → 0.938, 0.25 → 0.374; sRGB-encoded: 0.972 and 0.647 of 255.
    let p = png.get_pixel(0, 0).0;
    assert!(
        p[0].abs_diff(248) <= 1 && p[1].abs_diff(165) <= 1 && p[2] == 0,
        "{p:?}"
    );
}
