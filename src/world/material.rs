//! Terrain materials: what the ground is made of where a land-cover map says so (soil, crops in
//! rows, bare rock, sand, water, a road, snow). A world baked with a cover table that names
//! materials stores one byte a sample in `{x}_{y}.material.png` beside its type and density
//! maps; material 0 ([`Material::Default`]) leaves the ground to its grass type, as in every
//! world baked without one. The deferred terrain shading draws each material
//! (`shaders/shared/terrain_shading.wgsl`; CPU mirror: `crate::terrain::material`).

use std::fmt;

/// One terrain material; its `u8` is the byte stored in the tile's material map and read by the
/// shaders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Material {
    /// The ground of the sample's grass type (soil tinted by the grass, rock where bare).
    Default = 0,
    /// Bare brown soil.
    Soil = 1,
    /// Tilled soil in rows (cropland).
    Crops = 2,
    /// Bare rock.
    Rock = 3,
    /// Sand.
    Sand = 4,
    /// Water: a dark flat surface that reflects the sky.
    Water = 5,
    /// A paved road or built-up ground.
    Road = 6,
    /// Snow and ice.
    Snow = 7,
}

/// How many materials there are; a stored byte at or above it is refused.
pub const MATERIAL_COUNT: usize = 8;

impl Material {
    /// Every material, in byte order.
    pub const ALL: [Material; MATERIAL_COUNT] = [
        Material::Default,
        Material::Soil,
        Material::Crops,
        Material::Rock,
        Material::Sand,
        Material::Water,
        Material::Road,
        Material::Snow,
    ];

    /// The name a cover table gives it.
    pub fn name(self) -> &'static str {
        match self {
            Material::Default => "default",
            Material::Soil => "soil",
            Material::Crops => "crops",
            Material::Rock => "rock",
            Material::Sand => "sand",
            Material::Water => "water",
            Material::Road => "road",
            Material::Snow => "snow",
        }
    }

    /// The material of that name, if any.
    pub fn from_name(name: &str) -> Option<Material> {
        Material::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The material a stored byte stands for, if any.
    pub fn from_byte(byte: u8) -> Option<Material> {
        Material::ALL.get(usize::from(byte)).copied()
    }

    /// Every name, comma-separated (for errors).
    pub fn names() -> String {
        Material::ALL.map(Material::name).join(", ")
    }
}

impl fmt::Display for Material {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_bytes_round_trip() {
        for (k, m) in Material::ALL.into_iter().enumerate() {
            assert_eq!(m as usize, k);
            assert_eq!(Material::from_byte(k as u8), Some(m));
            assert_eq!(Material::from_name(m.name()), Some(m));
        }
        assert_eq!(Material::from_byte(MATERIAL_COUNT as u8), None);
        assert_eq!(Material::from_name("lava"), None);
    }
}
