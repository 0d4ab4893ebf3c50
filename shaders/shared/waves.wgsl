// Crysis' smoothed triangle wave (GPU Gems 3, ch. 16): a cheap, smooth stand-in for a sine
// in 0..1 with period 1, for the detail bending of blades and plants.

fn smooth_triangle(x: f32) -> f32 {
    let t = abs(fract(x + 0.5) * 2.0 - 1.0);
    return t * t * (3.0 - 2.0 * t);
}
