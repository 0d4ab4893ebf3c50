// The integer hash every stage draws its randomness from (lowbias32); CPU mirror:
// `hash_u32` in src/stream/derive_child.rs.

fn hash_u32(v: u32) -> u32 {
    var x = v;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}
