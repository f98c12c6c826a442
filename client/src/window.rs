//! The window presenter: a winit window with a wgpu surface showing the
//! presented frames (display-encoded by the presenter: exposure 1,
//! Reinhard, sRGB) and a stats overlay in the spirit of Moonlight's,
//! toggled with `O` (text by `glyphon`). `Esc` or closing the window ends
//! the session. In an interactive session the mouse and keys drive the
//! viewer ([`crate::viewer::LiveViewer`]: drag with the left button to
//! look, W/A/S/D to move, Space and C up and down, Shift to run).
//!
//! Each frame is drawn into an offscreen target of the surface's format
//! (image, then overlay), which is then drawn onto the surface; the same
//! target serves `--screenshot`. The presenter loop runs on its own thread
//! and hands frames over through the event loop proxy.

use std::path::PathBuf;
use std::sync::Arc;

use winit::application::ApplicationHandler;
use winit::event::{ElementState, KeyEvent, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop, EventLoopProxy};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::viewer::{LiveViewer, MoveKey};

/// What the presenter sends the window.
#[derive(Debug)]
pub enum Event {
    /// A presented frame: RGBA8, display-encoded, and the overlay text.
    Frame {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// RGBA8 pixels.
        rgba: Vec<u8>,
        /// Overlay text.
        stats: String,
    },
    /// The session ended.
    Done,
}

/// Where the presenter sends frames.
pub type Sink = EventLoopProxy<Event>;

/// A new event loop for the window, or why there is none (no display).
pub fn event_loop() -> anyhow::Result<EventLoop<Event>> {
    Ok(EventLoop::<Event>::with_user_event().build()?)
}

/// Runs the window until the session ends or the user closes it. With
/// `screenshot`, the last drawn frame (overlay included) is saved there.
/// With `viewer`, its mouse and keys drive that viewer.
pub fn run(
    event_loop: EventLoop<Event>,
    screenshot: Option<PathBuf>,
    viewer: Option<LiveViewer>,
) -> anyhow::Result<()> {
    let mut app = App {
        window: None,
        gfx: None,
        frame: None,
        overlay: true,
        screenshot,
        error: None,
        viewer,
        dragging: None,
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
    frame: Option<(u32, u32, Vec<u8>, String)>,
    overlay: bool,
    screenshot: Option<PathBuf>,
    error: Option<anyhow::Error>,
    /// The interactive session's viewer.
    viewer: Option<LiveViewer>,
    /// While the left button is held: the cursor's last position.
    dragging: Option<Option<(f64, f64)>>,
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
        let (Some(gfx), Some((w, h, rgba, stats))) = (self.gfx.as_mut(), self.frame.as_ref())
        else {
            return Ok(());
        };
        gfx.draw(*w, *h, rgba, self.overlay.then_some(stats.as_str()))
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
                rgba,
                stats,
            } => {
                self.frame = Some((width, height, rgba, stats));
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
    /// The device (errors typed, never wgpu's panic).
    gpu: gpu_device::Device,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    image: Option<(wgpu::Texture, wgpu::BindGroup, u32, u32)>,
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
        let gpu = gpu_device::Device::open(
            &adapter,
            &wgpu::DeviceDescriptor {
                label: Some("window"),
                required_features: wgpu::Features::empty(),
                required_limits: adapter.limits(),
                experimental_features: wgpu::ExperimentalFeatures::disabled(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            },
        )?;
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
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
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
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("blit"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("blit"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(config.format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let target = Self::make_target(device, &layout, &sampler, &config);
        let text = Text::new(device, queue, config.format);
        scope.finish()?;
        Ok(Self {
            surface,
            gpu,
            config,
            pipeline,
            layout,
            sampler,
            image: None,
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
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("window target"),
            size: wgpu::Extent3d {
                width: config.width,
                height: config.height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: config.format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
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

    fn draw(&mut self, w: u32, h: u32, rgba: &[u8], stats: Option<&str>) -> anyhow::Result<()> {
        // The presenter's bytes are sRGB-encoded: sampled through an sRGB
        // view they decode to linear, which an sRGB target encodes again.
        let format = if self.config.format.is_srgb() {
            wgpu::TextureFormat::Rgba8UnormSrgb
        } else {
            wgpu::TextureFormat::Rgba8Unorm
        };
        if self.image.as_ref().is_none_or(|i| (i.2, i.3) != (w, h)) {
            let texture = self.gpu.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("presented frame"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            });
            let group = bind(&self.gpu.device, &self.layout, &self.sampler, &texture);
            self.image = Some((texture, group, w, h));
        }
        let Some((texture, image_group, ..)) = &self.image else {
            return Ok(());
        };
        self.gpu.queue.write_texture(
            texture.as_image_copy(),
            rgba,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * w),
                rows_per_image: Some(h),
            },
            texture.size(),
        );
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
            let mut pass = begin(&mut encoder, &target_view);
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
            let mut pass = begin(&mut encoder, &view);
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
        let row = (4 * w).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("screenshot"),
            size: u64::from(row) * u64::from(h),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            self.target.0.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(h),
                },
            },
            self.target.0.size(),
        );
        self.gpu.queue.submit([encoder.finish()]);
        let slice = buffer.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        self.gpu.device.poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: None,
        })?;
        let data = slice.get_mapped_range()?;
        let bgra = matches!(
            self.config.format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        );
        let mut rgb = Vec::with_capacity((w * h * 3) as usize);
        for y in 0..h as usize {
            for px in data[y * row as usize..][..4 * w as usize].chunks_exact(4) {
                if bgra {
                    rgb.extend_from_slice(&[px[2], px[1], px[0]]);
                } else {
                    rgb.extend_from_slice(&px[..3]);
                }
            }
        }
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

fn begin<'a>(
    encoder: &'a mut wgpu::CommandEncoder,
    view: &'a wgpu::TextureView,
) -> wgpu::RenderPass<'a> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("window"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
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
