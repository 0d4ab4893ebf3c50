//! The targets the renderer draws into: the formats and sizes it accepts, checked when it is
//! made or resized and on every recorded frame.

use super::{Renderer, RendererError};
use crate::gpu::Targets;

/// Depth formats the renderer draws into (the Hi-Z pyramid reads them as depth textures).
pub const DEPTH_FORMATS: [wgpu::TextureFormat; 2] = [
    wgpu::TextureFormat::Depth32Float,
    wgpu::TextureFormat::Depth24Plus,
];

impl Renderer {
    pub(super) fn check_targets(
        &self,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) -> Result<(), RendererError> {
        let t = &self.targets;
        let size = |tex: &wgpu::Texture| (tex.width(), tex.height());
        let describe = |tex: &wgpu::Texture| {
            format!(
                "{}x{} {:?} with {:?}",
                tex.width(),
                tex.height(),
                tex.format(),
                tex.usage()
            )
        };
        let c = color.texture();
        if size(c) != (t.width, t.height) {
            return Err(RendererError::Target {
                which: "colour",
                found: describe(c),
                expected: format!("{}x{}", t.width, t.height),
            });
        }
        let d = depth.texture();
        let mut usage =
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        if self.terrain_depth.is_some() {
            usage |= wgpu::TextureUsages::COPY_SRC;
        }
        if size(d) != (t.width, t.height)
            || d.format() != t.depth_format
            || !d.usage().contains(usage)
        {
            return Err(RendererError::Target {
                which: "depth",
                found: describe(d),
                expected: format!(
                    "{}x{} {:?} with {:?}",
                    t.width, t.height, t.depth_format, usage
                ),
            });
        }
        Ok(())
    }
}

pub(super) fn check_formats(targets: &Targets) -> Result<(), RendererError> {
    if crate::shaders::encode_srgb_for(targets.color_format).is_none() {
        return Err(RendererError::ColorFormat(targets.color_format));
    }
    if !DEPTH_FORMATS.contains(&targets.depth_format) {
        return Err(RendererError::DepthFormat(targets.depth_format));
    }
    Ok(())
}

/// Refuses a target size that the adapter cannot serve: beyond its largest 2D texture, or (with
/// grass) a Hi-Z pyramid larger than the largest storage buffer binding or buffer. Checked here,
/// against this device's limits, so that no wgpu validation error can follow.
pub(super) fn check_size(
    device: &wgpu::Device,
    width: u32,
    height: u32,
    grass: bool,
) -> Result<(), RendererError> {
    let limits = device.limits();
    let limit = limits.max_texture_dimension_2d;
    if width == 0 || height == 0 || width > limit || height > limit {
        return Err(RendererError::BadSize {
            width,
            height,
            limit,
        });
    }
    if grass {
        let bytes = hiz_bytes(width, height);
        let (limit_name, limit) =
            if limits.max_storage_buffer_binding_size <= limits.max_buffer_size {
                (
                    "max_storage_buffer_binding_size",
                    limits.max_storage_buffer_binding_size,
                )
            } else {
                ("max_buffer_size", limits.max_buffer_size)
            };
        if bytes > limit {
            let pixels = u64::from(width) * u64::from(height);
            return Err(RendererError::SizeBeyondLimit {
                width,
                height,
                what: "Hi-Z pyramid storage buffer",
                bytes,
                limit_name,
                limit,
                max_pixels: (pixels as f64 * limit as f64 / bytes as f64) as u64,
            });
        }
    }
    Ok(())
}

/// Bytes of the Hi-Z pyramid of a `width` x `height` target (f32 levels down to 1x1).
pub fn hiz_bytes(width: u32, height: u32) -> u64 {
    (0..crate::grass::hiz::mip_count(width, height))
        .map(|m| u64::from((width >> m).max(1)) * u64::from((height >> m).max(1)) * 4)
        .sum()
}
