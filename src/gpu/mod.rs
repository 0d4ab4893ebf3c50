//! What every GPU stage shares: the headless GPU context (adapter choice), the description of
//! the targets a frame draws into, buffer and texture readback, timestamp timing, and the small
//! vocabulary every stage's set-up is written in: bind group layouts and bind groups one line a
//! binding ([`layout`]), pipelines, buffers and views ([`pipeline`]), render passes ([`pass`]).
//!
//! The adapter is chosen the way wgpu's own tools choose it, from environment variables:
//! `WGPU_BACKEND` (e.g. `vulkan`, `gl`), `WGPU_ADAPTER_NAME` (a case-insensitive substring of the
//! adapter's name, e.g. `llvmpipe` or `nvidia`) and `WGPU_POWER_PREF` (`low`, `high`).

pub mod layout;
pub mod pass;
pub mod pipeline;
mod readback;
mod timing;

pub use readback::{
    ReadbackError, read_buffer, read_buffer_pod, read_texture_layer, read_texture_level,
    read_texture_rgba8,
};
pub use timing::{GpuTimer, PassTimes};

use thiserror::Error;

/// The colour and depth targets a frame draws into: their formats and size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Targets {
    /// Format of the colour target.
    pub color_format: wgpu::TextureFormat,
    /// Format of the depth target (reverse-Z: cleared to 0, greater is nearer).
    pub depth_format: wgpu::TextureFormat,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

/// A 2D target texture of `width` x `height`, one mip level, one sample.
pub fn target_texture(
    device: &wgpu::Device,
    label: &str,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
    size: (u32, u32),
) -> wgpu::Texture {
    multisampled_texture(device, label, format, usage, size, 1)
}

/// Like [`target_texture`], with `samples` samples a pixel.
pub fn multisampled_texture(
    device: &wgpu::Device,
    label: &str,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
    (width, height): (u32, u32),
    samples: u32,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: samples,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

impl Targets {
    /// The `ENCODE_SRGB` pipeline constant of `shaders/shared/output.wgsl` for the colour
    /// format: 1 when the shader must encode sRGB itself, else 0.
    pub fn encode_srgb(&self) -> f64 {
        if crate::shaders::encode_srgb_for(self.color_format) == Some(true) {
            1.0
        } else {
            0.0
        }
    }
}

/// What can go wrong while opening the GPU.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum GpuError {
    /// No adapter matched the requested backends (and name, if one was asked for).
    #[error(
        "no GPU adapter found (backends: {backends}{name_note}). On a machine without a GPU, install \
         software Vulkan: `apt-get install mesa-vulkan-drivers` (Debian/Ubuntu), which provides the \
         llvmpipe adapter"
    )]
    NoAdapter {
        /// The backends that were searched.
        backends: String,
        /// A note about `WGPU_ADAPTER_NAME`, when it was set.
        name_note: String,
    },
    /// The adapter refused to open a device.
    #[error("adapter {adapter} could not open a device: {source}")]
    RequestDevice {
        /// The adapter's name.
        adapter: String,
        /// wgpu's error.
        #[source]
        source: wgpu::RequestDeviceError,
    },
}

/// A device and queue with what the rest of the crate needs to know about them.
pub struct GpuContext {
    /// The wgpu instance the adapter came from.
    pub instance: wgpu::Instance,
    /// The chosen adapter.
    pub adapter: wgpu::Adapter,
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Name, backend and driver of the adapter.
    pub info: wgpu::AdapterInfo,
    /// Whether render and compute passes can write timestamps.
    pub timestamps: bool,
}

impl GpuContext {
    /// Opens the adapter selected by the usual wgpu environment variables (see the module docs).
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async())
    }

    async fn new_async() -> Result<Self, GpuError> {
        Self::open(Self::instance(None), None).await
    }

    /// A wgpu instance for the backends of `WGPU_BACKEND` (default: the primary ones), with
    /// the display connection of a windowing system when a window will be drawn into.
    pub fn instance(display: Option<Box<dyn wgpu::wgt::WgpuHasDisplayHandle>>) -> wgpu::Instance {
        let mut desc = match display {
            Some(d) => wgpu::InstanceDescriptor::new_with_display_handle(d),
            None => wgpu::InstanceDescriptor::new_without_display_handle(),
        };
        desc.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
        desc.flags = wgpu::InstanceFlags::default().with_env();
        wgpu::Instance::new(desc)
    }

    /// Opens the adapter selected by the usual wgpu environment variables on `instance`, one
    /// that can present to `surface` when given.
    pub async fn open(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Self, GpuError> {
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);

        let wanted_name = std::env::var("WGPU_ADAPTER_NAME")
            .ok()
            .map(|n| n.to_lowercase());
        let adapter = match &wanted_name {
            Some(name) => instance
                .enumerate_adapters(backends)
                .await
                .into_iter()
                .find(|a| {
                    a.get_info().name.to_lowercase().contains(name.as_str())
                        && surface.is_none_or(|s| a.is_surface_supported(s))
                }),
            None => instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::from_env()
                        .unwrap_or(wgpu::PowerPreference::HighPerformance),
                    compatible_surface: surface,
                    ..Default::default()
                })
                .await
                .ok(),
        };
        let Some(adapter) = adapter else {
            return Err(GpuError::NoAdapter {
                backends: format!("{backends:?}"),
                name_note: wanted_name
                    .map(|n| format!(", WGPU_ADAPTER_NAME contains {n:?}"))
                    .unwrap_or_default(),
            });
        };
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("verdant"),
                required_features,
                required_limits: adapter.limits(),
                ..Default::default()
            })
            .await
            .map_err(|source| GpuError::RequestDevice {
                adapter: info.name.clone(),
                source,
            })?;
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            info,
            timestamps,
        })
    }

    /// A one-line description: adapter name, backend and driver.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {} {})",
            self.info.name, self.info.backend, self.info.driver, self.info.driver_info
        )
    }

    /// Blocks until all submitted work has finished.
    pub fn wait_idle(&self) {
        // An error here means the device was lost; the next submission reports it.
        let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
    }
}
