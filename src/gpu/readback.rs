//! Copying a rendered texture back to the CPU.

use thiserror::Error;

/// Why a readback failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ReadbackError {
    /// Mapping the staging buffer failed (device lost, usually).
    #[error("mapping the readback buffer failed: {0}")]
    Map(String),
    /// The texture's format cannot be read back this way.
    #[error("cannot read back a texture of format {0:?}")]
    Format(wgpu::TextureFormat),
}

/// Reads an RGBA8 texture (linear or sRGB) into tightly packed rows, top row first.
pub fn read_texture_rgba8(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
) -> Result<Vec<u8>, ReadbackError> {
    let format = texture.format();
    if format.block_copy_size(None) != Some(4) {
        return Err(ReadbackError::Format(format));
    }
    read_texture_layer(device, queue, texture, 0)
}

/// Reads one array layer of a texture of an uncompressed colour format into tightly packed
/// rows, first row first.
pub fn read_texture_layer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    layer: u32,
) -> Result<Vec<u8>, ReadbackError> {
    read_texture_level(device, queue, texture, 0, layer)
}

/// Reads mip level `mip` of array layer `layer` of a texture of an uncompressed colour format
/// into tightly packed rows, first row first.
pub fn read_texture_level(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    mip: u32,
    layer: u32,
) -> Result<Vec<u8>, ReadbackError> {
    let format = texture.format();
    let Some(texel) = format.block_copy_size(None) else {
        return Err(ReadbackError::Format(format));
    };
    let (w, h) = (
        (texture.width() >> mip).max(1),
        (texture.height() >> mip).max(1),
    );
    let row = w * texel;
    let padded =
        row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: u64::from(padded) * u64::from(h),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: mip,
            origin: wgpu::Origin3d {
                x: 0,
                y: 0,
                z: layer,
            },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    match rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(ReadbackError::Map(e.to_string())),
        Err(e) => return Err(ReadbackError::Map(e.to_string())),
    }
    let mut out = Vec::with_capacity((row * h) as usize);
    {
        let view = buffer
            .get_mapped_range(..)
            .map_err(|e| ReadbackError::Map(e.to_string()))?;
        for y in 0..h as usize {
            let start = y * padded as usize;
            out.extend_from_slice(&view[start..start + row as usize]);
        }
    }
    buffer.unmap();
    Ok(out)
}
