//! CPU mirror of `shaders/shared/hash.wgsl`: the integer hashes and their mappings to floats
//! that every stage draws its randomness from. The CPU mirrors of the stages hash with these,
//! so that they pick the same random values as the shaders, bit for bit.

/// The integer hash (lowbias32), `hash_u32` of the WGSL.
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// A hash of a 2D lattice point: the wind pass's colour-variation noise and the far field's
/// (which must match the blades').
pub fn hash2(x: i32, y: i32) -> u32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343) ^ (y as u32).wrapping_mul(0xd816_3841);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h
}

/// [`hash_u32`] chained over three words.
pub fn hash3(a: u32, b: u32, c: u32) -> u32 {
    hash_u32(a ^ hash_u32(b ^ hash_u32(c)))
}

/// [`hash_u32`] chained over four words.
pub fn hash4(a: u32, b: u32, c: u32, d: u32) -> u32 {
    hash_u32(a ^ hash_u32(b ^ hash_u32(c ^ hash_u32(d))))
}

/// A hash mapped to [0, 1) exactly (its top 24 bits).
pub fn rand01(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A hash mapped to [-1, 1) exactly (24 bits).
pub fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0) * 2.0 - 1.0
}

/// Value noise in [0, 1) with a smoothstep fade, on the lattice of [`hash2`]: the grass's
/// colour variation (`value_noise` in `shaders/grass_wind.wgsl`), which the far field's colour
/// must match.
pub fn value_noise(p: glam::Vec2) -> f32 {
    let fl = p.floor();
    let (ix, iy) = (fl.x as i32, fl.y as i32);
    let f = p - fl;
    let u = f * f * (glam::Vec2::splat(3.0) - 2.0 * f);
    let r = |x: i32, y: i32| (hash2(x, y) >> 8) as f32 / 16_777_216.0;
    let (a, b, c, d) = (r(ix, iy), r(ix + 1, iy), r(ix, iy + 1), r(ix + 1, iy + 1));
    let ab = a + (b - a) * u.x;
    let cd = c + (d - c) * u.x;
    ab + (cd - ab) * u.y
}

/// The basis of [`fnv1a64`] over nothing yet.
pub const FNV_BASIS: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a, 64 bits, over `bytes`, going on from `h` ([`FNV_BASIS`] to begin): stable across
/// runs and platforms; the CPU side's fingerprints (a bake's inputs, a world's samples, a cached
/// body) and their names. Not for an adversary.
pub fn fnv1a64(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    /// FNV-1a's published values (the empty input is its basis), and going on from a hash is
    /// hashing the whole.
    #[test]
    fn fnv1a64_matches_its_reference_values() {
        assert_eq!(fnv1a64(FNV_BASIS, b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(FNV_BASIS, b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a64(FNV_BASIS, b"foobar"), 0x8594_4171_f739_67e8);
        assert_eq!(
            fnv1a64(fnv1a64(FNV_BASIS, b"foo"), b"bar"),
            fnv1a64(FNV_BASIS, b"foobar")
        );
    }

    #[test]
    fn floats_of_a_hash_span_their_ranges_exactly() {
        assert_eq!(rand01(0), 0.0);
        assert_eq!(rand01(u32::MAX), 1.0 - 1.0 / 16_777_216.0);
        assert_eq!(unit(0), -1.0);
        assert_eq!(unit(u32::MAX), 1.0 - 2.0 / 16_777_216.0);
    }

    #[test]
    fn chained_hashes_are_the_single_hash_applied_in_turn() {
        assert_eq!(hash3(1, 2, 3), hash_u32(1 ^ hash_u32(2 ^ hash_u32(3))));
        assert_eq!(hash4(1, 2, 3, 4), hash_u32(1 ^ hash3(2, 3, 4)));
        // lowbias32 maps 0 to 0 and scatters its neighbours.
        assert_eq!(hash_u32(0), 0);
        assert_ne!(hash_u32(1), hash_u32(2));
    }
}
