//! What stops a renderer from being built or a frame from being recorded.

use super::ConfigError;
use crate::stream::AtlasError;
use crate::wind::WindError;
use crate::world::WorldError;

/// What stops a renderer from being built or a frame from being recorded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RendererError {
    /// A setting is out of its range
    /// ([`RendererConfig::validate`](super::RendererConfig::validate)).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A tile or the manifest could not be read.
    #[error(transparent)]
    World(#[from] WorldError),
    /// A plant type's mesh could not be made.
    #[error(transparent)]
    Plant(#[from] crate::plants::PlantError),
    /// A tile did not fit the atlas.
    #[error(transparent)]
    Atlas(#[from] AtlasError),
    /// The wind scene asked for does not exist or does not fit.
    #[error(transparent)]
    Wind(#[from] WindError),
    /// The device was made with limits below WebGPU's defaults, which the renderer's passes
    /// need ([`super::required_limits`]).
    #[error(
        "the device's limits are below what the renderer needs (WebGPU's defaults, \
         wgpu::Limits::default()): {}; make the device with required_limits: adapter.limits() \
         (or wgpu::Limits::default()) on an adapter that offers them",
        short.join(", ")
    )]
    DeviceLimits {
        /// Each limit that falls short: its name, the device's value and the least needed.
        short: Vec<String>,
    },
    /// The atlas slot count does not fit the adapter or the world.
    #[error(
        "an atlas of {slots} slots does not fit: it needs more slots than the world's {roots} \
         level-0 tiles and at most the adapter's {limit} texture array layers"
    )]
    AtlasSlots {
        /// Slots asked for.
        slots: u32,
        /// Level-0 tiles of the world (always resident).
        roots: u32,
        /// The adapter's `max_texture_array_layers`.
        limit: u32,
    },
    /// The device could not hold the atlas.
    #[error(
        "an atlas of {slots} slots needs {bytes} bytes of GPU memory, which the device could not \
         give ({reason}): choose fewer --atlas-slots"
    )]
    AtlasMemory {
        /// Slots asked for.
        slots: u32,
        /// The atlas's bytes (heights and grass maps).
        bytes: u64,
        /// The device's error.
        reason: String,
    },
    /// The device could not hold the renderer's other allocations, sized by the target size
    /// and the grass's, plants' and trees' settings.
    #[error(
        "{what} at {width}x{height}: the device could not give the GPU memory they need \
         ({reason}): choose a smaller --size, a shorter --grass-view-m, a larger \
         --grass-spacing-m, a smaller --tree-shadow-size or --aa off"
    )]
    DeviceMemory {
        /// What was being made, in words.
        what: &'static str,
        /// The target width.
        width: u32,
        /// The target height.
        height: u32,
        /// The device's error.
        reason: String,
    },
    /// The world's grass tiles are too large for the device to place their blades or plants.
    #[error(
        "the world's grass tiles (its finest) are {tile_m} m wide: {grid} {what} positions a side \
         at {cell_m} m apart, more than this device places in one pass ({most} a side); bake the \
         world with finer tiles (a smaller --cell-size or more levels) or space the blades wider \
         (--grass-spacing-m)"
    )]
    TileGrid {
        /// What is placed: `blade` or `plant`.
        what: &'static str,
        /// The grass tile's width, metres.
        tile_m: f32,
        /// The spacing of the grid, metres.
        cell_m: f32,
        /// Positions a side.
        grid: u64,
        /// The most positions a side the device dispatches.
        most: u64,
    },
    /// The target size is zero or beyond the adapter's limit.
    #[error("image size {width}x{height} is not supported (1 to {limit} pixels a side)")]
    BadSize {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
        /// The adapter's `max_texture_dimension_2d`.
        limit: u32,
    },
    /// The target size needs a buffer larger than the adapter allows (the grass's Hi-Z pyramid
    /// is one storage buffer bound whole, about 5.3 bytes a pixel).
    #[error(
        "image size {width}x{height} needs a {what} of {bytes} bytes, more than this adapter's \
         {limit_name} of {limit} bytes: choose a smaller size (about {max_pixels} pixels at most)"
    )]
    SizeBeyondLimit {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
        /// The buffer, in words (e.g. `Hi-Z pyramid storage buffer`).
        what: &'static str,
        /// Its size at this target size.
        bytes: u64,
        /// The adapter limit it exceeds (e.g. `max_storage_buffer_binding_size`).
        limit_name: &'static str,
        /// That limit.
        limit: u64,
        /// Roughly the most pixels (width times height) that fit.
        max_pixels: u64,
    },
    /// The CPU tile cache cannot hold a single tile, so no tile could ever be uploaded.
    #[error(
        "a CPU tile cache of {bytes} bytes cannot hold one tile of this world ({tile_bytes} \
         bytes): give it at least {min_mib} MiB"
    )]
    CacheTooSmall {
        /// The cache's ceiling asked for.
        bytes: u64,
        /// Bytes of one decoded tile.
        tile_bytes: u64,
        /// The smallest ceiling in MiB that holds one tile.
        min_mib: u64,
    },
    /// The colour format is not one the renderer draws into on any device.
    #[error(
        "colour format {0:?} is not supported (use an 8-bit RGBA/BGRA format, sRGB or not, \
         Rgb10a2Unorm or Rgba16Float; on a device with the features they need, Rgba32Float, \
         Rg11b10Ufloat or Rgba16Unorm)"
    )]
    ColorFormat(wgpu::TextureFormat),
    /// The colour format is one the renderer draws into, but not on this device: it cannot
    /// render into it, blend it or (with [`AntiAliasing::Msaa`](crate::aa::AntiAliasing::Msaa))
    /// multisample it without a feature the device was not made with.
    #[error(
        "colour format {format:?} cannot be drawn into on this device: {reason}; formats this \
         device draws into: {usable:?}"
    )]
    ColorFormatOnDevice {
        /// The format asked for.
        format: wgpu::TextureFormat,
        /// Why not, naming the wgpu feature that would make it work where there is one.
        reason: String,
        /// The colour formats the renderer draws into on this device.
        usable: Vec<wgpu::TextureFormat>,
    },
    /// The depth format is not one the renderer draws into.
    #[error("depth format {0:?} is not supported (use Depth32Float or Depth24Plus)")]
    DepthFormat(wgpu::TextureFormat),
    /// A target given to [`Renderer::record`](super::Renderer::record) does not match the
    /// renderer's targets: its format, usage, samples, size, or a view of more (or another
    /// size) than one mip level and one layer. `found` describes the view's texture and, for
    /// what only the view tells, wgpu's own words.
    #[error("the {which} target is {found}, but the renderer was made for {expected}")]
    Target {
        /// `"colour"` or `"depth"`.
        which: &'static str,
        /// What the target is.
        found: String,
        /// What the renderer expects.
        expected: String,
    },
    /// The frame's input cannot be drawn ([`FrameInput::check`](super::FrameInput::check)): a
    /// camera, time or jitter that is not finite, a field of view outside 0..180 degrees, a
    /// near plane not above zero, matrices that cannot be inverted. Returned by
    /// [`Renderer::record`](super::Renderer::record) after a
    /// [`Renderer::prepare`](super::Renderer::prepare) of such an input (which prepared
    /// nothing), and by the warm-up for such a camera.
    #[error("the frame's input cannot be drawn: {0}")]
    FrameInput(String),
    /// The renderer was resized, or its anti-aliasing switched, between
    /// [`Renderer::prepare`](super::Renderer::prepare) and
    /// [`Renderer::record`](super::Renderer::record): the prepared frame was for the renderer
    /// as it was, and is not drawn.
    #[error("{0} between prepare and record: prepare the frame again")]
    ChangedAfterPrepare(&'static str),
    /// [`Renderer::record`](super::Renderer::record) was called without a
    /// [`Renderer::prepare`](super::Renderer::prepare) before it.
    #[error("record was called without prepare: call prepare once before each record")]
    NotPrepared,
    /// The capture of the terrain-only depth was asked for with a depth format whose texels
    /// cannot be copied (use Depth32Float).
    #[error(
        "the terrain-only depth cannot be captured from a {0:?} target: its texels cannot be \
         copied (use Depth32Float)"
    )]
    DepthCapture(wgpu::TextureFormat),
}
