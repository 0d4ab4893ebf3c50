// The integer hashes every stage draws its randomness from, and their mappings to floats;
// CPU mirror: src/hash.rs.

// lowbias32.
fn hash_u32(v: u32) -> u32 {
    var x = v;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}

// A hash of a 2D lattice point: the grass's colour-variation noise and the far field's, which
// must match.
fn hash2(x: i32, y: i32) -> u32 {
    var h = (u32(x) * 0x8da6b343u) ^ (u32(y) * 0xd8163841u);
    h ^= h >> 16u;
    h *= 0x7feb352du;
    h ^= h >> 15u;
    return h;
}

fn hash3(a: u32, b: u32, c: u32) -> u32 {
    return hash_u32(a ^ hash_u32(b ^ hash_u32(c)));
}

fn hash4(a: u32, b: u32, c: u32, d: u32) -> u32 {
    return hash_u32(a ^ hash_u32(b ^ hash_u32(c ^ hash_u32(d))));
}

// A hash mapped to [0, 1) exactly (its top 24 bits).
fn rand01(h: u32) -> f32 {
    return f32(h >> 8u) * (1.0 / 16777216.0);
}

// A hash mapped to [-1, 1) exactly (24 bits).
fn unit(h: u32) -> f32 {
    return f32(h >> 8u) * (1.0 / 16777216.0) * 2.0 - 1.0;
}
