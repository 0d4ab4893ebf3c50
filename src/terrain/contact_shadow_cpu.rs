//! CPU mirror of `shaders/terrain_contact_shadow.wgsl` (the GPU stage:
//! [`crate::terrain::contact_shadow`]): each pixel's contact-shadow factor, loop for loop like
//! the shader's compute pass; a test compares the two.

use glam::{Mat4, Vec2, Vec3, Vec4};

use super::contact_shadow::ContactShadows;

impl ContactShadows {
    /// The colour factor of every pixel of a `width` x `height` reverse-Z depth image (row-major,
    /// top row first; 0 where nothing was drawn), seen through the camera-relative
    /// `view_proj`, with the sun toward `sun_dir`.
    pub fn factors(
        &self,
        depth: &[f32],
        width: u32,
        height: u32,
        view_proj: Mat4,
        sun_dir: Vec3,
    ) -> Vec<f32> {
        let inv = view_proj.inverse();
        let size = Vec2::new(width as f32, height as f32);
        let point = |x: u32, y: u32, d: f32| {
            let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let ndc = Vec2::new(c.x / size.x * 2.0 - 1.0, 1.0 - c.y / size.y * 2.0);
            let p = inv * Vec4::new(ndc.x, ndc.y, d, 1.0);
            p.truncate() / p.w
        };
        let at = |x: u32, y: u32| depth[(y * width + x) as usize];
        let mut out = vec![1.0f32; depth.len()];
        for y in 0..height {
            for x in 0..width {
                let d = at(x, y);
                if d <= 0.0 {
                    continue;
                }
                let p = point(x, y, d);
                let dist = p.length();
                if dist >= self.fade_end_m {
                    continue;
                }
                let mut shadowed = false;
                // Steps interpolated in clip space; the scene under a step at clip w and depth
                // qd lies at view depth w * qd / sd (reverse-Z to infinity).
                let c0 = view_proj * p.extend(1.0);
                let c1 = view_proj * (p + sun_dir * self.ray_m).extend(1.0);
                for i in 1..=self.steps {
                    let c = c0.lerp(c1, i as f32 / self.steps as f32);
                    if c.w <= 0.0 {
                        break;
                    }
                    let n = c.truncate() / c.w;
                    let s = Vec2::new((n.x * 0.5 + 0.5) * size.x, (0.5 - n.y * 0.5) * size.y);
                    if s.x < 0.0 || s.y < 0.0 || s.x >= size.x || s.y >= size.y {
                        break;
                    }
                    let (sx, sy) = (s.x.floor() as u32, s.y.floor() as u32);
                    if (sx, sy) == (x, y) {
                        continue;
                    }
                    let sd = at(sx, sy);
                    if sd <= 0.0 {
                        continue;
                    }
                    let behind = c.w * (1.0 - n.z / sd);
                    let bias = 0.02 + 0.004 * c.w;
                    if behind > bias && behind < self.thickness_m {
                        shadowed = true;
                        break;
                    }
                }
                if shadowed {
                    let t = ((dist - self.fade_start_m) / (self.fade_end_m - self.fade_start_m))
                        .clamp(0.0, 1.0);
                    let fade = 1.0 - t * t * (3.0 - 2.0 * t);
                    out[(y * width + x) as usize] = 1.0 + (self.shade - 1.0) * fade;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use glam::DVec3;

    /// A camera 1.7 m over flat ground, looking down at 30 degrees at a post 3 m away, 1 m
    /// tall: its shadow is found where geometry puts it, and nowhere else.
    #[test]
    fn a_post_shadows_the_ground_behind_it_from_the_sun_and_nothing_else() {
        let (w, h) = (96u32, 64u32);
        let camera = Camera::new(DVec3::new(0.0, 0.0, 1.7), 0.0, -30.0);
        let vp = camera.view_proj_relative(w as f32 / h as f32);
        let inv = vp.inverse();
        // The scene: ground at z = -1.7 (camera-relative), a box post of 0.2 m at x in 2.9..3.1,
        // y in -0.1..0.1, up to z = -0.7; ray-cast per pixel.
        let mut depth = vec![0.0f32; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let ndc = Vec2::new(
                    (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                    1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
                );
                let p = inv * Vec4::new(ndc.x, ndc.y, 0.5, 1.0);
                let dir = (p.truncate() / p.w).normalize();
                let mut t_hit = f32::MAX;
                if dir.z < 0.0 {
                    t_hit = -1.7 / dir.z;
                }
                // Slab test against the post.
                let (lo, hi) = (Vec3::new(2.9, -0.1, -1.7), Vec3::new(3.1, 0.1, -0.7));
                let t1 = (lo - Vec3::ZERO) / dir;
                let t2 = (hi - Vec3::ZERO) / dir;
                let (tmin, tmax) = (t1.min(t2).max_element(), t1.max(t2).min_element());
                if tmax >= tmin.max(0.0) {
                    t_hit = t_hit.min(tmin.max(0.0));
                }
                if t_hit < f32::MAX {
                    let c = vp * (dir * t_hit).extend(1.0);
                    depth[(y * w + x) as usize] = c.z / c.w;
                }
            }
        }
        // The sun in the north at 35 degrees: the post's shadow falls south of it (-y), in
        // view, 1 / tan(35 deg) = 1.4 m long from its top; the ray (1.2 m) finds the post
        // from up to 1 m away.
        let sun = Vec3::new(0.0, 0.819, 0.574).normalize();
        let s = ContactShadows::default();
        let f = s.factors(&depth, w, h, vp, sun);
        let mut behind = 0;
        let mut elsewhere = 0;
        for y in 0..h {
            for x in 0..w {
                let d = depth[(y * w + x) as usize];
                let ndc = Vec2::new(
                    (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                    1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
                );
                let p = inv * Vec4::new(ndc.x, ndc.y, d, 1.0);
                let p = p.truncate() / p.w;
                let on_ground = (p.z + 1.7).abs() < 0.01;
                let dark = f[(y * w + x) as usize] < 0.9;
                // In the shadow by geometry (and within the ray's reach): ground south of the
                // post within its width. Clear: ground away from the post's shadow, by more than
                // a pixel's footprint (about 0.3 m deep at this size) from the post itself.
                let in_shadow =
                    on_ground && (2.93..3.07).contains(&p.x) && (-0.9..-0.15).contains(&p.y);
                let clear = on_ground && (p.y > 0.2 || p.x < 2.6 || p.x > 3.8 || p.y < -1.8);
                if in_shadow && dark {
                    behind += 1;
                }
                if clear && dark {
                    elsewhere += 1;
                }
            }
        }
        assert!(
            behind > 3,
            "the post's shadow was not found ({behind} pixels)"
        );
        assert_eq!(elsewhere, 0, "{elsewhere} pixels dark away from the shadow");
    }
}
