//! Opening wgpu devices the way every part of the project needs them: the
//! scene renderer, the frame generator and the window presenter.
//!
//! * **One adapter choice** for the process ([`adapter`]): `--adapter NAME`
//!   ([`prefer_adapter`]) or `WGPU_ADAPTER_NAME` picks by name,
//!   `WGPU_BACKEND` restricts the backends; otherwise Vulkan first (Mesa's
//!   lavapipe on machines without a GPU) and any other backend (OpenGL) as
//!   the fallback. Each adapter chosen is logged once.
//! * **Typed errors, never wgpu's panic.** wgpu's default handler for an
//!   uncaptured validation or out-of-memory error aborts the process.
//!   [`Device::open`] installs a handler that logs and records the error
//!   instead ([`Device::wait`] reports it), and [`Device::scope`] turns the
//!   errors of one piece of work (building pipelines, allocating for a frame
//!   size, recording a frame) into a [`GpuError`] with context.
//! * **Capability checks** before use ([`require_format`],
//!   [`Device::require_buffer`], [`Device::require_texture`]) that name what
//!   is missing, the limit, and the command that fixes it where one exists.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// The one command that gives a Debian or Ubuntu machine without a GPU a
/// complete wgpu adapter (Mesa's lavapipe, software Vulkan).
pub const VULKAN_REMEDY: &str = "apt-get install -y mesa-vulkan-drivers libvulkan1";

/// What wgpu reported, by kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorKind {
    /// A validation error (an unsupported format, a limit, a bad binding).
    Validation,
    /// The device ran out of memory.
    OutOfMemory,
    /// An internal driver or backend error.
    Internal,
}

impl std::fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Validation => "validation",
            Self::OutOfMemory => "out-of-memory",
            Self::Internal => "internal",
        })
    }
}

/// Why a GPU could not be used.
#[derive(Clone, Debug, thiserror::Error)]
pub enum GpuError {
    /// wgpu found no adapter at all.
    #[error(
        "no GPU adapter found ({reason}); Mesa's software Vulkan driver provides one: {VULKAN_REMEDY}"
    )]
    NoAdapter {
        /// wgpu's answer.
        reason: String,
    },
    /// `--adapter` / `WGPU_ADAPTER_NAME` matched no adapter.
    #[error(
        "no GPU adapter's name contains {wanted:?} (--adapter / WGPU_ADAPTER_NAME); found: {found}"
    )]
    AdapterNotFound {
        /// The name asked for.
        wanted: String,
        /// Every adapter found, described.
        found: String,
    },
    /// The adapter refused to open a device.
    #[error("{adapter}: cannot open a device: {reason}")]
    Device {
        /// The adapter, described.
        adapter: String,
        /// wgpu's answer.
        reason: String,
    },
    /// A texture format lacks a capability the caller needs.
    #[error("{adapter} cannot use {format:?} for {what} (it lacks {missing}){}", remedy(*backend))]
    Unsupported {
        /// The adapter, described.
        adapter: String,
        /// Its backend.
        backend: wgpu::Backend,
        /// What the format is for.
        what: String,
        /// The format.
        format: wgpu::TextureFormat,
        /// The usages or features it lacks.
        missing: String,
    },
    /// The work needs more than one of the device's limits allows.
    #[error("{what} needs {needed} but {adapter} allows at most {allowed} ({limit}); use a smaller frame size{}", remedy(*backend))]
    Limit {
        /// The adapter, described.
        adapter: String,
        /// Its backend.
        backend: wgpu::Backend,
        /// What needs it.
        what: String,
        /// The name of the limit in `wgpu::Limits`.
        limit: &'static str,
        /// What is needed.
        needed: u64,
        /// What the device allows.
        allowed: u64,
    },
    /// wgpu reported an error for a piece of work.
    #[error("{adapter}: {context}: wgpu {kind} error: {message}")]
    Wgpu {
        /// The adapter, described.
        adapter: String,
        /// The work that failed.
        context: String,
        /// Its kind.
        kind: ErrorKind,
        /// wgpu's message, with its sources.
        message: String,
    },
    /// Waiting for the device failed (device lost or timed out).
    #[error("{adapter}: waiting for the device failed: {reason}")]
    Lost {
        /// The adapter, described.
        adapter: String,
        /// wgpu's answer.
        reason: String,
    },
}

/// The hint appended where the OpenGL backend lacks what Vulkan has.
fn remedy(backend: wgpu::Backend) -> String {
    if backend == wgpu::Backend::Gl {
        format!("; wgpu's OpenGL backend lacks it, Mesa's Vulkan driver has it: {VULKAN_REMEDY}")
    } else {
        String::new()
    }
}

/// An adapter in one phrase: name, backend and kind.
pub fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
}

static PREFERRED: OnceLock<String> = OnceLock::new();

/// Prefers the first adapter whose name contains `name` (case-insensitive)
/// for every device the process opens from now on; the command lines'
/// `--adapter`. The first call wins. Without it, `WGPU_ADAPTER_NAME` is
/// read.
pub fn prefer_adapter(name: &str) {
    let _ = PREFERRED.set(name.to_owned());
}

fn preferred_name() -> Option<String> {
    PREFERRED
        .get()
        .cloned()
        .or_else(|| std::env::var("WGPU_ADAPTER_NAME").ok())
        .filter(|n| !n.trim().is_empty())
}

/// The adapter for headless work (rendering, generation): by name when one
/// is preferred, else from `WGPU_BACKEND` when set, else Vulkan first and any
/// other backend as the fallback (the OpenGL backend cannot do everything
/// Vulkan does; see [`require_format`]).
pub fn adapter() -> Result<wgpu::Adapter, GpuError> {
    let from_env = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
    let adapter = if let Some(name) = preferred_name() {
        // The kept instance's adapters, then OpenGL's from a new one.
        let (gl, kept) = (wgpu::Backends::GL, from_env - wgpu::Backends::GL);
        let mut adapters = Vec::new();
        if !kept.is_empty() {
            adapters = enumerate(&instance(kept), kept);
        }
        if from_env.contains(gl) {
            adapters.extend(enumerate(&instance(gl), gl));
        }
        by_name(adapters, &name, None)?
    } else if std::env::var_os("WGPU_BACKEND").is_some() {
        on_backends(from_env)?
    } else {
        match on_backends(wgpu::Backends::VULKAN) {
            Ok(a) => a,
            Err(_) => on_backends(from_env)?,
        }
    };
    log_choice(&adapter);
    Ok(adapter)
}

/// The preferred adapter among `backends` only, whatever the environment
/// says (tests and tools that compare backends, e.g. OpenGL against
/// Vulkan).
pub fn adapter_on(backends: wgpu::Backends) -> Result<wgpu::Adapter, GpuError> {
    let adapter = on_backends(backends)?;
    log_choice(&adapter);
    Ok(adapter)
}

/// The preferred adapter among `backends`. A set of OpenGL and others
/// (`WGPU_BACKEND=vulkan,gl`, or every backend after Vulkan found none) is
/// tried in two: the others on the kept instance first, then OpenGL on a
/// new one, so that a Vulkan device never comes from an instance that is
/// dropped (see [`instance`]).
fn on_backends(backends: wgpu::Backends) -> Result<wgpu::Adapter, GpuError> {
    let (gl, rest) = (wgpu::Backends::GL, backends - wgpu::Backends::GL);
    if backends.contains(gl) && !rest.is_empty() {
        if let Ok(adapter) = request(&instance(rest), None) {
            return Ok(adapter);
        }
        return request(&instance(gl), None);
    }
    request(&instance(backends), None)
}

/// A headless instance on `backends`: without OpenGL, the process's one,
/// made once and kept for the life of the process; with it, a new one.
///
/// Dropping the last instance lets the Vulkan loader unload the driver
/// while threads that called into it may still run its thread-exit
/// destructors. `client run --interactive`, whose per-session renderers
/// drop their devices before the runtime's threads end, segfaulted on exit
/// on an H200 (a `tokio-rt-worker` jumped to an unmapped address from
/// libc's thread exit), and exits cleanly with the instances kept: the
/// driver stays loaded until the process ends. An OpenGL instance is not
/// shared: its EGL context is made current by each adapter request, and a
/// second request on the same instance while a device of the first uses
/// the context on another thread fails inside wgpu with `BadAccess` (a
/// panic; seen with the in-process server's renderer beside the
/// generator).
fn instance(backends: wgpu::Backends) -> wgpu::Instance {
    let new = || {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        desc.backends = backends;
        wgpu::Instance::new(desc)
    };
    if backends.contains(wgpu::Backends::GL) {
        return new();
    }
    static KEPT: Mutex<Vec<(wgpu::Backends, wgpu::Instance)>> = Mutex::new(Vec::new());
    let mut kept = KEPT.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((_, instance)) = kept.iter().find(|(b, _)| *b == backends) {
        return instance.clone();
    }
    let instance = new();
    kept.push((backends, instance.clone()));
    instance
}

/// The adapters of `instance` on `backends`.
fn enumerate(instance: &wgpu::Instance, backends: wgpu::Backends) -> Vec<wgpu::Adapter> {
    pollster::block_on(instance.enumerate_adapters(backends))
}

/// The adapter for a window's surface, chosen the same way as [`adapter`]
/// among those that can present to it.
pub fn adapter_for_surface(
    instance: &wgpu::Instance,
    surface: &wgpu::Surface<'_>,
) -> Result<wgpu::Adapter, GpuError> {
    let adapter = match preferred_name() {
        Some(name) => {
            let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
            by_name(enumerate(instance, backends), &name, Some(surface))?
        }
        None => request(instance, Some(surface))?,
    };
    log_choice(&adapter);
    Ok(adapter)
}

fn request(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface<'_>>,
) -> Result<wgpu::Adapter, GpuError> {
    pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference:
            wgpu::PowerPreference::from_env().unwrap_or(wgpu::PowerPreference::HighPerformance),
        force_fallback_adapter: false,
        compatible_surface: surface,
        apply_limit_buckets: false,
    }))
    .map_err(|e| GpuError::NoAdapter {
        reason: e.to_string(),
    })
}

/// The first of `adapters` whose name contains `name` (case-insensitive)
/// and that can present to `surface` when one is given.
fn by_name(
    adapters: Vec<wgpu::Adapter>,
    name: &str,
    surface: Option<&wgpu::Surface<'_>>,
) -> Result<wgpu::Adapter, GpuError> {
    let wanted = name.to_lowercase();
    let found = adapters
        .iter()
        .map(|a| describe(&a.get_info()))
        .collect::<Vec<_>>();
    adapters
        .into_iter()
        .filter(|a| surface.is_none_or(|s| a.is_surface_supported(s)))
        .find(|a| a.get_info().name.to_lowercase().contains(&wanted))
        .ok_or_else(|| GpuError::AdapterNotFound {
            wanted: name.to_owned(),
            found: if found.is_empty() {
                "none".into()
            } else {
                found.join("; ")
            },
        })
}

/// Logs an adapter the first time the process picks it.
fn log_choice(adapter: &wgpu::Adapter) {
    static SEEN: Mutex<Vec<String>> = Mutex::new(Vec::new());
    let info = adapter.get_info();
    let driver = format!("{} {}", info.driver, info.driver_info);
    let text = match driver.trim() {
        "" => describe(&info),
        d => format!("{}, driver {d}", describe(&info)),
    };
    let mut seen = SEEN.lock().unwrap_or_else(|p| p.into_inner());
    if seen.contains(&text) {
        tracing::debug!(adapter = %text, "GPU adapter");
    } else {
        tracing::info!(adapter = %text, "GPU adapter");
        seen.push(text);
    }
}

/// What a command-line program's `main` returns as its error, so that a
/// missing driver ends it the way it should: one line on stderr (`Error: `
/// and the whole chain, as `{:#}` gives it, which for `anyhow` joins the
/// causes) and a non-zero status; never a panic or a backtrace, whatever
/// `RUST_BACKTRACE` says (anyhow's `Debug` would print one).
pub struct OneLine(String);

impl<E: std::fmt::Display> From<E> for OneLine {
    fn from(e: E) -> Self {
        Self(format!("{e:#}").replace('\n', " "))
    }
}

impl std::fmt::Debug for OneLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// A plain 2D texture (one mip level, one sample, no other view formats):
/// the renderer's targets and shadow map, the window's images.
pub fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// A bind group of a texture view (binding 0) and its sampler (binding 1),
/// the layout of a sampled image: the renderer's shadow map, the window's
/// frame.
pub fn view_and_sampler(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    view: &wgpu::TextureView,
    sampler: &wgpu::Sampler,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(view),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::Sampler(sampler),
            },
        ],
    })
}

/// Checks that `format` supports `usages` and `flags` on `adapter`, before
/// any pipeline or texture is built with it.
pub fn require_format(
    adapter: &wgpu::Adapter,
    format: wgpu::TextureFormat,
    usages: wgpu::TextureUsages,
    flags: wgpu::TextureFormatFeatureFlags,
    what: &str,
) -> Result<(), GpuError> {
    let has = adapter.get_texture_format_features(format);
    let missing_usages = usages - has.allowed_usages;
    let missing_flags = flags - has.flags;
    if missing_usages.is_empty() && missing_flags.is_empty() {
        return Ok(());
    }
    let info = adapter.get_info();
    let mut missing = Vec::new();
    if !missing_usages.is_empty() {
        missing.push(format!("{missing_usages:?}"));
    }
    if !missing_flags.is_empty() {
        missing.push(format!("{missing_flags:?}"));
    }
    Err(GpuError::Unsupported {
        adapter: describe(&info),
        backend: info.backend,
        what: what.to_owned(),
        format,
        missing: missing.join(", "),
    })
}

/// The first error wgpu reported outside any [`Scope`], and how many.
#[derive(Clone, Debug, Default)]
struct ErrorLog {
    first: Arc<Mutex<Option<(ErrorKind, String)>>>,
    count: Arc<AtomicU64>,
}

impl ErrorLog {
    fn record(&self, error: wgpu::Error) {
        let (kind, message) = split(&error);
        tracing::error!(%kind, "uncaptured wgpu error: {message}");
        self.count.fetch_add(1, Ordering::Relaxed);
        let mut first = self.first.lock().unwrap_or_else(|p| p.into_inner());
        first.get_or_insert((kind, message));
    }

    fn take(&self) -> Option<(ErrorKind, String)> {
        self.first.lock().unwrap_or_else(|p| p.into_inner()).take()
    }
}

/// An error's kind and its message with every source.
fn split(error: &wgpu::Error) -> (ErrorKind, String) {
    let kind = match error {
        wgpu::Error::OutOfMemory { .. } => ErrorKind::OutOfMemory,
        wgpu::Error::Validation { .. } => ErrorKind::Validation,
        wgpu::Error::Internal { .. } => ErrorKind::Internal,
    };
    let mut message = error.to_string();
    let mut source = std::error::Error::source(error);
    while let Some(s) = source {
        let text = s.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        source = s.source();
    }
    (
        kind,
        message.split_whitespace().collect::<Vec<_>>().join(" "),
    )
}

/// An opened device whose errors are typed, never a panic.
#[derive(Debug)]
pub struct Device {
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter name and backend, for reports.
    pub adapter_info: wgpu::AdapterInfo,
    errors: ErrorLog,
}

impl Device {
    /// Opens a device on `adapter` and installs the error handler that
    /// records instead of panicking.
    pub fn open(
        adapter: &wgpu::Adapter,
        desc: &wgpu::DeviceDescriptor<'_>,
    ) -> Result<Self, GpuError> {
        let adapter_info = adapter.get_info();
        let (device, queue) =
            pollster::block_on(adapter.request_device(desc)).map_err(|e| GpuError::Device {
                adapter: describe(&adapter_info),
                reason: e.to_string(),
            })?;
        let errors = ErrorLog::default();
        let log = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e| log.record(e)));
        tracing::debug!(adapter = %describe(&adapter_info), label = ?desc.label, "device open");
        Ok(Self {
            device,
            queue,
            adapter_info,
            errors,
        })
    }

    /// The adapter in one phrase.
    pub fn describe(&self) -> String {
        describe(&self.adapter_info)
    }

    /// Starts capturing every error of the work that follows on this thread
    /// until [`Scope::finish`].
    pub fn scope(&self, context: impl Into<String>) -> Scope {
        let d = &self.device;
        Scope {
            adapter: self.describe(),
            context: context.into(),
            // Popped in reverse: validation first.
            guards: [
                d.push_error_scope(wgpu::ErrorFilter::OutOfMemory),
                d.push_error_scope(wgpu::ErrorFilter::Internal),
                d.push_error_scope(wgpu::ErrorFilter::Validation),
            ],
        }
    }

    /// Runs `work` inside a [`Scope`].
    pub fn checked<T>(&self, context: &str, work: impl FnOnce() -> T) -> Result<T, GpuError> {
        let scope = self.scope(context);
        let out = work();
        scope.finish()?;
        Ok(out)
    }

    /// The first error recorded outside any scope since the last call, as a
    /// [`GpuError`] with `context`.
    pub fn check(&self, context: &str) -> Result<(), GpuError> {
        match self.errors.take() {
            None => Ok(()),
            Some((kind, message)) => Err(GpuError::Wgpu {
                adapter: self.describe(),
                context: context.to_owned(),
                kind,
                message,
            }),
        }
    }

    /// Reads a texture (one mip level, one layer, a colour format) back to
    /// the host: its rows, top first, without the copy's row padding. For
    /// screenshots and tests, not a hot path (it waits for its copy, not
    /// for what others sharing the device submitted after it).
    pub fn read_texture(&self, texture: &wgpu::Texture) -> Result<Vec<u8>, GpuError> {
        let format = texture.format();
        let Some(texel) = format.block_copy_size(None) else {
            return Err(GpuError::Unsupported {
                adapter: self.describe(),
                backend: self.adapter_info.backend,
                what: "a read-back".into(),
                format,
                missing: "one copyable aspect".into(),
            });
        };
        let (w, h) = (texture.width(), texture.height());
        let row = (texel * w).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("texture read-back"),
            size: u64::from(row) * u64::from(h),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(h),
                },
            },
            texture.size(),
        );
        let index = self.queue.submit([encoder.finish()]);
        let slice = buffer.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        self.wait_for(index)?;
        let data = slice.get_mapped_range().map_err(|e| GpuError::Lost {
            adapter: self.describe(),
            reason: format!("mapping a read-back: {e:?}"),
        })?;
        Ok(data
            .chunks_exact(row as usize)
            .flat_map(|r| &r[..(texel * w) as usize])
            .copied()
            .collect())
    }

    /// Blocks until every submitted command buffer has finished, then
    /// reports any error recorded meanwhile.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.wait_until(None)
    }

    /// Blocks until submission `index` has finished (not what others
    /// sharing the device submitted after it: a window presenting from the
    /// device that generates), then reports any error recorded meanwhile.
    pub fn wait_for(&self, index: wgpu::SubmissionIndex) -> Result<(), GpuError> {
        self.wait_until(Some(index))
    }

    fn wait_until(&self, index: Option<wgpu::SubmissionIndex>) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: index,
                timeout: None,
            })
            .map_err(|e| GpuError::Lost {
                adapter: self.describe(),
                reason: e.to_string(),
            })?;
        self.check("submitted work")
    }

    /// Checks that one buffer of `bytes` (bound as storage when `storage`)
    /// fits the device's limits.
    pub fn require_buffer(&self, what: &str, bytes: u64, storage: bool) -> Result<(), GpuError> {
        let limits = self.device.limits();
        self.require_limit(what, "max_buffer_size", bytes, limits.max_buffer_size)?;
        if storage {
            self.require_limit(
                what,
                "max_storage_buffer_binding_size",
                bytes,
                limits.max_storage_buffer_binding_size,
            )?;
        }
        Ok(())
    }

    /// Checks that a 2-D texture of `width` × `height` fits the device.
    pub fn require_texture(&self, what: &str, width: u32, height: u32) -> Result<(), GpuError> {
        let allowed = self.device.limits().max_texture_dimension_2d;
        self.require_limit(
            what,
            "max_texture_dimension_2d",
            u64::from(width.max(height)),
            u64::from(allowed),
        )
    }

    fn require_limit(
        &self,
        what: &str,
        limit: &'static str,
        needed: u64,
        allowed: u64,
    ) -> Result<(), GpuError> {
        if needed <= allowed {
            return Ok(());
        }
        Err(GpuError::Limit {
            adapter: self.describe(),
            backend: self.adapter_info.backend,
            what: what.to_owned(),
            limit,
            needed,
            allowed,
        })
    }
}

/// Captures the errors of a piece of work on one thread ([`Device::scope`]).
#[must_use = "finish() reports what the scope caught"]
pub struct Scope {
    adapter: String,
    context: String,
    guards: [wgpu::ErrorScopeGuard; 3],
}

impl Scope {
    /// Ends the scope: the first error it caught (validation before
    /// internal before out-of-memory), if any.
    pub fn finish(self) -> Result<(), GpuError> {
        let Self {
            adapter,
            context,
            guards,
        } = self;
        let mut first = None;
        for guard in guards.into_iter().rev() {
            if let Some(e) = pollster::block_on(guard.pop()) {
                first.get_or_insert(e);
            }
        }
        match first {
            None => Ok(()),
            Some(e) => {
                let (kind, message) = split(&e);
                Err(GpuError::Wgpu {
                    adapter,
                    context,
                    kind,
                    message,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The software adapters of the project's machines: lavapipe, or
    /// llvmpipe through OpenGL.
    fn open() -> Device {
        let adapter = adapter().expect("a wgpu adapter (lavapipe or llvmpipe)");
        Device::open(&adapter, &wgpu::DeviceDescriptor::default()).expect("a device")
    }

    #[test]
    fn a_validation_error_is_typed_not_a_panic() {
        let d = open();
        // A buffer larger than the device allows: wgpu's default handler
        // would abort the process.
        let too_big = d.device.limits().max_buffer_size + 4;
        let err = d
            .checked("allocating", || {
                d.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("too big"),
                    size: too_big,
                    usage: wgpu::BufferUsages::STORAGE,
                    mapped_at_creation: false,
                })
            })
            .map(|_| ())
            .unwrap_err();
        match &err {
            GpuError::Wgpu { context, kind, .. } => {
                assert_eq!(context, "allocating");
                assert_eq!(*kind, ErrorKind::Validation);
            }
            other => panic!("unexpected {other:?}"),
        }
        // The same outside a scope reaches the recording handler, and
        // wait() reports it once.
        let _ = d.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("too big"),
            size: too_big,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        assert!(matches!(d.wait(), Err(GpuError::Wgpu { .. })));
        assert!(d.wait().is_ok());
    }

    #[test]
    fn limits_and_formats_name_what_is_missing() {
        let d = open();
        let max = d.device.limits().max_texture_dimension_2d;
        assert!(d.require_texture("frame", max, 1).is_ok());
        let err = d.require_texture("frame", max + 1, 1).unwrap_err();
        let text = err.to_string();
        assert!(text.contains("max_texture_dimension_2d"), "{text}");
        assert!(text.contains(&(max + 1).to_string()), "{text}");
        let limits = d.device.limits();
        assert!(d.require_buffer("b", limits.max_buffer_size, false).is_ok());
        assert!(
            d.require_buffer("b", limits.max_buffer_size + 1, false)
                .is_err()
        );
        // Depth formats are never storage textures.
        let adapter = adapter().unwrap();
        let err = require_format(
            &adapter,
            wgpu::TextureFormat::Depth32Float,
            wgpu::TextureUsages::STORAGE_BINDING,
            wgpu::TextureFormatFeatureFlags::empty(),
            "a test",
        )
        .unwrap_err();
        assert!(err.to_string().contains("STORAGE_BINDING"), "{err}");
    }

    #[test]
    fn one_line_joins_the_chain() {
        let e = GpuError::NoAdapter {
            reason: "none\nfound".into(),
        };
        let line = format!("{:?}", OneLine::from(e));
        assert!(!line.contains('\n'), "{line}");
        assert!(
            line.contains("none found") && line.contains(VULKAN_REMEDY),
            "{line}"
        );
    }

    #[test]
    fn remedy_only_for_opengl() {
        assert!(remedy(wgpu::Backend::Gl).contains(VULKAN_REMEDY));
        assert!(remedy(wgpu::Backend::Vulkan).is_empty());
        let e = GpuError::NoAdapter {
            reason: "none".into(),
        };
        assert!(e.to_string().contains(VULKAN_REMEDY));
    }
}
