//! The features of the grass model that a scene can switch off: model no more than a scene
//! needs. Each costs GPU time and contributes to the image; `verdant bench features` measures
//! both.

use std::fmt;
use std::str::FromStr;

/// A switchable feature.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Feature {
    /// Wind sources (directional, omni, vortex) on top of the ambient wind.
    WindSources,
    /// The trail the camera leaves in the grass.
    Interaction,
    /// Detail bending: edge flutter and whole-blade sway from smoothed triangle waves.
    DetailBending,
    /// Light through the blade when the sun is behind it.
    Translucency,
    /// Specular highlights with per-type gloss.
    Specular,
    /// Ambient occlusion from root to tip.
    AmbientOcclusion,
    /// Colour variation from world-space noise at the blade's root.
    ColorVariation,
    /// Ground darkened under dense grass.
    GroundDarkening,
    /// Beyond the grass's view distance, the terrain shaded with what the blades would show.
    FarField,
    /// Sun shadows cast by the terrain.
    Shadows,
    /// Plants among the grass: the world's flowers, ferns and bushes.
    Plants,
    /// Trees: the world's plant types of at least [`crate::world::TREE_MIN_HEIGHT_M`], placed
    /// on a coarser grid out to the fog.
    Trees,
    /// The trees' sun shadows on everything near the camera, from a cascaded shadow map
    /// ([`crate::plants::shadow`]).
    TreeShadows,
    /// Leaves shed by the trees and carried by the wind ([`crate::plants::particles`]).
    Particles,
}

impl Feature {
    /// Every feature, in bit order.
    pub const ALL: [Feature; 14] = [
        Feature::WindSources,
        Feature::Interaction,
        Feature::DetailBending,
        Feature::Translucency,
        Feature::Specular,
        Feature::AmbientOcclusion,
        Feature::ColorVariation,
        Feature::GroundDarkening,
        Feature::FarField,
        Feature::Shadows,
        Feature::Plants,
        Feature::Trees,
        Feature::TreeShadows,
        Feature::Particles,
    ];

    /// The bit of this feature in [`Features::bits`] (and in the shaders).
    pub fn bit(self) -> u32 {
        1 << Self::ALL.iter().position(|f| *f == self).expect("listed")
    }

    /// The name used on the command line and in manifests.
    pub fn name(self) -> &'static str {
        match self {
            Feature::WindSources => "wind-sources",
            Feature::Interaction => "interaction",
            Feature::DetailBending => "detail-bending",
            Feature::Translucency => "translucency",
            Feature::Specular => "specular",
            Feature::AmbientOcclusion => "ambient-occlusion",
            Feature::ColorVariation => "color-variation",
            Feature::GroundDarkening => "ground-darkening",
            Feature::FarField => "far-field",
            Feature::Shadows => "shadows",
            Feature::Plants => "plants",
            Feature::Trees => "trees",
            Feature::TreeShadows => "tree-shadows",
            Feature::Particles => "particles",
        }
    }
}

impl fmt::Display for Feature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Feature {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Feature::ALL
            .iter()
            .copied()
            .find(|f| f.name() == s.trim())
            .ok_or_else(|| {
                let names: Vec<&str> = Feature::ALL.iter().map(|f| f.name()).collect();
                format!("unknown feature {s:?} (features: {})", names.join(", "))
            })
    }
}

/// A set of switched-on features.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Features(u32);

impl Default for Features {
    /// Everything on.
    fn default() -> Self {
        Self::all()
    }
}

impl Features {
    /// Every feature on.
    pub fn all() -> Self {
        Self(Feature::ALL.iter().map(|f| f.bit()).sum())
    }

    /// Every feature off.
    pub fn none() -> Self {
        Self(0)
    }

    /// This set with `f` switched off.
    pub fn without(self, f: Feature) -> Self {
        Self(self.0 & !f.bit())
    }

    /// This set with `f` switched on.
    pub fn with(self, f: Feature) -> Self {
        Self(self.0 | f.bit())
    }

    /// This set with each of `off` switched off, then each of `on` switched on.
    pub fn switched(self, off: &[Feature], on: &[Feature]) -> Self {
        let s = off.iter().fold(self, |s, f| s.without(*f));
        on.iter().fold(s, |s, f| s.with(*f))
    }

    /// Whether `f` is on.
    pub fn has(self, f: Feature) -> bool {
        self.0 & f.bit() != 0
    }

    /// The bits, as the shaders read them.
    pub fn bits(self) -> u32 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bits_are_distinct() {
        let mut seen = 0;
        for f in Feature::ALL {
            assert_eq!(f.name().parse::<Feature>().unwrap(), f);
            assert_eq!(seen & f.bit(), 0);
            seen |= f.bit();
            assert!(!Features::all().without(f).has(f));
            assert!(Features::none().with(f).has(f));
            assert_eq!(Features::all().switched(&[f], &[f]), Features::all());
        }
        assert!(
            "sparkles"
                .parse::<Feature>()
                .unwrap_err()
                .contains("translucency")
        );
    }
}
