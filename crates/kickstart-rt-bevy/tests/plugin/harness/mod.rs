//! The headless harness the test suites share: a real Bevy app with the plugin, rendering one
//! camera's linear HDR (`Rgba16Float`, no tone mapping) into an image read back with Bevy's
//! screenshot.
//!
//! A module of the test binary (`main.rs`); each suite uses a different part.

#![allow(dead_code)]

use std::sync::{Arc, Mutex};

use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::ecs::system::ScheduleSystem;
use bevy::prelude::*;
use bevy::render::RenderPlugin;
use bevy::render::pipelined_rendering::PipelinedRenderingPlugin;
use bevy::render::render_resource::TextureFormat;
use bevy::render::settings::RenderCreation;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use kickstart_rt_bevy::{KickstartRtPlugin, RayTracedLighting};

pub const WIDTH: u32 = 320;
pub const HEIGHT: u32 = 180;
/// Frames each configuration renders before it is read: the denoisers' history fills.
pub const SETTLE_FRAMES: u32 = 24;

/// A linear RGB image read back from the camera's target.
pub struct Frame {
    pub texels: Vec<[f32; 3]>,
}

impl Frame {
    /// Mean colour of the `radius`-pixel square around `p`.
    pub fn mean(&self, (x, y): (u32, u32), radius: u32) -> Vec3 {
        let mut sum = Vec3::ZERO;
        let mut n = 0.0;
        for yy in y.saturating_sub(radius)..=(y + radius).min(HEIGHT - 1) {
            for xx in x.saturating_sub(radius)..=(x + radius).min(WIDTH - 1) {
                sum += Vec3::from(self.texels[(yy * WIDTH + xx) as usize]);
                n += 1.0;
            }
        }
        sum / n
    }

    /// The colour of pixel `(x, y)`.
    pub fn at(&self, x: u32, y: u32) -> Vec3 {
        Vec3::from(self.texels[(y * WIDTH + x) as usize])
    }
}

/// What a harness app is made of beside its camera.
pub struct Setup {
    pub plugin: KickstartRtPlugin,
    /// The renderer's creation (Bevy's default settings unless a test changes them).
    pub render_creation: RenderCreation,
    /// The camera's placement.
    pub camera: Transform,
    /// The camera's projection (its aspect ratio follows the target).
    pub projection: PerspectiveProjection,
}

impl Default for Setup {
    fn default() -> Self {
        Setup {
            plugin: KickstartRtPlugin::default(),
            render_creation: RenderCreation::default(),
            camera: Transform::from_translation(crate::seed::EYE)
                .looking_at(crate::seed::LOOK_AT, Vec3::Y),
            projection: PerspectiveProjection::default(),
        }
    }
}

/// The app and its camera's target image.
pub struct Harness {
    pub app: App,
    pub target: Handle<Image>,
    pub camera: Transform,
    pub projection: PerspectiveProjection,
}

impl Harness {
    /// The seed scene (its objects matte) seen from the seed's eye.
    pub fn new(effects: RayTracedLighting) -> Harness {
        Harness::with(Setup::default(), effects, crate::seed::spawn, true)
    }

    /// A scene spawned by `spawn` at startup, seen by `setup.camera`; `matte` makes the seed
    /// scene's objects matte.
    pub fn with<M>(
        setup: Setup,
        effects: RayTracedLighting,
        spawn: impl IntoScheduleConfigs<ScheduleSystem, M>,
        matte: bool,
    ) -> Harness {
        let mut app = App::new();
        app.add_plugins((
            DefaultPlugins
                .set(WindowPlugin {
                    primary_window: None,
                    exit_condition: ExitCondition::DontExit,
                    close_when_requested: false,
                    ..default()
                })
                .set(RenderPlugin {
                    render_creation: setup.render_creation,
                    synchronous_pipeline_compilation: true,
                    ..default()
                })
                .disable::<WinitPlugin>()
                .disable::<PipelinedRenderingPlugin>()
                .disable::<bevy::log::LogPlugin>(),
            setup.plugin,
        ))
        .add_systems(Startup, spawn);
        if matte {
            app.insert_resource(crate::seed::Matte);
        }
        let image = Image::new_target_texture(WIDTH, HEIGHT, TextureFormat::Rgba16Float, None);
        let target = app.world_mut().resource_mut::<Assets<Image>>().add(image);
        app.world_mut().spawn((
            Camera3d::default(),
            Msaa::Off,
            Tonemapping::None,
            RenderTarget::Image(target.clone().into()),
            effects,
            setup.camera,
            Projection::Perspective(setup.projection.clone()),
        ));
        app.finish();
        app.cleanup();
        Harness {
            app,
            target,
            camera: setup.camera,
            projection: setup.projection,
        }
    }

    pub fn run(&mut self, frames: u32) {
        for _ in 0..frames {
            self.app.update();
        }
    }

    /// Renders until a screenshot of the target arrives.
    pub fn capture(&mut self) -> Frame {
        let slot: Arc<Mutex<Option<Image>>> = Arc::default();
        let into = slot.clone();
        self.app
            .world_mut()
            .spawn(Screenshot::image(self.target.clone()))
            .observe(move |captured: On<ScreenshotCaptured>| {
                *into.lock().unwrap() = Some(captured.image.clone());
            });
        for _ in 0..20 {
            self.app.update();
            if let Some(image) = slot.lock().unwrap().take() {
                return decode(&image);
            }
        }
        panic!("no screenshot after 20 frames");
    }

    /// Sets the camera's effects.
    pub fn set_effects(&mut self, effects: RayTracedLighting) {
        let world = self.app.world_mut();
        let camera = world
            .query_filtered::<Entity, With<Camera3d>>()
            .single(world)
            .expect("the harness has one camera");
        world.entity_mut(camera).insert(effects);
    }

    /// The pixel showing world point `p`.
    pub fn pixel_of(&self, p: Vec3) -> (u32, u32) {
        pixel_through(&self.camera, &self.projection, p)
    }

    /// The entity of the seed scene's coloured object `i`.
    pub fn object(&mut self, i: usize) -> Entity {
        let world = self.app.world_mut();
        world
            .query::<(Entity, &crate::seed::Object)>()
            .iter(world)
            .find(|(_, o)| o.0 == i)
            .map(|(e, _)| e)
            .expect("the seed scene has three objects")
    }

    pub fn set_object_visibility(&mut self, i: usize, visibility: Visibility) {
        let object = self.object(i);
        self.app.world_mut().entity_mut(object).insert(visibility);
    }
}

/// `Rgba16Float` texels to linear RGB.
fn decode(image: &Image) -> Frame {
    assert_eq!(image.texture_descriptor.format, TextureFormat::Rgba16Float);
    let data = image.data.as_ref().expect("screenshot has data");
    assert_eq!(data.len(), (WIDTH * HEIGHT * 8) as usize);
    let half = |b: &[u8]| f16_to_f32(u16::from_le_bytes([b[0], b[1]]));
    let texels = data
        .chunks_exact(8)
        .map(|t| [half(&t[0..2]), half(&t[2..4]), half(&t[4..6])])
        .collect();
    Frame { texels }
}

fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f32::from(h & 0x3ff);
    sign * match exp {
        0 => frac * 2f32.powi(-24),
        31 => f32::INFINITY,
        e => (1.0 + frac / 1024.0) * 2f32.powi(e - 15),
    }
}

/// The pixel showing world point `p` to a camera placed by `camera` (Bevy's default
/// perspective projection).
pub fn pixel_of(camera: &Transform, p: Vec3) -> (u32, u32) {
    pixel_through(camera, &PerspectiveProjection::default(), p)
}

/// The pixel showing world point `p` to a camera placed by `camera`, through `projection`.
pub fn pixel_through(
    camera: &Transform,
    projection: &PerspectiveProjection,
    p: Vec3,
) -> (u32, u32) {
    let view = camera.to_matrix().inverse();
    let projection = bevy::camera::CameraProjection::get_clip_from_view(&PerspectiveProjection {
        aspect_ratio: WIDTH as f32 / HEIGHT as f32,
        ..projection.clone()
    });
    let ndc = (projection * view).project_point3(p);
    let x = (ndc.x * 0.5 + 0.5) * WIDTH as f32;
    let y = (0.5 - ndc.y * 0.5) * HEIGHT as f32;
    (x as u32, y as u32)
}
