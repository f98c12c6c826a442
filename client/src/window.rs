//! The window presenter: a winit window with a wgpu surface showing the
//! presented frames (linear HDR colour, display-encoded on the window's
//! GPU: exposure 1, Reinhard, sRGB; [`crate::display`]) and a stats
//! overlay in the spirit of Moonlight's, toggled with `O` (text by
//! `glyphon`). `Esc` or closing the window ends the session. In an
//! interactive session the mouse and keys drive the viewer
//! ([`crate::viewer::LiveViewer`]: drag with the left button to look,
//! W/A/S/D to move, Space and C up and down, Shift to run).
//!
//! Each frame is display-encoded once, as it arrives, then drawn into an
//! offscreen target of the surface's format (image, then overlay), which
//! is then drawn onto the surface; the same target serves `--screenshot`.
//! The presenter loop runs on its own thread and hands frames over through
//! the event loop proxy: a frame's colour from the host, or, where a wgpu
//! generator shares the window's device ([`Shared`]), a frame it already
//! generated and display-encoded there.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;

use winit::application::ApplicationHandler;
use winit::event::{ElementState, KeyEvent, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop, EventLoopProxy};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::display::{DisplayPass, Image};
use crate::viewer::{LiveViewer, MoveKey};
use framegen::GpuContext;

/// What the presenter sends the window.
#[derive(Debug)]
pub enum Event {
    /// A presented frame: its linear colour, and the overlay text.
    Frame {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Linear RGBA, `width × height` pixels, row-major (the frame's
        /// own colour: the window applies the display transform).
        color: Vec<[half::f16; 4]>,
        /// Overlay text.
        stats: String,
    },
    /// A presented frame already display-encoded on the window's own
    /// device (by a generator sharing it, [`Shared`]), and the overlay
    /// text.
    Encoded {
        /// The frame's textures; the window shows `encoded`.
        image: Arc<Image>,
        /// Overlay text.
        stats: String,
    },
    /// The session ended.
    Done,
}

/// What the window shares with the presenter once it is up: its device
/// (opened as the generator would open one, [`GpuContext::descriptor`],
/// on an adapter that presents to the window) and its display transform,
/// so that a generator on that device hands frames over without leaving
/// it (issue 15 §2).
#[derive(Clone, Debug)]
pub struct Shared {
    /// The window's device, as a generator's context.
    pub ctx: Arc<GpuContext>,
    /// The display transform into the window's image format.
    pub display: Arc<DisplayPass>,
}

/// A frame waiting for the next redraw.
enum Pending {
    /// Linear colour from the host: width, height, pixels.
    Host(u32, u32, Vec<[half::f16; 4]>),
    /// Already encoded on the device.
    Device(Arc<Image>),
}

/// Where the presenter sends frames.
pub type Sink = EventLoopProxy<Event>;

/// A new event loop for the window, or why there is none (no display).
pub fn event_loop() -> anyhow::Result<EventLoop<Event>> {
    Ok(EventLoop::<Event>::with_user_event().build()?)
}

/// Runs the window until the session ends or the user closes it. With
/// `screenshot`, the last drawn frame (overlay included) is saved there.
/// With `viewer`, its mouse and keys drive that viewer. With `share`, the
/// window's device and display transform are sent there once the window
/// is up (dropped unsent if it fails to open).
pub fn run(
    event_loop: EventLoop<Event>,
    screenshot: Option<PathBuf>,
    viewer: Option<LiveViewer>,
    share: Option<std::sync::mpsc::SyncSender<Shared>>,
) -> anyhow::Result<()> {
    let mut app = App {
        window: None,
        gfx: None,
        pending: None,
        stats: String::new(),
        overlay: true,
        screenshot,
        error: None,
        viewer,
        dragging: None,
        share,
    };
    event_loop.run_app(&mut app)?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

struct App {
    window: Option<Arc<Window>>,
    gfx: Option<Gfx>,
    /// The newest frame not yet shown.
    pending: Option<Pending>,
    /// The newest frame's overlay text.
    stats: String,
    overlay: bool,
    screenshot: Option<PathBuf>,
    error: Option<anyhow::Error>,
    /// The interactive session's viewer.
    viewer: Option<LiveViewer>,
    /// While the left button is held: the cursor's last position.
    dragging: Option<Option<(f64, f64)>>,
    /// Where the window's device goes once it is open.
    share: Option<std::sync::mpsc::SyncSender<Shared>>,
}

/// The viewer's movement key for a key's text, if it is one.
fn move_key(key: &Key) -> Option<MoveKey> {
    Some(match key {
        Key::Named(NamedKey::Space) => MoveKey::Up,
        Key::Named(NamedKey::Shift) => MoveKey::Run,
        Key::Character(c) => match c.to_ascii_lowercase().as_str() {
            "w" => MoveKey::Forward,
            "s" => MoveKey::Back,
            "a" => MoveKey::Left,
            "d" => MoveKey::Right,
            "c" => MoveKey::Down,
            _ => return None,
        },
        _ => return None,
    })
}

impl App {
    fn fail(&mut self, el: &ActiveEventLoop, e: anyhow::Error) {
        tracing::error!("window: {e:#}");
        self.error = Some(e);
        el.exit();
    }

    fn draw(&mut self) -> anyhow::Result<()> {
        let Some(gfx) = self.gfx.as_mut() else {
            return Ok(());
        };
        match self.pending.take() {
            Some(Pending::Host(w, h, color)) => gfx.show(w, h, &color)?,
            Some(Pending::Device(image)) => gfx.show_encoded(image),
            None => {}
        }
        gfx.draw(self.overlay.then_some(self.stats.as_str()))
    }
}

impl ApplicationHandler<Event> for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let attrs = Window::default_attributes()
            .with_title(if self.viewer.is_some() {
                "framegen client (drag: look, W/A/S/D: move, O: overlay, Esc: quit)"
            } else {
                "framegen client (O: overlay, Esc: quit)"
            })
            .with_inner_size(winit::dpi::PhysicalSize::new(960u32, 540u32));
        let result = el
            .create_window(attrs)
            .map_err(anyhow::Error::from)
            .and_then(|w| {
                let w = Arc::new(w);
                let gfx = Gfx::new(w.clone())?;
                Ok((w, gfx))
            });
        match result {
            Ok((w, gfx)) => {
                if let Some(share) = self.share.take() {
                    // The presenter may have stopped waiting: then it
                    // generates elsewhere.
                    let _ = share.try_send(Shared {
                        ctx: gfx.gpu.clone(),
                        display: gfx.display.clone(),
                    });
                }
                self.window = Some(w);
                self.gfx = Some(gfx);
            }
            Err(e) => self.fail(el, e),
        }
    }

    fn user_event(&mut self, el: &ActiveEventLoop, event: Event) {
        match event {
            Event::Frame {
                width,
                height,
                color,
                stats,
            } => {
                self.pending = Some(Pending::Host(width, height, color));
                self.stats = stats;
                if let Some(w) = &self.window {
                    w.request_redraw();
                }
            }
            Event::Encoded { image, stats } => {
                self.pending = Some(Pending::Device(image));
                self.stats = stats;
                if let Some(w) = &self.window {
                    w.request_redraw();
                }
            }
            Event::Done => {
                if let Some(path) = self.screenshot.take() {
                    let result = self.draw().and_then(|_| match &self.gfx {
                        Some(g) => g.save(&path),
                        None => Ok(()),
                    });
                    if let Err(e) = result {
                        return self.fail(el, e);
                    }
                }
                el.exit();
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        if let Some(viewer) = &self.viewer {
            match &event {
                WindowEvent::KeyboardInput {
                    event:
                        KeyEvent {
                            logical_key, state, ..
                        },
                    ..
                } => {
                    if let Some(key) = move_key(logical_key) {
                        let down = *state == ElementState::Pressed;
                        viewer.key(key, down, std::time::Instant::now());
                    }
                }
                WindowEvent::MouseInput {
                    state,
                    button: MouseButton::Left,
                    ..
                } => {
                    self.dragging = (*state == ElementState::Pressed).then_some(None);
                }
                WindowEvent::CursorMoved { position, .. } => {
                    if let Some(last) = &mut self.dragging {
                        if let Some((x, y)) = *last {
                            viewer.look(position.x - x, position.y - y);
                        }
                        *last = Some((position.x, position.y));
                    }
                }
                WindowEvent::Focused(false) => {
                    // Keys released elsewhere never come back as releases.
                    let now = std::time::Instant::now();
                    for key in [
                        MoveKey::Forward,
                        MoveKey::Back,
                        MoveKey::Left,
                        MoveKey::Right,
                        MoveKey::Up,
                        MoveKey::Down,
                        MoveKey::Run,
                    ] {
                        viewer.key(key, false, now);
                    }
                    self.dragging = None;
                }
                _ => {}
            }
        }
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::KeyboardInput {
                event:
                    KeyEvent {
                        logical_key,
                        state: ElementState::Pressed,
                        ..
                    },
                ..
            } => match logical_key {
                Key::Named(NamedKey::Escape) => el.exit(),
                Key::Character(c) if c.eq_ignore_ascii_case("o") => {
                    self.overlay = !self.overlay;
                    if let Some(w) = &self.window {
                        w.request_redraw();
                    }
                }
                _ => {}
            },
            WindowEvent::Resized(size) => {
                if let Some(g) = &mut self.gfx {
                    g.resize(size.width, size.height);
                }
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.draw() {
                    self.fail(el, e);
                }
            }
            _ => {}
        }
    }
}

/// The wgpu side of the window.
struct Gfx {
    surface: wgpu::Surface<'static>,
    /// The device (errors typed, never wgpu's panic), opened as a
    /// generator's so that one can share it.
    gpu: Arc<GpuContext>,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// The display transform into the encoded image's format.
    display: Arc<DisplayPass>,
    /// The frames shown lately on the device, each with its encoded image
    /// bound for the blit, the shown one first: frames come from a few
    /// images in turn (the presenter's ring, [`Self::own`]), so each is
    /// bound once, not per frame.
    bound: VecDeque<(Arc<Image>, wgpu::BindGroup)>,
    /// Where frames from the host are uploaded and encoded (the shown
    /// frame may instead be one a generator on this device encoded).
    own: Option<Arc<Image>>,
    target: (wgpu::Texture, wgpu::BindGroup),
    text: Text,
}

struct Text {
    fonts: glyphon::FontSystem,
    swash: glyphon::SwashCache,
    viewport: glyphon::Viewport,
    atlas: glyphon::TextAtlas,
    renderer: glyphon::TextRenderer,
    buffer: glyphon::Buffer,
}

/// How many shown images keep their binding: the presenter's ring and the
/// window's own.
const BOUND: usize = crate::present::RING + 1;

const BLIT_WGSL: &str = r#"
@group(0) @binding(0) var image: texture_2d<f32>;
@group(0) @binding(1) var image_sampler: sampler;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs(@builtin(vertex_index) i: u32) -> VsOut {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VsOut;
    out.position = vec4<f32>(uv * vec2<f32>(2.0, -2.0) + vec2<f32>(-1.0, 1.0), 0.0, 1.0);
    out.uv = uv;
    return out;
}

@fragment
fn fs(in: VsOut) -> @location(0) vec4<f32> {
    return textureSample(image, image_sampler, in.uv);
}
"#;

impl Gfx {
    fn new(window: Arc<Window>) -> anyhow::Result<Self> {
        let size = window.inner_size();
        // The display handle lets wgpu's OpenGL backend (EGL) present to the
        // window too; without it only Vulkan could.
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(window.clone())),
        );
        let surface = instance.create_surface(window)?;
        let adapter = gpu_device::adapter_for_surface(&instance, &surface)?;
        // Opened as the generator opens its own, so that it can share it.
        let gpu = GpuContext::from_device(gpu_device::Device::open(
            &adapter,
            &wgpu::DeviceDescriptor {
                label: Some("window"),
                ..GpuContext::descriptor(&adapter)
            },
        )?);
        let scope = gpu.scope("building the window's pipeline");
        let (device, queue) = (&gpu.device, &gpu.queue);
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| anyhow::anyhow!("the surface is not supported by the adapter"))?;
        config.present_mode = wgpu::PresentMode::Fifo;
        surface.configure(device, &config);
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("image"),
            entries: &[
                crate::display::image_entry(0, true),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("blit"),
            source: wgpu::ShaderSource::Wgsl(BLIT_WGSL.into()),
        });
        let pipeline =
            crate::display::full_screen(device, "blit", &module, &layout, "fs", config.format);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let target = Self::make_target(device, &layout, &sampler, &config);
        // Encoded into sRGB where the surface is: sampled through it the
        // image decodes to linear, which the surface encodes again.
        let display = Arc::new(DisplayPass::new(
            device,
            if config.format.is_srgb() {
                wgpu::TextureFormat::Rgba8UnormSrgb
            } else {
                wgpu::TextureFormat::Rgba8Unorm
            },
        ));
        let text = Text::new(device, queue, config.format);
        scope.finish()?;
        Ok(Self {
            surface,
            gpu,
            config,
            pipeline,
            layout,
            sampler,
            display,
            bound: VecDeque::new(),
            own: None,
            target,
            text,
        })
    }

    fn make_target(
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        sampler: &wgpu::Sampler,
        config: &wgpu::SurfaceConfiguration,
    ) -> (wgpu::Texture, wgpu::BindGroup) {
        let texture = gpu_device::texture_2d(
            device,
            "window target",
            (config.width, config.height),
            config.format,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let group = bind(device, layout, sampler, &texture);
        (texture, group)
    }

    fn resize(&mut self, width: u32, height: u32) {
        if width == 0 || height == 0 {
            return;
        }
        self.config.width = width;
        self.config.height = height;
        self.surface.configure(&self.gpu.device, &self.config);
        self.target =
            Self::make_target(&self.gpu.device, &self.layout, &self.sampler, &self.config);
    }

    /// Puts a frame on the device and display-encodes it there (the
    /// presenter's bytes are linear HDR; see [`crate::display`]).
    fn show(&mut self, w: u32, h: u32, color: &[[half::f16; 4]]) -> anyhow::Result<()> {
        if w == 0 || h == 0 {
            return Ok(());
        }
        self.gpu.require_texture("a presented frame", w, h)?;
        let own = match &self.own {
            Some(i) if (i.width, i.height) == (w, h) => i.clone(),
            _ => Arc::new(self.display.image(&self.gpu.device, w, h)),
        };
        self.display.upload(&self.gpu.queue, &own, color)?;
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        self.display.encode(&mut encoder, &own);
        self.gpu.queue.submit([encoder.finish()]);
        self.own = Some(own.clone());
        self.show_encoded(own);
        Ok(())
    }

    /// Shows a frame already display-encoded on this device, with the
    /// binding its image had if it was shown lately. Images of another
    /// size than this one are let go.
    fn show_encoded(&mut self, image: Arc<Image>) {
        let size = (image.width, image.height);
        self.bound.retain(|(i, _)| (i.width, i.height) == size);
        let known = self.bound.iter().position(|(i, _)| Arc::ptr_eq(i, &image));
        let entry = match known.and_then(|at| self.bound.remove(at)) {
            Some(entry) => entry,
            None => {
                let group = bind(
                    &self.gpu.device,
                    &self.layout,
                    &self.sampler,
                    &image.encoded,
                );
                (image, group)
            }
        };
        self.bound.push_front(entry);
        self.bound.truncate(BOUND);
    }

    /// Draws the shown frame and the overlay (`stats`) onto the surface.
    fn draw(&mut self, stats: Option<&str>) -> anyhow::Result<()> {
        let Some((_, image_group)) = self.bound.front() else {
            return Ok(());
        };
        if let Some(stats) = stats {
            self.text.prepare(
                &self.gpu.device,
                &self.gpu.queue,
                stats,
                self.config.width,
                self.config.height,
            )?;
        }
        let target_view = self.target.0.create_view(&Default::default());
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = crate::display::begin(&mut encoder, &target_view);
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, image_group, &[]);
            pass.draw(0..3, 0..1);
            if stats.is_some() {
                self.text
                    .renderer
                    .render(&self.text.atlas, &self.text.viewport, &mut pass)?;
            }
        }
        let (frame, reconfigure) = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => (Some(t), false),
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => (Some(t), true),
            wgpu::CurrentSurfaceTexture::Lost => {
                anyhow::bail!("the window surface was lost")
            }
            // Timeout, occluded, outdated: skip showing this frame (the
            // offscreen target is still drawn, for the screenshot).
            _ => (None, true),
        };
        if let Some(frame) = &frame {
            let view = frame.texture.create_view(&Default::default());
            let mut pass = crate::display::begin(&mut encoder, &view);
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.target.1, &[]);
            pass.draw(0..3, 0..1);
        }
        self.gpu.queue.submit([encoder.finish()]);
        if let Some(frame) = frame {
            self.gpu.queue.present(frame);
        }
        if reconfigure {
            self.surface.configure(&self.gpu.device, &self.config);
        }
        self.text.atlas.trim();
        // An error wgpu reported for this frame (recorded, not a panic).
        self.gpu.check("presenting a frame")?;
        Ok(())
    }

    /// Saves the offscreen target (what the window shows) as a PNG.
    fn save(&self, path: &std::path::Path) -> anyhow::Result<()> {
        let (w, h) = (self.config.width, self.config.height);
        let data = self.gpu.read_texture(&self.target.0)?;
        let bgra = matches!(
            self.config.format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        );
        let rgb: Vec<u8> = data
            .chunks_exact(4)
            .flat_map(|px| {
                if bgra {
                    [px[2], px[1], px[0]]
                } else {
                    [px[0], px[1], px[2]]
                }
            })
            .collect();
        image::save_buffer(path, &rgb, w, h, image::ExtendedColorType::Rgb8)?;
        Ok(())
    }
}

fn bind(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    sampler: &wgpu::Sampler,
    texture: &wgpu::Texture,
) -> wgpu::BindGroup {
    let view = texture.create_view(&Default::default());
    gpu_device::view_and_sampler(device, "image", layout, &view, sampler)
}

impl Text {
    fn new(device: &wgpu::Device, queue: &wgpu::Queue, format: wgpu::TextureFormat) -> Self {
        let mut fonts = glyphon::FontSystem::new();
        // A minimal system may have no fontconfig setup: load DejaVu Sans
        // Mono directly when it is installed (Debian: fonts-dejavu-core).
        let dejavu = "/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf";
        if std::path::Path::new(dejavu).exists() {
            let _ = fonts.db_mut().load_font_file(dejavu);
        }
        let swash = glyphon::SwashCache::new();
        let cache = glyphon::Cache::new(device);
        let viewport = glyphon::Viewport::new(device, &cache);
        let mut atlas = glyphon::TextAtlas::new(device, queue, &cache, format);
        let renderer =
            glyphon::TextRenderer::new(&mut atlas, device, wgpu::MultisampleState::default(), None);
        let buffer = glyphon::Buffer::new(&mut fonts, glyphon::Metrics::new(16.0, 20.0));
        Self {
            fonts,
            swash,
            viewport,
            atlas,
            renderer,
            buffer,
        }
    }

    fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        text: &str,
        width: u32,
        height: u32,
    ) -> anyhow::Result<()> {
        self.viewport
            .update(queue, glyphon::Resolution { width, height });
        let mut buffer = self.buffer.borrow_with(&mut self.fonts);
        buffer.set_size(Some(width as f32), Some(height as f32));
        buffer.set_text(
            text,
            &glyphon::Attrs::new().family(glyphon::Family::Monospace),
            glyphon::Shaping::Advanced,
            None,
        );
        buffer.shape_until_scroll(false);
        self.renderer.prepare(
            device,
            queue,
            &mut self.fonts,
            &mut self.atlas,
            &self.viewport,
            [glyphon::TextArea {
                buffer: &self.buffer,
                left: 12.0,
                top: 10.0,
                scale: 1.0,
                bounds: glyphon::TextBounds {
                    left: 0,
                    top: 0,
                    right: width as i32,
                    bottom: height as i32,
                },
                default_color: glyphon::Color::rgb(255, 255, 255),
                custom_glyphs: &[],
            }],
            &mut self.swash,
        )?;
        Ok(())
    }
}
