//! Copying GPU buffers and textures back to the CPU, waiting for the GPU: for tests, tools and
//! headless captures, never inside a frame of the renderer (which reads its figures through a
//! ring of buffers mapped on submit, see `crate::renderer`).

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
    let all = map_and_read(device, &buffer, ..)?;
    let mut out = Vec::with_capacity((row * h) as usize);
    for y in 0..h as usize {
        let start = y * padded as usize;
        out.extend_from_slice(&all[start..start + row as usize]);
    }
    Ok(out)
}

/// Reads `range` of `buffer` (which needs `COPY_SRC`) through a staging buffer.
pub fn read_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    range: impl std::ops::RangeBounds<u64>,
) -> Result<Vec<u8>, ReadbackError> {
    use std::ops::Bound;
    let start = match range.start_bound() {
        Bound::Included(&s) => s,
        Bound::Excluded(&s) => s + 1,
        Bound::Unbounded => 0,
    };
    let end = match range.end_bound() {
        Bound::Included(&e) => e + 1,
        Bound::Excluded(&e) => e,
        Bound::Unbounded => buffer.size(),
    };
    let size = end.saturating_sub(start);
    if size == 0 {
        return Ok(Vec::new());
    }
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, start, &staging, 0, size);
    queue.submit([encoder.finish()]);
    map_and_read(device, &staging, ..)
}

/// Like [`read_buffer`], as a vector of plain values (`T` of 4 or 8 bytes, say).
pub fn read_buffer_pod<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    range: impl std::ops::RangeBounds<u64>,
) -> Result<Vec<T>, ReadbackError> {
    Ok(bytemuck::pod_collect_to_vec(&read_buffer(
        device, queue, buffer, range,
    )?))
}

/// Maps a `MAP_READ` buffer, waits for it and copies `range` out; unmaps it again.
fn map_and_read(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    range: std::ops::RangeFull,
) -> Result<Vec<u8>, ReadbackError> {
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, range, move |r| {
        let _ = tx.send(r);
    });
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    match rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(ReadbackError::Map(e.to_string())),
        Err(e) => return Err(ReadbackError::Map(e.to_string())),
    }
    let out = buffer
        .get_mapped_range(..)
        .map_err(|e| ReadbackError::Map(e.to_string()))?
        .to_vec();
    buffer.unmap();
    Ok(out)
}
