//! The tile atlas: texture arrays holding the heights, grass types and densities of resident
//! tiles, one array layer per slot. The slot count is fixed when the atlas is made.

use crate::world::TileData;

/// Texture arrays with a fixed number of tile slots.
pub struct TileAtlas {
    /// Heights, `R32Float`, metres.
    pub heights: wgpu::Texture,
    /// Grass, `Rgba8Uint`: r = type index, g = density (0..=255), b and a unused.
    pub grass: wgpu::Texture,
    size: u32,
    slots: u32,
}

/// A tile that does not fit the atlas it is uploaded to.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AtlasError {
    /// The slot index is past the last slot.
    #[error("atlas slot {slot} is out of range (the atlas has {slots} slots)")]
    SlotOutOfRange {
        /// The slot asked for.
        slot: u32,
        /// Slots in the atlas.
        slots: u32,
    },
    /// The tile's sample count differs from the atlas's.
    #[error("tile {tile:?} has {found} samples a side, the atlas holds {expected}")]
    WrongSize {
        /// The tile.
        tile: crate::world::TileId,
        /// The atlas's samples a side.
        expected: u32,
        /// The tile's.
        found: u32,
    },
}

impl TileAtlas {
    /// An atlas of `slots` layers of `size` x `size` samples.
    pub fn new(device: &wgpu::Device, size: u32, slots: u32) -> Self {
        let make = |label, format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: size,
                    height: size,
                    depth_or_array_layers: slots,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_DST
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        };
        Self {
            heights: make("atlas heights", wgpu::TextureFormat::R32Float),
            grass: make("atlas grass", wgpu::TextureFormat::Rgba8Uint),
            size,
            slots,
        }
    }

    /// Number of slots.
    pub fn slots(&self) -> u32 {
        self.slots
    }

    /// Samples a side of each slot.
    pub fn size(&self) -> u32 {
        self.size
    }

    /// Bytes of GPU memory the atlas holds.
    pub fn byte_size(&self) -> u64 {
        u64::from(self.size) * u64::from(self.size) * u64::from(self.slots) * 8
    }

    /// Writes `tile` into `slot`.
    pub fn upload(
        &self,
        queue: &wgpu::Queue,
        slot: u32,
        tile: &TileData,
    ) -> Result<(), AtlasError> {
        if slot >= self.slots {
            return Err(AtlasError::SlotOutOfRange {
                slot,
                slots: self.slots,
            });
        }
        if tile.size != self.size {
            return Err(AtlasError::WrongSize {
                tile: tile.id,
                expected: self.size,
                found: tile.size,
            });
        }
        let write = |texture: &wgpu::Texture, bytes: &[u8], texel: u32| {
            queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: slot,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                bytes,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.size * texel),
                    rows_per_image: Some(self.size),
                },
                wgpu::Extent3d {
                    width: self.size,
                    height: self.size,
                    depth_or_array_layers: 1,
                },
            );
        };
        write(&self.heights, bytemuck::cast_slice(&tile.heights), 4);
        write(&self.grass, &pack_grass(tile), 4);
        Ok(())
    }
}

impl TileAtlas {
    /// Reads slot `slot` back as tile data labelled `id` (for tests and tools; it waits for
    /// the GPU).
    pub fn read_back(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        slot: u32,
        id: crate::world::TileId,
    ) -> Result<TileData, crate::gpu::ReadbackError> {
        let h = crate::gpu::read_texture_layer(device, queue, &self.heights, slot)?;
        let g = crate::gpu::read_texture_layer(device, queue, &self.grass, slot)?;
        Ok(TileData {
            id,
            size: self.size,
            heights: bytemuck::pod_collect_to_vec(&h),
            grass_type: g.chunks_exact(4).map(|t| t[0]).collect(),
            density: g.chunks_exact(4).map(|t| t[1]).collect(),
        })
    }
}

/// Interleaves a tile's grass type and density into the atlas's RGBA8 texels.
pub fn pack_grass(tile: &TileData) -> Vec<u8> {
    tile.grass_type
        .iter()
        .zip(&tile.density)
        .flat_map(|(&t, &d)| [t, d, 0, 0])
        .collect()
}
