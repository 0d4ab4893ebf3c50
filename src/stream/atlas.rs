//! The tile atlas: texture arrays holding the heights, grass types and densities of resident
//! tiles, one array layer per slot. The slot count is fixed when the atlas is made.

use std::sync::Mutex;

use crate::world::{TileData, TileId};

/// Texture arrays with a fixed number of tile slots.
pub struct TileAtlas {
    /// Heights, `R32Float`, metres.
    pub heights: wgpu::Texture,
    /// Grass, `Rgba8Uint`: r = type index, g = density (0..=255), b = terrain material
    /// (`crate::world::Material`), a unused.
    pub grass: wgpu::Texture,
    /// Per slot, the identity of what was last written into it on the GPU, as
    /// `[level, x, y, generation]` u32s (16 bytes a slot): an upload writes it with the tile's
    /// samples, a derivation from its compute pass. The frame compares it with what it expects
    /// to read ([`TileAtlas::claimed`]) and counts mismatches as holes.
    pub identity: wgpu::Buffer,
    /// Per slot, the identity the CPU last gave it ([`TileAtlas::claim`]).
    claims: Mutex<Vec<[u32; 4]>>,
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
    #[error("tile {tile} has {found} samples a side, the atlas holds {expected}")]
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
        let identity = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("atlas identity"),
            size: u64::from(slots.max(1)) * 16,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Self {
            heights: make("atlas heights", wgpu::TextureFormat::R32Float),
            grass: make("atlas grass", wgpu::TextureFormat::Rgba8Uint),
            identity,
            claims: Mutex::new(vec![[0; 4]; slots as usize]),
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
        let identity = self.claim(slot, tile.id);
        queue.write_buffer(
            &self.identity,
            u64::from(slot) * 16,
            bytemuck::cast_slice(&identity),
        );
        Ok(())
    }

    /// Gives `slot` to `tile` with a new generation and returns its identity
    /// (`[level, x, y, generation]`, generations from 1): what the GPU's copy of the slot must
    /// hold once the upload or derivation that fills it has run.
    pub fn claim(&self, slot: u32, tile: TileId) -> [u32; 4] {
        let mut claims = self.claims.lock().unwrap_or_else(|e| e.into_inner());
        let Some(c) = claims.get_mut(slot as usize) else {
            return [0; 4];
        };
        let generation = c[3].wrapping_add(1).max(1);
        *c = [u32::from(tile.level), tile.x, tile.y, generation];
        *c
    }

    /// The identity `slot` was last given ([`TileAtlas::claim`]); zeros if never.
    pub fn claimed(&self, slot: u32) -> [u32; 4] {
        let claims = self.claims.lock().unwrap_or_else(|e| e.into_inner());
        claims.get(slot as usize).copied().unwrap_or([0; 4])
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
            material: TileData::material_map(g.chunks_exact(4).map(|t| t[2]).collect()),
        })
    }
}

/// Interleaves a tile's grass type, density and material into the atlas's RGBA8 texels.
pub fn pack_grass(tile: &TileData) -> Vec<u8> {
    tile.grass_type
        .iter()
        .zip(&tile.density)
        .enumerate()
        .flat_map(|(k, (&t, &d))| [t, d, tile.material_at(k), 0])
        .collect()
}
