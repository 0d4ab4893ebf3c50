// A fragment's colour as it is written to the target. Shading is linear; an sRGB target
// encodes on store, a float target keeps linear values, and a plain unorm target (such as a
// window's Bgra8Unorm) gets the sRGB encoding here (`ENCODE_SRGB`, set per pipeline).

override ENCODE_SRGB: bool = false;

fn output_color(c: vec3<f32>) -> vec4<f32> {
    if ENCODE_SRGB {
        let x = max(c, vec3<f32>(0.0));
        let lo = x * 12.92;
        let hi = 1.055 * pow(x, vec3<f32>(1.0 / 2.4)) - 0.055;
        return vec4<f32>(select(hi, lo, x <= vec3<f32>(0.0031308)), 1.0);
    }
    return vec4<f32>(c, 1.0);
}
