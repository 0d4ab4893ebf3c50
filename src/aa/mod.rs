//! Anti-aliasing of the frame: the methods a [`crate::Renderer`] can use; the temporal
//! method's stage ([`taa`], `shaders/aa_taa.wgsl`) with its CPU mirror ([`taa_cpu`]), and the
//! multisampling stage ([`msaa`], `shaders/aa_msaa.wgsl`) with its mirror ([`msaa_cpu`]).
//!
//! Thin grass blades are narrower than a pixel at a few metres: drawn once per pixel centre
//! they cover whole pixels or none, so the frame is darker and more saturated than the scene
//! and crawls in motion. Temporal anti-aliasing spreads the samples of each pixel over frames:
//! the projection is shifted within the pixel every frame ([`jitter`]) and the frames are
//! folded into a history that follows the surfaces on screen.

use std::fmt;
use std::str::FromStr;

use glam::Vec2;

pub mod msaa;
pub mod msaa_cpu;
pub mod taa;
pub mod taa_cpu;

/// How the frame is anti-aliased.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AntiAliasing {
    /// None: one sample at each pixel's centre. A single still frame of a scene, where no
    /// history could build up, is drawn best so.
    Off,
    /// Temporal: a jittered projection every frame, folded into a reprojected, clipped
    /// history ([`taa::Taa`]). The default: against the truth it errs less than no
    /// anti-aliasing in every sequence and along every path `bench aa` measures, at 960x540
    /// and 1920x1080, for 3.0% and 7.2% of the frame's GPU time on an H100 (README,
    /// "Anti-aliasing"). Its first frame, or
    /// the first after a cut, is the current frame alone, reconstructed at the pixels'
    /// centres.
    #[default]
    Taa,
    /// Multisampling of the grass, four samples a pixel, each blade's sub-pixel width kept as
    /// coverage ([`msaa::Msaa`]).
    Msaa,
}

impl AntiAliasing {
    /// Every method, in the order the benchmarks list them.
    pub const ALL: [AntiAliasing; 3] = [AntiAliasing::Off, AntiAliasing::Taa, AntiAliasing::Msaa];

    /// The method's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            AntiAliasing::Off => "off",
            AntiAliasing::Taa => "taa",
            AntiAliasing::Msaa => "msaa",
        }
    }
}

impl fmt::Display for AntiAliasing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for AntiAliasing {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|m| m.name()).collect();
                format!(
                    "unknown anti-aliasing {s:?}: expected one of {}",
                    names.join(", ")
                )
            })
    }
}

/// Samples in the jitter sequence before it repeats.
pub const JITTER_SAMPLES: u64 = 16;

/// The radical inverse of `i` in `base`: the Halton sequence's coordinate.
fn halton(mut i: u64, base: u64) -> f32 {
    let mut f = 1.0f64;
    let mut r = 0.0f64;
    while i > 0 {
        f /= base as f64;
        r += f * (i % base) as f64;
        i /= base;
    }
    r as f32
}

/// The sub-pixel offset of frame `frame` (pixels, each coordinate in -0.5..0.5): the
/// Halton (2, 3) sequence from its second point, repeating every [`JITTER_SAMPLES`] frames, so
/// that any run of frames spreads its samples evenly over the pixel.
pub fn jitter(frame: u64) -> Vec2 {
    let i = frame % JITTER_SAMPLES + 1;
    Vec2::new(halton(i, 2), halton(i, 3)) - 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_refused_with_the_choices() {
        for m in AntiAliasing::ALL {
            assert_eq!(m.name().parse::<AntiAliasing>(), Ok(m));
        }
        let err = "msaa16".parse::<AntiAliasing>().unwrap_err();
        assert!(
            err.contains("msaa16") && err.contains("off, taa, msaa"),
            "{err}"
        );
    }

    #[test]
    fn jitter_covers_the_pixel_evenly() {
        let n = JITTER_SAMPLES as usize;
        let points: Vec<Vec2> = (0..JITTER_SAMPLES).map(jitter).collect();
        assert_eq!(jitter(JITTER_SAMPLES), points[0]);
        let mean = points.iter().copied().sum::<Vec2>() / n as f32;
        assert!(mean.length() < 0.05, "mean {mean}");
        // Every quarter of the pixel gets about a quarter of the samples.
        for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let k = points
                .iter()
                .filter(|p| p.x * sx > 0.0 && p.y * sy > 0.0)
                .count();
            assert!(
                (n / 4 - 1..=n / 4 + 1).contains(&k),
                "quadrant ({sx}, {sy}): {k}"
            );
        }
        assert!(points.iter().all(|p| p.abs().max_element() < 0.5));
    }
}
