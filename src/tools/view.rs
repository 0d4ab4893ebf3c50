//! `verdant view`: a window on a world, drawn by a [`Renderer`] into the window's surface.
//!
//! Keys: drag with the left mouse button to look around; W A S D fly, Q and E down and up,
//! Shift four times faster, the mouse wheel (or `+` and `-`) sets the speed; P follows the
//! manifest's camera path (again to fly free from there), N takes the next path; 1 to 9 choose
//! the manifest's wind scenes; L shows the tile levels and grass rings; T steps through the
//! anti-aliasing methods; V switches vsync; Escape quits. Live figures (frame time, GPU time per pass, blades drawn, tiles resident) are
//! in the window's title.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use glam::DVec3;
use winit::application::ApplicationHandler;
use winit::event::{DeviceEvent, ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::camera::{Camera, sample_path, walker_at};
use crate::gpu::GpuContext;
use crate::renderer::{FrameInput, FrameStats, Renderer, RendererConfig, RendererOptions};
use crate::stream::ServiceConfig;
use crate::world::{CameraPath, World};

/// What `verdant view` is asked to do.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// The world's folder, or its `http://` address.
    pub world: PathBuf,
    /// How a world over HTTP is fetched.
    pub http: crate::stream::HttpOptions,
    /// Inner size of the window.
    pub size: (u32, u32),
    /// Wait for the display's refresh (vsync) or not.
    pub vsync: bool,
    /// The camera path to start on (and to follow with P); the manifest's first when `None`.
    pub path: Option<String>,
    /// Follow the path from the start.
    pub follow: bool,
    /// Render this many frames (at a fixed 1/60 s step, standing still unless following) and
    /// exit.
    pub frames: Option<u32>,
    /// Write the last frame to this PNG file (with `frames`).
    pub screenshot: Option<PathBuf>,
    /// Limits of the tile service; `atlas_slots` [`super::WORLD_ATLAS_SLOTS`] sizes the atlas to
    /// the world.
    pub service: ServiceConfig,
    /// Wind scene to start with (default: the path's wind keys, else `breeze`).
    pub wind_scene: Option<String>,
    /// Anti-aliasing to start with (default: the renderer's); T cycles through the methods.
    pub aa: Option<crate::aa::AntiAliasing>,
    /// Ends the view at its next frame once set (Ctrl-C, SIGTERM): a session as the window's
    /// closing does, a run of N frames with [`ViewSummary::stopped`].
    pub stop: Option<crate::bake::CancelFlag>,
}

/// What a run of [`ViewOptions::frames`] frames measured (a session the user ends reports
/// nothing: its frames are 0).
#[derive(Clone, Debug, Default)]
pub struct ViewSummary {
    /// Frames drawn.
    pub frames: u64,
    /// Median wall time between frames, milliseconds.
    pub median_frame_ms: f64,
    /// The adapter, backend and driver.
    pub adapter: String,
    /// The camera path the view started on (at its first key).
    pub path: String,
    /// The most terrain tiles a frame drew (0: no frame drew any terrain, see
    /// [`super::fly::no_terrain_drawn`]).
    pub tiles_drawn_max: u32,
    /// Whether a run of N frames was stopped ([`ViewOptions::stop`]) before its last frame:
    /// `frames` were drawn, and no screenshot was written.
    pub stopped: bool,
}

/// Opens the window and runs until it is closed (or `frames` are drawn).
pub fn run_view(opts: ViewOptions) -> Result<ViewSummary> {
    crate::tools::options::check_size("--size", opts.size)?;
    if let Some(n) = opts.frames {
        crate::tools::options::check_range("--frames", n, 1..=u32::MAX, "")?;
    }
    if opts.screenshot.is_some() && opts.frames.is_none() {
        bail!("--screenshot needs --frames N (the frame to capture)");
    }
    if let Some(file) = &opts.screenshot {
        check_screenshot(file)?;
    }
    let (world, source) = crate::tools::open_world(&opts.world, &opts.http)?;
    let stop = crate::tools::stop::Stop::new(opts.stop.clone());
    if stop.requested() {
        // Stopped while the world opened (over HTTP, say): nothing drawn.
        return Ok(ViewSummary {
            stopped: opts.frames.is_some(),
            ..ViewSummary::default()
        });
    }
    if opts.path.is_some() {
        crate::tools::camera_path(&world, &opts.world, opts.path.as_deref())?;
    }
    crate::tools::check_wind_option(&world, opts.wind_scene.as_deref())?;
    let no_display = std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty())
        && std::env::var_os("WAYLAND_DISPLAY").is_none_or(|d| d.is_empty());
    let hint = "`verdant view` needs a desktop session (X11 or Wayland); for a headless run \
                use `verdant fly`";
    if no_display {
        bail!("no display to open a window on: DISPLAY and WAYLAND_DISPLAY are not set. {hint}");
    }
    let Ok(event_loop) = EventLoop::new() else {
        bail!("cannot connect to the display named by DISPLAY or WAYLAND_DISPLAY. {hint}");
    };
    let mut app = Viewer {
        opts,
        stop,
        world: Some((world, source)),
        state: None,
        error: None,
        summary: ViewSummary::default(),
    };
    event_loop
        .run_app(&mut app)
        .context("the window's event loop failed")?;
    if let Some(e) = app.error {
        return Err(e);
    }
    let drawn = app.state.as_ref().map_or(0, |s| s.frames);
    let stopped = app.stop.requested();
    if let Some(n) = app.opts.frames
        && app.summary.frames < u64::from(n)
        && stopped
    {
        // Stopped by a signal: said by the caller, as every run stopped so is.
        return Ok(ViewSummary {
            frames: drawn,
            stopped: true,
            ..app.summary
        });
    }
    // A run of N frames whose window was closed (or Escape pressed) before the last.
    if let Some(n) = app.opts.frames
        && app.summary.frames < u64::from(n)
    {
        let shot = app.opts.screenshot.as_ref().map_or(String::new(), |f| {
            format!("; {} was not written", f.display())
        });
        bail!("the window was closed after {drawn} of {n} frames{shot}");
    }
    Ok(app.summary)
}

struct Viewer {
    opts: ViewOptions,
    /// [`ViewOptions::stop`], looked at before each frame and event.
    stop: crate::tools::stop::Stop,
    world: Option<(World, std::sync::Arc<dyn crate::stream::TileSource>)>,
    state: Option<State>,
    error: Option<anyhow::Error>,
    summary: ViewSummary,
}

/// The flying camera and what the keys hold down.
#[derive(Default)]
struct Controls {
    forward: f64,
    right: f64,
    up: f64,
    fast: bool,
    dragging: bool,
}

struct State {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ctx: GpuContext,
    renderer: Renderer,
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    paths: Vec<CameraPath>,
    path_index: usize,
    following: bool,
    path_t: f64,
    position: DVec3,
    yaw_deg: f64,
    pitch_deg: f64,
    speed_mps: f64,
    controls: Controls,
    overlay: bool,
    time_s: f64,
    last_frame: Instant,
    frame_times_ms: Vec<f64>,
    frames: u64,
    title_at: Instant,
    last_stats: Option<FrameStats>,
    /// The most terrain tiles a frame drew, over the frames whose figures have come back.
    tiles_drawn_max: u32,
    wind_scene: String,
    /// Whether the window is larger than the renderer draws (past the device's largest
    /// texture or the renderer's pixels): drawing pauses until it fits again.
    too_large: bool,
}

fn depth_target(device: &wgpu::Device, width: u32, height: u32) -> wgpu::Texture {
    crate::gpu::target_texture(
        device,
        "viewer depth",
        crate::terrain::DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        (width, height),
    )
}

/// How long an interactive window waits for its first frame's tiles before it opens on what has
/// come (a local world's take well under a second).
const INTERACTIVE_WARM_UP: Duration = Duration::from_secs(2);

impl Viewer {
    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<State> {
        let (world, source) = self.world.take().context("the viewer started twice")?;
        let (w, h) = self.opts.size;
        let attrs = Window::default_attributes()
            .with_title(format!("verdant: {}", world.manifest.name))
            .with_inner_size(winit::dpi::PhysicalSize::new(w, h));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .context("cannot open a window")?,
        );
        let instance = GpuContext::instance(None);
        let surface = instance
            .create_surface(window.clone())
            .context("cannot draw into the window")?;
        let ctx = pollster::block_on(GpuContext::open(instance, Some(&surface)))?;
        let size = window.inner_size();
        let (w, h) = (size.width.max(1), size.height.max(1));
        let caps = surface.get_capabilities(&ctx.adapter);
        // Prefer an sRGB format; the renderer encodes for plain unorm ones itself.
        let format = caps
            .formats
            .iter()
            .copied()
            .filter(|f| crate::shaders::encode_srgb_for(*f).is_some())
            .min_by_key(|f| !f.is_srgb())
            .with_context(|| {
                format!(
                    "the window offers no colour format the renderer draws into ({:?})",
                    caps.formats
                )
            })?;
        let mut usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
        if self.opts.screenshot.is_some() {
            if !caps.usages.contains(wgpu::TextureUsages::COPY_SRC) {
                bail!("this window's surface cannot be read back for --screenshot");
            }
            usage |= wgpu::TextureUsages::COPY_SRC;
        }
        let mut config = surface
            .get_default_config(&ctx.adapter, w, h)
            .context("the window's surface does not work with this adapter")?;
        config.usage = usage;
        config.format = format;
        config.present_mode = present_mode(&caps, self.opts.vsync);
        config.desired_maximum_frame_latency = 2;
        configure(&surface, &ctx.device, &config)?;

        let paths = paths_of(&world);
        let path_index = match &self.opts.path {
            Some(name) => paths.iter().position(|p| &p.name == name).unwrap_or(0),
            None => 0,
        };
        let path = &paths[path_index];
        let mut rc = RendererConfig::for_world(&world);
        rc.service = super::service_over(self.opts.service, &rc);
        rc.wind_scene = self.opts.wind_scene.clone();
        if let Some(aa) = self.opts.aa {
            rc.aa = aa;
        }
        if rc.wind_scene.is_none() {
            rc.wind_keys = path.wind.clone();
        }
        let mut options = RendererOptions::new(&world, format, crate::terrain::DEPTH_FORMAT, w, h);
        options.config = rc;
        let mut renderer = Renderer::with_source(&ctx.device, &ctx.queue, world, source, options)?;
        let t0 = path.start_s();
        let start = sample_path(path, t0);
        // A run of N frames (a screenshot, say) starts complete, as `fly` does. A window the
        // user flies waits for its first frame's tiles only briefly: over a slow network the
        // window would not answer for the whole wait; it opens on what has come (the coarser
        // tiles drawing the finer ones) and streaming shows.
        let interactive = self.opts.frames.is_none();
        let wait = if interactive {
            INTERACTIVE_WARM_UP
        } else {
            Duration::from_secs(30)
        };
        let warm_up = renderer.warm_up_report(&start, wait)?;
        let streamed = crate::tools::fly::check_streaming(
            &self.opts.world,
            &renderer.world().manifest.pyramid,
            &renderer.service().stats(),
            &warm_up,
        );
        // Tiles kept out by a failed load, not merely still on their way.
        let failed = warm_up
            .missing
            .iter()
            .any(|m| renderer.service().blocked_by(m.tile).is_some());
        match streamed {
            // A run of N frames would show the coarsest tiles only.
            Err(e) if !interactive => return Err(e.into()),
            Err(e) if failed => log::warn!("{e}"),
            _ if !warm_up.missing.is_empty() && !failed => log::info!(
                "the window opens with {} of the first frame's tiles still loading; they \
                 stream in as it draws",
                warm_up.missing.len()
            ),
            _ => {}
        }
        let depth = depth_target(&ctx.device, w, h);
        let wind_scene = renderer.wind_scene_at(0.0);
        Ok(State {
            depth_view: depth.create_view(&Default::default()),
            depth,
            window,
            surface,
            config,
            ctx,
            renderer,
            paths,
            path_index,
            following: self.opts.follow,
            path_t: t0,
            position: start.position,
            yaw_deg: start.yaw_deg,
            pitch_deg: start.pitch_deg,
            speed_mps: 20.0,
            controls: Controls::default(),
            overlay: false,
            time_s: 0.0,
            last_frame: Instant::now(),
            frame_times_ms: Vec::new(),
            frames: 0,
            title_at: Instant::now(),
            last_stats: None,
            tiles_drawn_max: 0,
            wind_scene,
            too_large: false,
        })
    }

    /// Ends the run with `e`, or with the first error if one came before (a frame already
    /// asked for may fail after it, for the same cause).
    fn fail(&mut self, event_loop: &ActiveEventLoop, e: anyhow::Error) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }
}

/// Configures `surface` as `config` says, an error (a display that went away, say) returned
/// rather than raised as a panic by wgpu's default handler.
fn configure(
    surface: &wgpu::Surface<'_>,
    device: &wgpu::Device,
    config: &wgpu::SurfaceConfiguration,
) -> Result<()> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    surface.configure(device, config);
    match pollster::block_on(scope.pop()) {
        None => Ok(()),
        Some(e) => {
            bail!("the window's surface could not be configured (was the display closed?): {e}")
        }
    }
}

fn present_mode(caps: &wgpu::SurfaceCapabilities, vsync: bool) -> wgpu::PresentMode {
    use wgpu::PresentMode as P;
    let wanted: &[P] = if vsync {
        &[P::Fifo]
    } else {
        &[P::Immediate, P::Mailbox, P::Fifo]
    };
    wanted
        .iter()
        .copied()
        .find(|m| caps.present_modes.contains(m))
        .unwrap_or(caps.present_modes[0])
}

impl ApplicationHandler for Viewer {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        // A stop asked for while the world opened, or while the first tiles came in.
        if self.stop.requested() {
            event_loop.exit();
            return;
        }
        match self.start(event_loop) {
            Ok(s) => {
                s.window.request_redraw();
                self.state = Some(s);
                if self.stop.requested() {
                    event_loop.exit();
                }
            }
            Err(e) => self.fail(event_loop, e),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        // Nothing more is drawn once a stop is asked for (the display may be going with it).
        if self.stop.requested() {
            event_loop.exit();
            return;
        }
        let Some(s) = &mut self.state else { return };
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) if size.width > 0 && size.height > 0 => {
                let (width, height) = (size.width, size.height);
                // The renderer first: a size it cannot draw leaves it, the surface and the
                // depth target as they were.
                match s.renderer.resize(width, height) {
                    Ok(()) => {
                        s.too_large = false;
                        s.config.width = width;
                        s.config.height = height;
                        if let Err(e) = configure(&s.surface, &s.ctx.device, &s.config) {
                            self.fail(event_loop, e);
                            return;
                        }
                        s.depth = depth_target(&s.ctx.device, width, height);
                        s.depth_view = s.depth.create_view(&Default::default());
                    }
                    // A session: drawing pauses until the window is made smaller.
                    Err(e) if self.opts.frames.is_none() => {
                        if !s.too_large {
                            log::warn!(
                                "the window is {width}x{height}, larger than verdant draws \
                                 ({e}); drawing pauses until it is made smaller"
                            );
                        }
                        s.too_large = true;
                        s.window.set_title(&format!(
                            "verdant: the window is too large to draw ({width}x{height}); \
                             make it smaller"
                        ));
                    }
                    // A run of N frames cannot draw them at the size asked.
                    Err(e) => self.fail(
                        event_loop,
                        anyhow::Error::new(e)
                            .context(format!("the window was resized to {width}x{height}")),
                    ),
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                let down = event.state == ElementState::Pressed;
                if let PhysicalKey::Code(code) = event.physical_key
                    && let Err(e) = s.key(code, down, event.repeat)
                {
                    self.fail(event_loop, e);
                    return;
                }
                if down && event.physical_key == PhysicalKey::Code(KeyCode::Escape) {
                    event_loop.exit();
                }
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                s.controls.dragging = state == ElementState::Pressed;
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => f64::from(y),
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                s.speed_mps = (s.speed_mps * 1.25f64.powf(steps)).clamp(1.0, 2000.0);
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw(event_loop) {
                    self.fail(event_loop, e);
                }
            }
            _ => {}
        }
    }

    fn device_event(
        &mut self,
        _event_loop: &ActiveEventLoop,
        _id: winit::event::DeviceId,
        event: DeviceEvent,
    ) {
        let Some(s) = &mut self.state else { return };
        if let DeviceEvent::MouseMotion { delta } = event
            && s.controls.dragging
            && !s.following
        {
            s.yaw_deg -= delta.0 * 0.15;
            s.pitch_deg = (s.pitch_deg - delta.1 * 0.15).clamp(-89.0, 89.0);
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if self.stop.requested() {
            event_loop.exit();
            return;
        }
        if self.opts.stop.is_some() {
            // The loop wakes now and then to look, even while it draws nothing.
            event_loop.set_control_flow(winit::event_loop::ControlFlow::wait_duration(
                std::time::Duration::from_millis(100),
            ));
        }
        // Nothing is drawn while the window is too large: the loop waits for its next resize.
        if let Some(s) = &self.state
            && !s.too_large
        {
            s.window.request_redraw();
        }
    }
}

impl State {
    fn key(&mut self, code: KeyCode, down: bool, repeat: bool) -> Result<()> {
        let amount = if down { 1.0 } else { 0.0 };
        match code {
            KeyCode::KeyW => self.controls.forward = amount,
            KeyCode::KeyS => self.controls.forward = -amount,
            KeyCode::KeyD => self.controls.right = amount,
            KeyCode::KeyA => self.controls.right = -amount,
            KeyCode::KeyE => self.controls.up = amount,
            KeyCode::KeyQ => self.controls.up = -amount,
            KeyCode::ShiftLeft | KeyCode::ShiftRight => self.controls.fast = down,
            _ if !down || repeat => {}
            KeyCode::Equal | KeyCode::NumpadAdd => {
                self.speed_mps = (self.speed_mps * 1.5).min(2000.0)
            }
            KeyCode::Minus | KeyCode::NumpadSubtract => {
                self.speed_mps = (self.speed_mps / 1.5).max(1.0);
            }
            KeyCode::KeyP => {
                self.following = !self.following;
                if self.following {
                    // Pick the path up where it is nearest the camera's time on it.
                    self.path_t = self.path_t.max(self.paths[self.path_index].start_s());
                }
            }
            KeyCode::KeyN => {
                self.path_index = (self.path_index + 1) % self.paths.len();
                self.path_t = self.paths[self.path_index].start_s();
            }
            KeyCode::KeyL => {
                self.overlay = !self.overlay;
                self.renderer.set_overlay(self.overlay);
            }
            KeyCode::KeyT => {
                use crate::aa::AntiAliasing;
                let all = AntiAliasing::ALL;
                let now = self.renderer.anti_aliasing();
                let i = all.iter().position(|&m| m == now).unwrap_or(0);
                if let Err(e) = self.renderer.set_anti_aliasing(all[(i + 1) % all.len()]) {
                    log::warn!("{e}");
                }
            }
            KeyCode::KeyV => {
                let vsync = self.config.present_mode != wgpu::PresentMode::Fifo;
                let caps = self.surface.get_capabilities(&self.ctx.adapter);
                self.config.present_mode = present_mode(&caps, vsync);
                configure(&self.surface, &self.ctx.device, &self.config)?;
            }
            KeyCode::Digit1
            | KeyCode::Digit2
            | KeyCode::Digit3
            | KeyCode::Digit4
            | KeyCode::Digit5
            | KeyCode::Digit6
            | KeyCode::Digit7
            | KeyCode::Digit8
            | KeyCode::Digit9 => {
                let i = code as usize - KeyCode::Digit1 as usize;
                let scenes = &self.renderer.world().manifest.wind_scenes;
                if let Some(scene) = scenes.get(i) {
                    let name = scene.name.clone();
                    self.renderer.change_wind_scene(&name, self.time_s, 3.0)?;
                    self.wind_scene = name;
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn camera(&mut self, dt: f64) -> (Camera, Option<glam::DVec2>) {
        let path = &self.paths[self.path_index];
        if self.following {
            let (t0, t1) = (path.start_s(), path.end_s());
            self.path_t += dt;
            if self.path_t > t1 {
                self.path_t = t0 + (self.path_t - t1) % (t1 - t0).max(1e-3);
            }
            let c = sample_path(path, self.path_t);
            (self.position, self.yaw_deg, self.pitch_deg) = (c.position, c.yaw_deg, c.pitch_deg);
            let walker = walker_at(&self.renderer.world().manifest, path, self.path_t);
            return (c, Some(walker));
        }
        let c = Camera::new(self.position, self.yaw_deg, self.pitch_deg);
        let forward = c.forward();
        let right = forward.cross(DVec3::Z).normalize_or(DVec3::X);
        let boost = if self.controls.fast { 4.0 } else { 1.0 };
        let step = (forward * self.controls.forward
            + right * self.controls.right
            + DVec3::Z * self.controls.up)
            * self.speed_mps
            * boost
            * dt;
        self.position += step;
        let c = Camera::new(self.position, self.yaw_deg, self.pitch_deg);
        (c, Some(self.position.truncate()))
    }

    fn update_title(&mut self) {
        if self.title_at.elapsed() < Duration::from_millis(500) {
            return;
        }
        self.title_at = Instant::now();
        let n = self.frame_times_ms.len().min(60);
        let recent = &self.frame_times_ms[self.frame_times_ms.len() - n..];
        let mut sorted = recent.to_vec();
        sorted.sort_by(f64::total_cmp);
        // No time between frames yet: no frame time to show.
        let timing = match sorted.get(n / 2) {
            Some(&ms) => format!("{ms:.1} ms ({:.0} fps)", 1e3 / ms.max(1e-3)),
            None => "first frame".to_owned(),
        };
        let mut title = format!(
            "verdant: {} | {timing}",
            self.renderer.world().manifest.name
        );
        if let Some(st) = &self.last_stats {
            let gpu: f64 = st.gpu.iter().map(|(_, t)| t).sum();
            let passes: Vec<String> = st
                .gpu
                .iter()
                .map(|(name, t)| format!("{name} {t:.2}"))
                .collect();
            let blades = st.grass.drawn[0] + st.grass.drawn[1];
            title.push_str(&format!(
                " | GPU {gpu:.2} ms: {} | {blades} blades | tiles {}/{}",
                passes.join(", "),
                st.residency.resident,
                st.residency.desired,
            ));
        }
        title.push_str(&format!(
            " | {} {:.0} m/s | wind {} | aa {}{}",
            if self.following { "path" } else { "free" },
            self.speed_mps,
            self.wind_scene,
            self.renderer.anti_aliasing(),
            if self.overlay { " | overlay" } else { "" }
        ));
        self.window.set_title(&title);
    }
}

impl Viewer {
    fn redraw(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let Some(s) = &mut self.state else {
            return Ok(());
        };
        if s.too_large {
            return Ok(());
        }
        let now = Instant::now();
        let wall_ms = now.duration_since(s.last_frame).as_secs_f64() * 1e3;
        s.last_frame = now;
        if s.frames > 0 {
            s.frame_times_ms.push(wall_ms);
            if s.frame_times_ms.len() > 4096 {
                s.frame_times_ms.drain(..2048);
            }
        }
        // A fixed step when a run of N frames is asked for, so that it can be reproduced.
        let dt = match self.opts.frames {
            Some(_) => 1.0 / 60.0,
            None => (wall_ms / 1e3).min(0.25),
        };
        let (camera, walker) = s.camera(dt);
        s.time_s += dt;
        let input = FrameInput {
            jitter_px: glam::Vec2::ZERO,
            camera,
            time_s: s.time_s,
            walker,
        };
        s.renderer.prepare(&s.ctx.queue, &input);
        let frame = match s.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                configure(&s.surface, &s.ctx.device, &s.config)?;
                return Ok(());
            }
            _ => return Ok(()), // timed out or occluded: try the next frame
        };
        let view = frame.texture.create_view(&Default::default());
        let mut encoder = s.ctx.device.create_command_encoder(&Default::default());
        s.renderer.record(&mut encoder, &view, &s.depth_view)?;
        let last = self
            .opts
            .frames
            .is_some_and(|n| s.frames + 1 >= u64::from(n));
        let submission = s.ctx.queue.submit([encoder.finish()]);
        if last && let Some(file) = &self.opts.screenshot {
            save_screenshot(&s.ctx, &frame.texture, file)?;
        }
        s.window.pre_present_notify();
        s.ctx.queue.present(frame);
        s.frames += 1;
        if last {
            // Every frame's figures, the last ones included, before the summary.
            let _ = s.ctx.device.poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: None,
            });
        }
        for st in s.renderer.take_stats() {
            s.tiles_drawn_max = s.tiles_drawn_max.max(st.tiles_drawn);
            s.last_stats = Some(st);
        }
        s.update_title();
        if last {
            let mut sorted = s.frame_times_ms.clone();
            sorted.sort_by(f64::total_cmp);
            self.summary = ViewSummary {
                frames: s.frames,
                median_frame_ms: sorted.get(sorted.len() / 2).copied().unwrap_or(0.0),
                adapter: s.ctx.describe(),
                path: s.paths[s.path_index].name.clone(),
                tiles_drawn_max: s.tiles_drawn_max,
                stopped: false,
            };
            event_loop.exit();
        }
        Ok(())
    }
}

/// Checks `--screenshot FILE` before anything is drawn: a `.png` in an existing folder that is
/// in no world (a world's folder or any folder below it), and, where the file exists already,
/// one that a run may write over ([`crate::tools::output::not_an_output`]: an 8-bit RGB or RGBA
/// PNG without a JSON sidecar beside it), never a file of another kind: not a DEM or a map.
fn check_screenshot(file: &Path) -> Result<()> {
    let shown = file.display();
    let trailing_slash = file.as_os_str().as_encoded_bytes().ends_with(b"/");
    if trailing_slash
        || !file
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        bail!("--screenshot {shown}: must name a .png file");
    }
    let parent = match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if parent.exists() && !parent.is_dir() {
        bail!("--screenshot {shown}: {} is not a folder", parent.display());
    }
    if !parent.is_dir() {
        bail!(
            "--screenshot {shown}: the folder {} does not exist",
            parent.display()
        );
    }
    if let Some(why) = crate::world::format::refused_output(parent) {
        bail!("--screenshot {shown}: its folder is {why}; write the screenshot elsewhere");
    }
    let resolved = crate::world::format::resolve_lexically(parent)
        .ok()
        .flatten();
    if let Some(world) = resolved
        .iter()
        .flat_map(|p| p.ancestors())
        .find(|a| a.join("world.toml").is_file())
    {
        bail!(
            "--screenshot {shown}: its folder is inside the world {}; write the screenshot \
             elsewhere",
            world.display()
        );
    }
    if file.is_dir() {
        bail!("--screenshot {shown}: is a folder");
    }
    match crate::tools::output::not_an_output(file) {
        None => Ok(()),
        Some(why) => bail!(
            "--screenshot {shown}: exists and {why}; a screenshot replaces only an earlier \
             screenshot"
        ),
    }
}

/// Writes the window's current image (an RGBA or BGRA 8-bit texture) to a PNG file.
fn save_screenshot(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    file: &std::path::Path,
) -> Result<()> {
    let mut pixels = crate::gpu::read_texture_rgba8(&ctx.device, &ctx.queue, texture)
        .context("cannot read the window's image back")?;
    let bgra = matches!(
        texture.format(),
        wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
    );
    for px in pixels.chunks_exact_mut(4) {
        if bgra {
            px.swap(0, 2);
        }
        px[3] = 255;
    }
    let img = image::RgbaImage::from_raw(texture.width(), texture.height(), pixels)
        .context("screenshot size")?;
    crate::tools::output::write_png(file, &img).context("cannot write the screenshot")?;
    Ok(())
}

/// The camera paths the viewer follows (P, N): the world's, or where it has none (a world
/// written by hand), one of its own, `overview`: the world's centre from above its highest
/// point, looking north and down.
fn paths_of(world: &World) -> Vec<crate::world::CameraPath> {
    let m = &world.manifest;
    if !m.paths.is_empty() {
        return m.paths.clone();
    }
    let at = |t_s: f64| crate::world::CameraKey {
        t_s,
        position_m: [
            0.5 * m.extent_m[0],
            0.5 * m.extent_m[1],
            f64::from(m.height_range_m[1]) + 30.0,
        ],
        yaw_deg: 90.0,
        pitch_deg: -20.0,
    };
    vec![crate::world::CameraPath::through(
        "overview",
        vec![at(0.0), at(10.0)],
    )]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A world without camera paths is viewed from above its centre; one with paths by them.
    #[test]
    fn a_world_without_camera_paths_is_viewed_from_above_its_centre() {
        let mut world =
            World::open(&Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz")).unwrap();
        let named: Vec<String> = paths_of(&world).into_iter().map(|p| p.name).collect();
        let theirs: Vec<String> = world
            .manifest
            .paths
            .iter()
            .map(|p| p.name.clone())
            .collect();
        assert_eq!(named, theirs);
        world.manifest.paths.clear();
        let paths = paths_of(&world);
        assert_eq!(paths.len(), 1);
        let path = &paths[0];
        assert_eq!(path.name, "overview");
        assert!(path.length_s() > 0.0);
        let m = &world.manifest;
        let c = sample_path(path, path.start_s());
        assert!((c.position.x - 0.5 * m.extent_m[0]).abs() < 1e-6);
        assert!((c.position.y - 0.5 * m.extent_m[1]).abs() < 1e-6);
        assert!(c.position.z > f64::from(m.height_range_m[1]));
        assert!(c.pitch_deg < 0.0);
    }
}
