//! Fuzzing of the world's decoders: the tile readers (EXR heights, PNG type and density maps),
//! the DEM with its JSON sidecar, and `world.toml`. Each `check_*` function takes untrusted
//! bytes and panics only when a decoder breaks its promise: it must either refuse the input
//! with an error or return values inside the ranges the format states (heights finite and
//! within the manifest's range, grass types below the type count, the sizes asked for; a
//! manifest that validates and survives being written out and read back). [`Mutator`] is a
//! deterministic mutation loop over valid seeds, run briefly by the test suite
//! (`tests/fuzz.rs`) and for as long as asked with `VERDANT_FUZZ_ITERATIONS`.

use std::path::Path;

use super::dem::Dem;
use super::format::{ReadOptions, decode_density, decode_grass_types, decode_heights};
use super::manifest::Manifest;

/// Tile decoders' checks: `size` samples a side, against `options`.
pub struct TileCheck {
    /// Samples a side.
    pub size: u32,
    /// Height range and grass type count.
    pub options: ReadOptions,
}

impl TileCheck {
    /// Decodes `bytes` as a height file; panics if it is accepted with values out of range.
    pub fn heights(&self, bytes: &[u8]) -> bool {
        let Ok(h) = decode_heights(
            bytes,
            self.size,
            &self.options,
            Path::new("fuzz.height.exr"),
        ) else {
            return false;
        };
        let [lo, hi] = self.options.height_range_m;
        let tolerance = 1.0 + 0.01 * (hi - lo).abs();
        assert_eq!(
            h.len(),
            (self.size * self.size) as usize,
            "wrong sample count"
        );
        assert!(
            h.iter()
                .all(|v| v.is_finite() && *v >= lo - tolerance && *v <= hi + tolerance),
            "a height outside the range was accepted"
        );
        true
    }

    /// Decodes `bytes` as a type map; panics if it is accepted with an index out of range.
    pub fn grass_types(&self, bytes: &[u8]) -> bool {
        let Ok(t) = decode_grass_types(bytes, self.size, &self.options, Path::new("fuzz.type.png"))
        else {
            return false;
        };
        assert_eq!(
            t.len(),
            (self.size * self.size) as usize,
            "wrong sample count"
        );
        assert!(
            t.iter()
                .all(|&v| usize::from(v) < self.options.grass_type_count),
            "a grass type beyond the count was accepted"
        );
        true
    }

    /// Decodes `bytes` as a density map; panics if it is accepted at the wrong size.
    pub fn density(&self, bytes: &[u8]) -> bool {
        let Ok(d) = decode_density(bytes, self.size, Path::new("fuzz.density.png")) else {
            return false;
        };
        assert_eq!(
            d.len(),
            (self.size * self.size) as usize,
            "wrong sample count"
        );
        true
    }
}

/// Loads a DEM from `png` and `sidecar` written into `dir`; panics if it is accepted with a
/// height that is not finite or a size that does not match its samples.
pub fn check_dem(dir: &Path, png: &[u8], sidecar: &[u8]) -> bool {
    let png_path = dir.join("fuzz.png");
    std::fs::write(&png_path, png).expect("write the fuzz DEM");
    std::fs::write(dir.join("fuzz.json"), sidecar).expect("write the fuzz sidecar");
    let Ok(dem) = Dem::load(&png_path) else {
        return false;
    };
    assert!(
        dem.width >= 2 && dem.height >= 2,
        "a DEM under 2 samples a side"
    );
    assert_eq!(
        dem.heights.len(),
        dem.width as usize * dem.height as usize,
        "wrong sample count"
    );
    assert!(
        dem.heights.iter().all(|h| h.is_finite()),
        "a non-finite height was accepted"
    );
    assert!(
        dem.cell_ew_m.is_finite() && dem.cell_ew_m > 0.0,
        "a bad cell size was accepted"
    );
    assert!(
        dem.cell_ns_m.is_finite() && dem.cell_ns_m > 0.0,
        "a bad cell size was accepted"
    );
    true
}

/// Parses `bytes` as `world.toml`; panics if an accepted manifest does not validate or does not
/// read back the same after being written out.
pub fn check_manifest(bytes: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(bytes) else {
        return false;
    };
    let path = Path::new("fuzz/world.toml");
    let Ok(m) = Manifest::parse(text, path) else {
        return false;
    };
    m.validate(path).expect("an accepted manifest validates");
    let again = Manifest::parse(&m.to_toml(), path).expect("a written manifest reads back");
    assert_eq!(
        again, m,
        "a manifest changed when written out and read back"
    );
    true
}

/// A deterministic mutator of byte strings (xorshift64*): bit flips, interesting bytes,
/// truncation, chunk copies, insertions and splices with another seed.
pub struct Mutator(u64);

impl Mutator {
    /// A mutator from `seed` (any value).
    pub fn new(seed: u64) -> Self {
        Self(seed.max(1))
    }

    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }

    /// A mutation of `seed` (one to four edits), sometimes spliced with `other`.
    pub fn mutate(&mut self, seed: &[u8], other: &[u8]) -> Vec<u8> {
        let mut v = seed.to_vec();
        for _ in 0..1 + self.below(4) {
            let len = v.len();
            match self.below(7) {
                0 if len > 0 => {
                    let i = self.below(len);
                    v[i] ^= 1 << self.below(8);
                }
                1 if len > 0 => {
                    let i = self.below(len);
                    v[i] = [0, 1, 0x7f, 0x80, 0xff, b'9', b'-'][self.below(7)];
                }
                2 => v.truncate(self.below(len + 1)),
                3 if len > 0 => {
                    let a = self.below(len);
                    let n = self.below((len - a).min(64) + 1);
                    let at = self.below(len + 1);
                    let chunk: Vec<u8> = v[a..a + n].to_vec();
                    v.splice(at..at, chunk);
                }
                4 => {
                    let at = self.below(len + 1);
                    let n = 1 + self.below(8);
                    let bytes: Vec<u8> = (0..n).map(|_| self.next() as u8).collect();
                    v.splice(at..at, bytes);
                }
                5 if len > 0 && !other.is_empty() => {
                    let cut = self.below(len);
                    let from = self.below(other.len());
                    v.truncate(cut);
                    v.extend_from_slice(&other[from..]);
                }
                _ if len > 0 => {
                    // Overwrite a 4-byte word: lengths, sizes and floats live in such words.
                    let i = self.below(len.saturating_sub(3).max(1));
                    let word = [0u32, u32::MAX, 0x7fc0_0000, 0x7f80_0000, 1 << 20][self.below(5)];
                    for (k, b) in word.to_le_bytes().iter().enumerate() {
                        if i + k < len {
                            v[i + k] = *b;
                        }
                    }
                }
                _ => v.push(self.next() as u8),
            }
        }
        v
    }
}
