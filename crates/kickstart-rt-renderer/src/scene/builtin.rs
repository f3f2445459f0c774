//! The built-in scenes: the default scene of the instance-id bug report (an icosahedron sphere, a
//! torus knot, a tube and a floor, each its own colour, in a room of a floor and two walls), the
//! Cornell box, built in code from the classic Cornell measurements, and a closed room lit only
//! by the sun through a small window in its ceiling (the sparse-GI case: little light reaches most surfaces).

use glam::{Affine3A, Vec3};

use super::{Camera, Instance, Light, Mesh, Scene};

/// A unit sphere: an icosahedron subdivided `subdivisions` times, vertices pushed onto the sphere.
pub fn icosphere(subdivisions: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut p: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut mid = std::collections::HashMap::new();
        let mut m = |a: u32, b: u32, p: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                p.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(f.len() * 4);
        for [a, b, c] in f {
            let (ab, bc, ca) = (m(a, b, &mut p), m(b, c, &mut p), m(c, a, &mut p));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = next;
    }
    (p.iter().map(|v| v.to_array()).collect(), f.concat())
}

/// A tube of radius `r` around a closed curve, `n` segments along it and `m` around it.
pub(super) fn sweep(
    curve: impl Fn(f32) -> Vec3,
    r: f32,
    n: u32,
    m: u32,
    closed: bool,
) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut p = Vec::new();
    let rings = if closed { n } else { n + 1 };
    for i in 0..rings {
        let s = i as f32 / n as f32;
        let c = curve(s);
        let tangent = (curve(s + 1e-3) - curve(s - 1e-3)).normalize();
        let side = tangent.cross(Vec3::Y).try_normalize().unwrap_or(Vec3::X);
        let up = side.cross(tangent);
        for j in 0..m {
            let a = j as f32 / m as f32 * std::f32::consts::TAU;
            p.push((c + (side * a.cos() + up * a.sin()) * r).to_array());
        }
    }
    let mut idx = Vec::new();
    for i in 0..n {
        let i1 = (i + 1) % rings;
        for j in 0..m {
            let j1 = (j + 1) % m;
            let (a, b, c, d) = (i * m + j, i * m + j1, i1 * m + j1, i1 * m + j);
            idx.extend([a, b, c, a, c, d]);
        }
    }
    (p, idx)
}

fn quad(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> (Vec<[f32; 3]>, Vec<u32>) {
    (
        vec![a.to_array(), b.to_array(), c.to_array(), d.to_array()],
        vec![0, 1, 2, 0, 2, 3],
    )
}

/// The default scene, with the camera the CPU reference image has always used.
pub fn default_scene() -> Scene {
    let tau = std::f32::consts::TAU;
    let (sp, si) = icosphere(3);
    let (kp, ki) = sweep(
        |s| {
            let t = s * tau;
            let (p, q) = (2.0, 3.0);
            let r = (q * t).cos() + 2.0;
            Vec3::new(r * (p * t).cos(), -(q * t).sin(), r * (p * t).sin()) * 0.25
        },
        0.1,
        256,
        12,
        true,
    );
    let (tp, ti) = sweep(|s| Vec3::new(0.0, s * 1.6, 0.0), 0.3, 16, 24, false);
    let (fp, fi) = quad(
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(-4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, -4.0),
    );
    let (bp, bi) = quad(
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(4.0, 0.0, -4.0),
        Vec3::new(4.0, 4.0, -4.0),
        Vec3::new(-4.0, 4.0, -4.0),
    );
    let (lp, li) = quad(
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(-4.0, 4.0, -4.0),
        Vec3::new(-4.0, 4.0, 4.0),
        Vec3::new(-4.0, 0.0, 4.0),
    );
    let parts = vec![
        (
            "sphere",
            (sp, si),
            Vec3::new(0.9, 0.15, 0.1),
            Affine3A::from_scale_rotation_translation(
                Vec3::splat(0.7),
                Default::default(),
                Vec3::new(-1.4, 0.7, 0.0),
            ),
        ),
        (
            "torus knot",
            (kp, ki),
            Vec3::new(0.1, 0.7, 0.2),
            Affine3A::from_translation(Vec3::new(0.6, 1.0, -0.6)),
        ),
        (
            "tube",
            (tp, ti),
            Vec3::new(0.15, 0.3, 0.9),
            Affine3A::from_translation(Vec3::new(2.2, 0.0, 0.6)),
        ),
        (
            "floor",
            (fp, fi),
            Vec3::new(0.9, 0.8, 0.2),
            Affine3A::IDENTITY,
        ),
        ("back wall", (bp, bi), Vec3::splat(0.8), Affine3A::IDENTITY),
        ("left wall", (lp, li), Vec3::splat(0.8), Affine3A::IDENTITY),
    ];
    let mut scene = from_parts("default", parts);
    scene.camera = Some(Camera {
        eye: Vec3::new(0.3, 2.4, 6.0),
        at: Vec3::new(0.2, 0.8, 0.0),
        up: Vec3::Y,
        fov_y_deg: 50.0,
    });
    // The room of the bug report: a warm sun over the walls' open side and a cool point light
    // between the knot and the tube, so both shadow kinds and the colour bleeding show.
    scene.lights = vec![
        Light::Sun {
            direction: Vec3::new(-0.5, -1.0, -0.45).normalize(),
            irradiance: Vec3::new(3.0, 2.8, 2.5),
            angular_diameter: 0.0093,
        },
        Light::Point {
            position: Vec3::new(1.6, 2.2, 1.6),
            intensity: Vec3::new(2.0, 2.4, 3.0),
            range: 12.0,
        },
    ];
    // A slightly glossy floor, to show reflections of the objects.
    if let Some(floor) = scene.meshes.iter_mut().find(|m| m.name == "floor") {
        floor.material.roughness = 0.25;
    }
    scene
}

type Part = (&'static str, (Vec<[f32; 3]>, Vec<u32>), Vec3, Affine3A);

/// One mesh and one instance per part. The built-in meshes are valid by construction, so a
/// failed check is a bug in this file; such a part is left out with an error in the log rather
/// than panicking.
fn from_parts(name: &str, parts: Vec<Part>) -> Scene {
    let mut scene = Scene {
        name: name.into(),
        ..Default::default()
    };
    for (part, (positions, indices), color, transform) in parts {
        match Mesh::new(part, positions, indices, color) {
            Ok(m) => {
                scene.instances.push(Instance {
                    mesh: scene.meshes.len(),
                    transform,
                });
                scene.meshes.push(m);
            }
            Err(e) => log::error!("built-in scene {name}: {e}"),
        }
    }
    scene
}

/// Appends the quad `a b c d` (two triangles) to `(p, i)`, wound so that its geometric normal
/// (counter-clockwise) points along `facing`: walls face into the room, blocks face out.
pub(super) fn push_quad(mesh: &mut (Vec<[f32; 3]>, Vec<u32>), q: [Vec3; 4], facing: Vec3) {
    let n = (q[1] - q[0]).cross(q[2] - q[0]);
    let q = if n.dot(facing) < 0.0 {
        [q[0], q[3], q[2], q[1]]
    } else {
        q
    };
    let base = mesh.0.len() as u32;
    mesh.0.extend(q.iter().map(|v| v.to_array()));
    mesh.1
        .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
}

/// A closed block: the footprint `corners` (x, z, counter-clockwise or not) extruded from y = 0 to
/// `height`, six faces wound outwards.
pub(super) fn block(corners: [[f32; 2]; 4], height: f32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let low = corners.map(|[x, z]| Vec3::new(x, 0.0, z));
    let high = corners.map(|[x, z]| Vec3::new(x, height, z));
    let centre = (low.iter().sum::<Vec3>() + high.iter().sum::<Vec3>()) / 8.0;
    let mut mesh = (Vec::new(), Vec::new());
    push_quad(&mut mesh, low, Vec3::NEG_Y);
    push_quad(&mut mesh, high, Vec3::Y);
    for k in 0..4 {
        let k1 = (k + 1) % 4;
        let side = [low[k], low[k1], high[k1], high[k]];
        let mid = side.iter().sum::<Vec3>() / 4.0;
        push_quad(&mut mesh, side, mid - centre);
    }
    mesh
}

/// The Cornell box in code: the classic measurements of the Cornell Program of Computer Graphics
/// (millimetres, here in metres), with the walls made square and the blocks closed. Red wall at
/// x = 0.556 (left as seen by the camera), green wall at x = 0 (right), white floor, ceiling and
/// back wall, the light just below the ceiling, and the classic camera (eye at z = −0.8 looking
/// down +z, 39.3° vertical field of view).
pub fn cornell_box() -> Scene {
    let (w, h, d) = (0.556, 0.5488, 0.5592);
    let white = Vec3::new(0.725, 0.71, 0.68);
    let red = Vec3::new(0.63, 0.065, 0.05);
    let green = Vec3::new(0.14, 0.45, 0.091);
    let wall = |q: [[f32; 3]; 4], facing: Vec3| {
        let mut m = (Vec::new(), Vec::new());
        push_quad(&mut m, q.map(Vec3::from), facing);
        m
    };
    let mm = |c: [[f32; 2]; 4]| c.map(|[x, z]| [x * 1e-3, z * 1e-3]);
    let parts = vec![
        (
            "floor",
            wall(
                [[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, 0.0, d], [0.0, 0.0, d]],
                Vec3::Y,
            ),
            white,
            Affine3A::IDENTITY,
        ),
        (
            "ceiling",
            wall(
                [[0.0, h, 0.0], [w, h, 0.0], [w, h, d], [0.0, h, d]],
                Vec3::NEG_Y,
            ),
            white,
            Affine3A::IDENTITY,
        ),
        (
            "back wall",
            wall(
                [[0.0, 0.0, d], [w, 0.0, d], [w, h, d], [0.0, h, d]],
                Vec3::NEG_Z,
            ),
            white,
            Affine3A::IDENTITY,
        ),
        (
            "red wall",
            wall(
                [[w, 0.0, 0.0], [w, 0.0, d], [w, h, d], [w, h, 0.0]],
                Vec3::NEG_X,
            ),
            red,
            Affine3A::IDENTITY,
        ),
        (
            "green wall",
            wall(
                [[0.0, 0.0, 0.0], [0.0, 0.0, d], [0.0, h, d], [0.0, h, 0.0]],
                Vec3::X,
            ),
            green,
            Affine3A::IDENTITY,
        ),
        (
            "light",
            wall(
                [
                    [0.343, h - 1e-4, 0.227],
                    [0.213, h - 1e-4, 0.227],
                    [0.213, h - 1e-4, 0.332],
                    [0.343, h - 1e-4, 0.332],
                ],
                Vec3::NEG_Y,
            ),
            Vec3::splat(0.78),
            Affine3A::IDENTITY,
        ),
        (
            "short block",
            block(
                mm([[130.0, 65.0], [82.0, 225.0], [240.0, 272.0], [290.0, 114.0]]),
                0.165,
            ),
            white,
            Affine3A::IDENTITY,
        ),
        (
            "tall block",
            block(
                mm([
                    [423.0, 247.0],
                    [265.0, 296.0],
                    [314.0, 456.0],
                    [472.0, 406.0],
                ]),
                0.330,
            ),
            white,
            Affine3A::IDENTITY,
        ),
    ];
    let mut scene = from_parts("cornell", parts);
    scene.camera = Some(Camera {
        eye: Vec3::new(0.278, 0.273, -0.8),
        at: Vec3::new(0.278, 0.273, 0.0),
        up: Vec3::Y,
        fov_y_deg: 39.3,
    });
    // The ceiling panel glows, and a spot just below it, aimed down, stands in for its light in
    // the rasteriser (which has no area lights).
    if let Some(light) = scene.meshes.iter_mut().find(|m| m.name == "light") {
        light.material.emissive = Vec3::new(17.0, 12.0, 4.0);
    }
    scene.lights = vec![Light::Spot {
        position: Vec3::new(0.278, h - 0.01, 0.2795),
        direction: Vec3::NEG_Y,
        intensity: Vec3::new(0.9, 0.8, 0.65),
        range: 3.0,
        inner_angle: 0.9,
        outer_angle: 1.5,
    }];
    scene
}

/// The window room's walls, floor and ceiling: x and z in ±[`WINDOW_ROOM_HALF_WIDTH`], y from 0 to
/// [`WINDOW_ROOM_HEIGHT`].
pub const WINDOW_ROOM_HALF_WIDTH: f32 = 2.0;
/// The window room's height.
pub const WINDOW_ROOM_HEIGHT: f32 = 3.0;
/// The window room's only opening, a square hole in the ceiling: `[x0, z0, x1, z1]`. 0.9 m × 0.9 m,
/// about 1/20 of the ceiling.
pub const WINDOW_ROOM_WINDOW: [f32; 4] = [-0.95, -0.95, -0.05, -0.05];
/// The way the window room's sun travels (not normalised): steep, so that all of it that
/// enters through the window lands on the floor, a patch beside the spot below the window.
pub const WINDOW_ROOM_SUN: Vec3 = Vec3::new(0.35, -1.0, 0.25);

/// A closed room, 4 m × 4 m × 3 m, every face towards the inside, whose only light is the sun
/// shining through a window of 1/20 of the ceiling onto a patch of the floor; nothing else
/// lights it (no emission, and declaring the sun keeps the demo from adding its default lights).
/// The camera, inside, looks down at the sunlit patch with the dim walls behind it; the window
/// stays out of its view, so every pixel shows a surface. Everything but the patch
/// is lit only by light bounced off it, which about one diffuse ray in a hundred from the view
/// reaches: the sparse diffuse GI a denoiser must not lose.
pub fn window_room() -> Scene {
    let (w, h) = (WINDOW_ROOM_HALF_WIDTH, WINDOW_ROOM_HEIGHT);
    let [wx0, wz0, wx1, wz1] = WINDOW_ROOM_WINDOW;
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let face = |quads: &[[Vec3; 4]], facing: Vec3| {
        let mut m = (Vec::new(), Vec::new());
        for q in quads {
            push_quad(&mut m, *q, facing);
        }
        m
    };
    let ceiling_rect = |x0: f32, z0: f32, x1: f32, z1: f32| {
        [v(x0, h, z0), v(x1, h, z0), v(x1, h, z1), v(x0, h, z1)]
    };
    let white = Vec3::new(0.8, 0.78, 0.75);
    let parts = vec![
        (
            "floor",
            face(
                &[[v(-w, 0.0, -w), v(w, 0.0, -w), v(w, 0.0, w), v(-w, 0.0, w)]],
                Vec3::Y,
            ),
            Vec3::new(0.6, 0.45, 0.3),
            Affine3A::IDENTITY,
        ),
        (
            // Four strips around the window.
            "ceiling",
            face(
                &[
                    ceiling_rect(-w, -w, w, wz0),
                    ceiling_rect(-w, wz1, w, w),
                    ceiling_rect(-w, wz0, wx0, wz1),
                    ceiling_rect(wx1, wz0, w, wz1),
                ],
                Vec3::NEG_Y,
            ),
            white,
            Affine3A::IDENTITY,
        ),
        (
            "walls",
            {
                let mut m = face(
                    &[[v(-w, 0.0, -w), v(w, 0.0, -w), v(w, h, -w), v(-w, h, -w)]],
                    Vec3::Z,
                );
                for (q, facing) in [
                    (
                        [v(-w, 0.0, w), v(w, 0.0, w), v(w, h, w), v(-w, h, w)],
                        Vec3::NEG_Z,
                    ),
                    (
                        [v(-w, 0.0, -w), v(-w, 0.0, w), v(-w, h, w), v(-w, h, -w)],
                        Vec3::X,
                    ),
                    (
                        [v(w, 0.0, -w), v(w, 0.0, w), v(w, h, w), v(w, h, -w)],
                        Vec3::NEG_X,
                    ),
                ] {
                    push_quad(&mut m, q, facing);
                }
                m
            },
            white,
            Affine3A::IDENTITY,
        ),
    ];
    let mut scene = from_parts("window-room", parts);
    scene.camera = Some(Camera {
        eye: Vec3::new(-1.5, 1.7, 1.6),
        at: Vec3::new(0.6, 0.2, 0.0),
        up: Vec3::Y,
        fov_y_deg: 65.0,
    });
    scene.lights = vec![Light::Sun {
        direction: WINDOW_ROOM_SUN.normalize(),
        irradiance: Vec3::new(6.0, 5.7, 5.2),
        angular_diameter: 0.0093,
    }];
    scene
}
