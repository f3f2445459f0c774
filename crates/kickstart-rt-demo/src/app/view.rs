//! `ksrt view`: a winit window on a scene, rendered by the same [`Renderer`] as `ksrt render`.
//!
//! Controls: hold the left mouse button and drag to look; W/A/S/D move, Q/E down/up, Shift
//! faster; 1–6 toggle specular, diffuse, AO, shadow, denoise, lidar; V cycles what is shown
//! (composite, direct, each channel, the SDK debug view); B cycles the SDK debug view (hit
//! distance, barycentrics, instance colours, lighting cache); Escape quits.
//!
//! Timings are shown in the **window title** (CPU frame time and the GPU time of each SDK task
//! of the last measured frame, refreshed twice a second): a text overlay would need a font
//! rasteriser for little gain. The same line goes to the log at `info` level.

use crate::app::frames::RendererExt;
use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use kickstart_rt as ksrt;
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::app::defaults::Resolver;
use kickstart_rt_renderer::composite::Show;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::frame::{Effects, EFFECT_NAMES};
use kickstart_rt_renderer::renderer::Renderer;
use kickstart_rt_renderer::scene::{Camera, Scene};

/// `ksrt view`'s options.
pub struct ViewArgs {
    /// Scene name or path.
    pub scene: String,
    /// Scenes folder.
    pub scenes_dir: PathBuf,
    /// Window size, `WIDTHxHEIGHT` (`None`: the adapter's default, [`crate::app::defaults`]).
    pub size: Option<String>,
    /// Effects at start (`--effects`).
    pub effects: String,
    /// Start camera (`--camera`).
    pub camera: Option<String>,
    /// Close after this many frames.
    pub frames: Option<u32>,
    /// Where to write the last frame when `frames` ends the run.
    pub screenshot: Option<PathBuf>,
}

/// The SDK debug views `B` cycles through.
const DEBUG_VIEWS: [ksrt::DebugOutputType; 4] = [
    ksrt::DebugOutputType::HitT,
    ksrt::DebugOutputType::Barycentrics,
    ksrt::DebugOutputType::RandomMeshColor,
    ksrt::DebugOutputType::DirectLightingCache,
];

/// A fly camera: position, yaw and pitch (radians; yaw 0 looks down −z).
struct FlyCamera {
    eye: Vec3,
    yaw: f32,
    pitch: f32,
    fov_y_deg: f32,
}

impl FlyCamera {
    fn from_camera(c: &Camera) -> FlyCamera {
        let d = (c.at - c.eye).normalize_or(Vec3::NEG_Z);
        FlyCamera {
            eye: c.eye,
            yaw: d.x.atan2(-d.z),
            pitch: d.y.clamp(-1.0, 1.0).asin(),
            fov_y_deg: c.fov_y_deg,
        }
    }

    fn forward(&self) -> Vec3 {
        Vec3::new(
            self.yaw.sin() * self.pitch.cos(),
            self.pitch.sin(),
            -self.yaw.cos() * self.pitch.cos(),
        )
    }

    fn camera(&self) -> Camera {
        Camera {
            eye: self.eye,
            at: self.eye + self.forward(),
            up: Vec3::Y,
            fov_y_deg: self.fov_y_deg,
        }
    }
}

struct Gpu {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    renderer: Renderer,
}

struct App {
    args: ViewArgs,
    scene: Scene,
    effects: Effects,
    fly: FlyCamera,
    gpu: Option<Gpu>,
    error: Option<String>,
    keys: HashSet<KeyCode>,
    looking: bool,
    last_cursor: Option<(f64, f64)>,
    last_frame: Instant,
    title_at: Instant,
    frame_ms: f32,
    show: usize,
    debug: usize,
    frames: u32,
    /// When the window's animation clock started: an animated scene plays its first animation
    /// from it, looping, whatever the frame rate.
    started: Instant,
}

/// Runs the viewer until the window closes (or `--frames` frames were drawn).
pub fn run(args: ViewArgs) -> AnyResult<()> {
    let size = match &args.size {
        Some(size) => crate::app::args::parse_size(size)?,
        None => {
            // The window's own adapter comes later, from its surface; the default one is the
            // same device wherever there is only one (a CPU device is no one's second choice).
            let info = crate::app::gpu::adapter()?.get_info();
            let mut picked = Resolver::new(crate::app::defaults::is_software(&info));
            let size = picked.pick(None, crate::app::defaults::VIEW_SIZE, "{v}", "--size");
            if let Some(notice) = picked.notice(&info) {
                eprintln!("{notice}");
            }
            crate::app::args::parse_size(size)?
        }
    };
    let effects = Effects::parse(&args.effects)?;
    let start = args
        .camera
        .as_deref()
        .map(kickstart_rt_renderer::scene::parse_camera)
        .transpose()?;
    let mut scene =
        crate::app::progress::with_spinner(true, format!("loading {}", args.scene), || {
            crate::app::scenes::load(&args.scene, &args.scenes_dir)
        })?;
    let fly = FlyCamera::from_camera(&scene.prepare_view(
        start.or_else(|| kickstart_rt_renderer::scene::benchmark_camera(&args.scene)),
    ));
    let event_loop = EventLoop::new().map_err(|e| {
        format!("ksrt view: cannot open a window ({e}); is there a display (DISPLAY, or Xvfb)?")
    })?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let mut app = App {
        args: ViewArgs {
            size: Some(format!("{}x{}", size.0, size.1)),
            ..args
        },
        scene,
        effects,
        fly,
        gpu: None,
        error: None,
        keys: HashSet::new(),
        looking: false,
        last_cursor: None,
        last_frame: Instant::now(),
        title_at: Instant::now(),
        frame_ms: 0.0,
        show: 0,
        debug: 0,
        frames: 0,
        started: Instant::now(),
    };
    event_loop.run_app(&mut app)?;
    match app.error {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

impl App {
    fn init(&mut self, event_loop: &ActiveEventLoop) -> AnyResult<Gpu> {
        let (w, h) = crate::app::args::parse_size(self.args.size.as_deref().unwrap_or_default())?;
        let attributes = Window::default_attributes()
            .with_title(format!("ksrt — {}", self.scene.name))
            .with_inner_size(winit::dpi::PhysicalSize::new(w, h));
        let window = Arc::new(event_loop.create_window(attributes)?);
        let mut desc = wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(
            event_loop.owned_display_handle(),
        ));
        if std::env::var_os("WGPU_BACKEND").is_none() {
            desc.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(desc);
        let surface = instance.create_surface(window.clone())?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            compatible_surface: Some(&surface),
            ..Default::default()
        }))
        .map_err(|e| format!("no GPU adapter can present to this window: {e}"))?;
        let (device, queue) = crate::app::gpu::device(&adapter)?;
        let caps = surface.get_capabilities(&adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| {
                matches!(
                    f,
                    wgpu::TextureFormat::Bgra8UnormSrgb | wgpu::TextureFormat::Rgba8UnormSrgb
                )
            })
            .or_else(|| caps.formats.first().copied())
            .ok_or("the window's surface offers no format")?;
        if !caps.usages.contains(wgpu::TextureUsages::COPY_DST) {
            return Err("the window's surface cannot be copied into (no COPY_DST usage)".into());
        }
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_DST,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes.first().copied().unwrap_or_default(),
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&device, &config);
        let renderer = self.make_renderer(&device, &queue, &config)?;
        log::info!(
            "ksrt view: WASD/QE move, drag to look, 1-6 toggle {}, V show, B debug view",
            EFFECT_NAMES.join("/")
        );
        Ok(Gpu {
            window,
            surface,
            device,
            queue,
            config,
            renderer,
        })
    }

    fn make_renderer(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        config: &wgpu::SurfaceConfiguration,
    ) -> AnyResult<Renderer> {
        let mut opts = crate::app::frames::renderer_options((config.width, config.height));
        opts.effects = self.effects;
        opts.gpu_timing = true;
        opts.ldr_format = config.format;
        let mut r = crate::app::frames::new_renderer(device, queue, &self.scene, &opts)?;
        r.show = Show::ALL[self.show % Show::ALL.len()];
        Ok(r)
    }

    fn key(&mut self, code: KeyCode, event_loop: &ActiveEventLoop) {
        let toggle = match code {
            KeyCode::Digit1 => Some("specular"),
            KeyCode::Digit2 => Some("diffuse"),
            KeyCode::Digit3 => Some("ao"),
            KeyCode::Digit4 => Some("shadow"),
            KeyCode::Digit5 => Some("denoise"),
            KeyCode::Digit6 => Some("lidar"),
            _ => None,
        };
        if let Some(name) = toggle {
            if let Some(f) = self.effects.flag(name) {
                *f = !*f;
                log::info!("{name}: {}", if *f { "on" } else { "off" });
            }
        }
        let Some(gpu) = self.gpu.as_mut() else {
            return;
        };
        if toggle.is_some() {
            gpu.renderer.sdk.effects = self.effects;
            // The denoisers' history was made with the other set of inputs.
            gpu.renderer.cut();
        }
        match code {
            KeyCode::KeyV => {
                self.show = (self.show + 1) % Show::ALL.len();
                gpu.renderer.show = Show::ALL[self.show];
                if gpu.renderer.show == Show::Debug {
                    gpu.renderer.sdk.debug_view = Some(DEBUG_VIEWS[self.debug]);
                }
                log::info!("showing {:?}", gpu.renderer.show);
            }
            KeyCode::KeyB => {
                self.debug = (self.debug + 1) % DEBUG_VIEWS.len();
                gpu.renderer.sdk.debug_view = Some(DEBUG_VIEWS[self.debug]);
                gpu.renderer.show = Show::Debug;
                self.show = Show::ALL.len() - 1;
                log::info!("debug view {:?}", DEBUG_VIEWS[self.debug]);
            }
            KeyCode::Escape => event_loop.exit(),
            _ => {}
        }
    }

    fn update_camera(&mut self, dt: f32) {
        let speed = self.scene.size()
            * 0.15
            * if self.keys.contains(&KeyCode::ShiftLeft) {
                4.0
            } else {
                1.0
            };
        let f = self.fly.forward();
        let right = f.cross(Vec3::Y).normalize_or(Vec3::X);
        let mut m = Vec3::ZERO;
        for (k, d) in [
            (KeyCode::KeyW, f),
            (KeyCode::KeyS, -f),
            (KeyCode::KeyD, right),
            (KeyCode::KeyA, -right),
            (KeyCode::KeyE, Vec3::Y),
            (KeyCode::KeyQ, Vec3::NEG_Y),
        ] {
            if self.keys.contains(&k) {
                m += d;
            }
        }
        self.fly.eye += m.normalize_or_zero() * speed * dt;
    }

    fn redraw(&mut self, event_loop: &ActiveEventLoop) -> AnyResult<()> {
        let now = Instant::now();
        let dt = (now - self.last_frame).as_secs_f32().min(0.1);
        self.last_frame = now;
        self.frame_ms = self.frame_ms * 0.9 + dt * 1000.0 * 0.1;
        self.update_camera(dt);
        let camera = self.fly.camera();
        let measure = now >= self.title_at;
        let last = self.args.frames.is_some_and(|n| self.frames + 1 >= n);
        let Some(gpu) = self.gpu.as_mut() else {
            return Ok(());
        };
        let frame = match gpu.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                gpu.surface.configure(&gpu.device, &gpu.config);
                return Ok(());
            }
            other => {
                log::debug!("no surface texture this frame: {other:?}");
                return Ok(());
            }
        };
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ksrt view frame"),
            });
        // Wrapped in f64 first, so that an f32 time keeps its precision after hours of play.
        let duration = f64::from(self.scene.animation_duration());
        if duration > 0.0 {
            let t = (now - self.started).as_secs_f64().rem_euclid(duration);
            gpu.renderer.set_time(t as f32);
        }
        let tasks = gpu
            .renderer
            .record_frame(&gpu.device, &gpu.queue, &mut encoder, &camera)?;
        encoder.copy_texture_to_texture(
            gpu.renderer.ldr.as_image_copy(),
            frame.texture.as_image_copy(),
            wgpu::Extent3d {
                width: gpu.config.width.min(gpu.renderer.ldr.width()),
                height: gpu.config.height.min(gpu.renderer.ldr.height()),
                depth_or_array_layers: 1,
            },
        );
        gpu.queue.submit([encoder.finish()]);
        let timings = gpu.renderer.finish(&gpu.device, &tasks, measure)?;
        gpu.window.pre_present_notify();
        gpu.queue.present(frame);
        self.frames += 1;
        if measure {
            self.title_at = now + Duration::from_millis(500);
            let mut title = title(
                &self.scene.name,
                self.frame_ms,
                &self.effects,
                timings.as_ref(),
            );
            if !gpu.renderer.sdk.refused.is_empty() {
                title += &format!(" — unsupported by this SDK: {:?}", gpu.renderer.sdk.refused);
            }
            log::info!("{title}");
            gpu.window.set_title(&title);
        }
        if last {
            if let Some(path) = &self.args.screenshot {
                let t =
                    crate::app::readback::read_texture(&gpu.device, &gpu.queue, &gpu.renderer.ldr)?;
                crate::app::readback::to_png(&t, crate::app::readback::Encoding::Display)
                    .save(path)
                    .map_err(|e| format!("--screenshot {}: {e}", path.display()))?;
                println!("wrote {} after {} frames", path.display(), self.frames);
            }
            event_loop.exit();
        }
        Ok(())
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: impl std::fmt::Display) {
        self.error = Some(e.to_string());
        event_loop.exit();
    }
}

/// The window title: scene, frame time, effects on, and the GPU milliseconds of each SDK task.
fn title(scene: &str, frame_ms: f32, effects: &Effects, t: Option<&ksrt::GpuTimings>) -> String {
    let mut e = *effects;
    let on: Vec<&str> = EFFECT_NAMES
        .iter()
        .copied()
        .filter(|n| e.flag(n).is_some_and(|f| *f))
        .collect();
    let mut s = format!(
        "ksrt — {scene} — {frame_ms:.1} ms/frame — [{}]",
        on.join(" ")
    );
    if let Some(t) = t {
        let mut labels: Vec<&str> = Vec::new();
        for p in &t.passes {
            if !labels.contains(&p.label) {
                labels.push(p.label);
            }
        }
        for l in labels {
            s += &format!(" | {l} {:.2}", t.sum_ms(&[l]));
        }
        s += " ms (GPU)";
    }
    s
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gpu.is_some() {
            return;
        }
        match self.init(event_loop) {
            Ok(g) => {
                g.window.request_redraw();
                self.gpu = Some(g);
            }
            Err(e) => self.fail(event_loop, e),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) if size.width > 0 && size.height > 0 => {
                let result = match self.gpu.as_ref() {
                    Some(g) => {
                        let mut config = g.config.clone();
                        config.width = size.width;
                        config.height = size.height;
                        g.surface.configure(&g.device, &config);
                        self.make_renderer(&g.device, &g.queue, &config)
                            .map(|r| (r, config))
                    }
                    None => return,
                };
                match result {
                    Ok((r, config)) => {
                        if let Some(g) = self.gpu.as_mut() {
                            g.renderer = r;
                            g.config = config;
                        }
                    }
                    Err(e) => self.fail(event_loop, e),
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    match event.state {
                        ElementState::Pressed => {
                            if !event.repeat {
                                self.key(code, event_loop);
                            }
                            self.keys.insert(code);
                        }
                        ElementState::Released => {
                            self.keys.remove(&code);
                        }
                    }
                }
            }
            WindowEvent::MouseInput {
                button: MouseButton::Left,
                state,
                ..
            } => {
                self.looking = state == ElementState::Pressed;
                self.last_cursor = None;
            }
            WindowEvent::CursorMoved { position, .. } if self.looking => {
                if let Some((x, y)) = self.last_cursor {
                    self.fly.yaw += (position.x - x) as f32 * 0.004;
                    self.fly.pitch =
                        (self.fly.pitch - (position.y - y) as f32 * 0.004).clamp(-1.55, 1.55);
                }
                self.last_cursor = Some((position.x, position.y));
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw(event_loop) {
                    self.fail(event_loop, e);
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(g) = &self.gpu {
            g.window.request_redraw();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fly_camera_keeps_the_start_view_direction() {
        let c = Camera {
            eye: Vec3::new(1.0, 2.0, 3.0),
            at: Vec3::new(4.0, 0.0, -1.0),
            up: Vec3::Y,
            fov_y_deg: 45.0,
        };
        let f = FlyCamera::from_camera(&c);
        let want = (c.at - c.eye).normalize();
        assert!((f.forward() - want).length() < 1e-5, "{}", f.forward());
        assert_eq!(f.camera().eye, c.eye);
    }
}
