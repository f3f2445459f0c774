//! The seed scene — a red sphere, a green torus knot and a blue tube on a grey floor — with
//! kickstart-rt's ray-traced reflections, GI, AO and shadows, toggled by keys.
//!
//! ```sh
//! cargo +nightly run --ignore-rust-version --example seed_scene
//! cargo +nightly run --ignore-rust-version --example seed_scene -- --frames 8  # exits (CI)
//! # No window: renders to an image and prints the SDK passes' GPU time a frame.
//! cargo +nightly run --release --ignore-rust-version --example seed_scene -- \
//!     --headless --size 1920x1080 --frames 200 --timings
//! ```
//!
//! `--out FILE.png` saves the last frame; `--effects LIST` picks the effects on at start
//! (comma-separated from reflections, gi, ao, shadows, denoise; `none` for none); `--preset
//! performance|balanced|quality` the SDK's preset (quality by default).
//!
//! Keys: R reflections, G GI, O ambient occlusion, S shadows, D denoising, Space pauses the
//! camera. The window's title shows which are on.

#[path = "seed/mod.rs"]
mod seed;

use std::collections::BTreeMap;
use std::time::Duration;

use bevy::app::ScheduleRunnerPlugin;
use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy::render::render_resource::TextureFormat;
use bevy::render::view::screenshot::{Screenshot, save_to_disk};
use bevy::window::{ExitCondition, WindowResolution};
use bevy::winit::WinitPlugin;
use kickstart_rt_bevy::{KickstartRtPlugin, RayTracedLighting, SdkTimings};

/// Command-line options.
#[derive(Resource, Clone)]
struct Options {
    frames: Option<u32>,
    headless: bool,
    size: UVec2,
    timings: bool,
    out: Option<String>,
    effects: RayTracedLighting,
}

fn main() -> AppExit {
    let options = match parse_args() {
        Ok(o) => o,
        Err(e) => {
            eprintln!(
                "seed_scene: {e}\nusage: seed_scene [--frames N] [--headless] [--size WxH] \
                 [--timings] [--out FILE.png] [--effects LIST] [--preset NAME]"
            );
            return AppExit::error();
        }
    };
    let mut app = App::new();
    if options.headless {
        app.add_plugins((
            DefaultPlugins
                .set(WindowPlugin {
                    primary_window: None,
                    exit_condition: ExitCondition::DontExit,
                    close_when_requested: false,
                    ..default()
                })
                .disable::<WinitPlugin>(),
            ScheduleRunnerPlugin::run_loop(Duration::ZERO),
        ));
    } else {
        app.add_plugins(DefaultPlugins.set(WindowPlugin {
            primary_window: Some(Window {
                title: "kickstart-rt seed scene".into(),
                resolution: WindowResolution::new(options.size.x, options.size.y),
                ..default()
            }),
            ..default()
        }));
    }
    app.add_plugins(KickstartRtPlugin {
        gpu_timing: options.timings,
        ..default()
    })
    .insert_resource(options)
    .add_systems(Startup, (seed::spawn, spawn_camera))
    .add_systems(Update, (toggle_effects, orbit, count_frames))
    .run()
}

fn parse_args() -> Result<Options, String> {
    let mut options = Options {
        frames: None,
        headless: false,
        size: UVec2::new(960, 540),
        timings: false,
        out: None,
        effects: RayTracedLighting::default(),
    };
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--frames" => {
                let n = args.next().ok_or("--frames needs a number")?;
                options.frames = Some(
                    n.parse()
                        .map_err(|_| format!("--frames {n}: not a number"))?,
                );
            }
            "--size" => {
                let s = args.next().ok_or("--size needs WxH")?;
                let (w, h) = s
                    .split_once('x')
                    .ok_or(format!("--size {s}: expected WxH"))?;
                let parse = |v: &str| v.parse::<u32>().ok().filter(|v| *v > 0);
                options.size = UVec2::new(
                    parse(w).ok_or(format!("--size {s}: bad width"))?,
                    parse(h).ok_or(format!("--size {s}: bad height"))?,
                );
            }
            "--out" => options.out = Some(args.next().ok_or("--out needs a file name")?),
            "--effects" => {
                let list = args.next().ok_or("--effects needs a list")?;
                options.effects = RayTracedLighting {
                    preset: options.effects.preset,
                    ..parse_effects(&list)?
                };
            }
            "--preset" => {
                let name = args.next().ok_or("--preset needs a name")?;
                options.effects.preset = name.parse()?;
            }
            "--headless" => options.headless = true,
            "--timings" => options.timings = true,
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(options)
}

fn parse_effects(list: &str) -> Result<RayTracedLighting, String> {
    let mut e = RayTracedLighting {
        reflections: false,
        gi: false,
        ao: false,
        shadows: false,
        denoise: false,
        ..default()
    };
    for name in list.split(',').filter(|n| !n.is_empty() && *n != "none") {
        match name {
            "reflections" => e.reflections = true,
            "gi" => e.gi = true,
            "ao" => e.ao = true,
            "shadows" => e.shadows = true,
            "denoise" => e.denoise = true,
            other => return Err(format!("--effects: unknown effect {other}")),
        }
    }
    Ok(e)
}

/// The image a headless camera renders into.
#[derive(Resource)]
struct Target(Handle<Image>);

fn spawn_camera(mut commands: Commands, options: Res<Options>, mut images: ResMut<Assets<Image>>) {
    let mut camera = commands.spawn((
        Camera3d::default(),
        Msaa::Off,
        // A tone mapper without lookup tables (those need Bevy's `tonemapping_luts` feature).
        Tonemapping::AcesFitted,
        options.effects.clone(),
        Transform::from_translation(seed::EYE).looking_at(seed::LOOK_AT, Vec3::Y),
    ));
    if options.headless {
        let image = Image::new_target_texture(
            options.size.x,
            options.size.y,
            TextureFormat::Rgba8UnormSrgb,
            None,
        );
        let handle = images.add(image);
        camera.insert(RenderTarget::Image(handle.clone().into()));
        commands.insert_resource(Target(handle));
    }
}

/// R, G, O, S, D toggle reflections, GI, AO, shadows, denoising.
fn toggle_effects(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    mut cameras: Query<&mut RayTracedLighting>,
    mut windows: Query<&mut Window>,
) {
    let Some(keys) = keys else { return };
    for mut rt in &mut cameras {
        let rt = &mut *rt;
        for (key, flag) in [
            (KeyCode::KeyR, &mut rt.reflections),
            (KeyCode::KeyG, &mut rt.gi),
            (KeyCode::KeyO, &mut rt.ao),
            (KeyCode::KeyS, &mut rt.shadows),
            (KeyCode::KeyD, &mut rt.denoise),
        ] {
            if keys.just_pressed(key) {
                *flag = !*flag;
            }
        }
        let on = |b: bool| if b { "on" } else { "off" };
        for mut window in &mut windows {
            window.title = format!(
                "kickstart-rt — [R]eflections {} [G]I {} A[O] {} [S]hadows {} [D]enoise {} \
                 ({} preset)",
                on(rt.reflections),
                on(rt.gi),
                on(rt.ao),
                on(rt.shadows),
                on(rt.denoise),
                rt.preset.name()
            );
        }
    }
}

/// Circles the camera slowly (Space pauses), so the denoisers' reprojection is at work.
fn orbit(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    mut paused: Local<bool>,
    mut angle: Local<f32>,
    mut cameras: Query<&mut Transform, With<Camera3d>>,
) {
    if keys.is_some_and(|k| k.just_pressed(KeyCode::Space)) {
        *paused = !*paused;
    }
    if !*paused {
        *angle += 0.004;
    }
    for mut transform in &mut cameras {
        let eye = Quat::from_rotation_y(*angle) * seed::EYE;
        *transform = Transform::from_translation(eye).looking_at(seed::LOOK_AT, Vec3::Y);
    }
}

/// Exits after `--frames` (after saving the last frame with `--out`); with `--timings`, prints the SDK's GPU time a frame, averaged over
/// the second half of the frames (the first half warms pipelines and denoisers up).
fn count_frames(
    mut commands: Commands,
    options: Res<Options>,
    target: Option<Res<Target>>,
    timings: Res<SdkTimings>,
    mut frame: Local<u32>,
    mut sums: Local<(BTreeMap<String, f64>, u32)>,
    mut exit: MessageWriter<AppExit>,
) {
    *frame += 1;
    let Some(frames) = options.frames else { return };
    if options.timings && *frame > frames / 2 && *frame <= frames {
        let passes = timings.passes();
        if !passes.is_empty() {
            sums.1 += 1;
        }
        for (label, ms) in passes {
            *sums.0.entry(label).or_default() += ms;
        }
    }
    if *frame == frames {
        if options.timings {
            print_timings(&sums, options.size);
        }
        println!("rendered {frames} frames");
        if let Some(out) = &options.out {
            let screenshot = match &target {
                Some(t) => Screenshot::image(t.0.clone()),
                None => Screenshot::primary_window(),
            };
            commands
                .spawn(screenshot)
                .observe(save_to_disk(out.clone()));
        }
    }
    // The screenshot is read back a few frames later.
    let last = if options.out.is_some() {
        frames + 5
    } else {
        frames
    };
    if *frame >= last {
        exit.write(AppExit::Success);
    }
}

fn print_timings((sums, frames): &(BTreeMap<String, f64>, u32), size: UVec2) {
    let frames = *frames;
    if frames == 0 {
        println!(
            "no GPU timings were read (the device needs TIMESTAMP_QUERY and TIMESTAMP_QUERY_INSIDE_ENCODERS)"
        );
        return;
    }
    println!(
        "SDK GPU time a frame at {}x{}, mean of {frames} frames:",
        size.x, size.y
    );
    let mut total = 0.0;
    for (label, ms) in sums {
        let mean = ms / frames as f64;
        total += mean;
        println!("  {label:<48} {mean:8.3} ms");
    }
    println!("  {:<48} {total:8.3} ms", "total");
}
