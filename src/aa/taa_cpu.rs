//! CPU mirror of the temporal anti-aliasing resolve (`shaders/aa_taa.wgsl`, stage
//! [`crate::aa::taa`]): the same per-pixel rule over images in memory, for the test that
//! compares the two and for reading the method without a GPU.

use glam::{Mat4, Vec2, Vec3, Vec4};

/// One resolve's inputs: images row-major, top row first.
pub struct ResolveInput<'a> {
    /// Width and height in pixels.
    pub size: (u32, u32),
    /// The current (jittered) frame, linear colour.
    pub current: &'a [Vec3],
    /// Its depth (reverse-Z: 1 near, 0 at infinity).
    pub depth: &'a [f32],
    /// The last history: linear colour, and in `w` the samples it holds (0: none).
    pub history: &'a [Vec4],
    /// The blades' motion vectors ([`crate::aa::taa::MOTION_FORMAT`]): the pixels a blade's
    /// point moved since the last frame (x, y), its depth (z), 1 where a blade wrote it (w), 2
    /// where a falling leaf marked its pixel as one whose history does not hold it (the pixel
    /// starts again from its current sample). Empty: none anywhere.
    pub motion: &'a [Vec4],
    /// The last frame's spreads: each pixel's samples' variance over time per YCoCg channel
    /// (xyz). Empty: none anywhere.
    pub spread: &'a [Vec4],
    /// See [`crate::aa::taa::reprojection`].
    pub reproject: Mat4,
    /// Most samples a history holds.
    pub max_samples: f32,
    /// Standard deviations of the neighbourhood the history is clipped to.
    pub clip_sigma: f32,
    /// How fast the most samples fall with the pixels a surface moved.
    pub motion_falloff: f32,
    /// Standard deviations of the pixel's own spread, around the current sample, that the
    /// clip's box also reaches (0: none).
    pub pixel_spread: f32,
    /// How much faster the most samples fall with the pixels of parallax (what a surface
    /// moved beyond the camera's turn).
    pub parallax_falloff: f32,
    /// The fewest samples a moving surface's history keeps.
    pub min_samples: f32,
    /// The current frame's jitter (pixels, x right, y down): its sample of a pixel shows the
    /// scene at the pixel's centre minus it.
    pub jitter: Vec2,
    /// The standard deviation (pixels) of the Gaussian that reconstructs the current frame
    /// at each pixel's centre from its 3x3 samples (0: the pixel's own sample).
    pub reconstruct_px: f32,
    /// How much faster the most samples fall with the pixels of a blade's own motion (its
    /// motion vector beyond where its depth alone would have taken it).
    pub sway_falloff: f32,
    /// Start every pixel again.
    pub reset: bool,
}

/// How far (relative) the frame's depth may lie from a blade's motion vector's depth for the
/// motion to be the pixel's (the shader's `MOTION_DEPTH_TOLERANCE`).
pub const MOTION_DEPTH_TOLERANCE: f32 = 2e-3;

/// The pixels a surface may move in a frame and still reach for its own spread (the shader's
/// `SPREAD_MOTION_PX`): the reach falls linearly to nothing there.
pub const SPREAD_MOTION_PX: f32 = 0.5;

/// Luma and the two chroma differences.
fn ycocg(c: Vec3) -> Vec3 {
    Vec3::new(
        (c.x + 2.0 * c.y + c.z) / 4.0,
        (c.x - c.z) / 2.0,
        (2.0 * c.y - c.x - c.z) / 4.0,
    )
}

fn rgb(c: Vec3) -> Vec3 {
    let (y, co, cg) = (c.x, c.y, c.z);
    Vec3::new(y + co - cg, y + cg, y - co - cg)
}

impl ResolveInput<'_> {
    fn at<T: Copy>(&self, image: &[T], x: i64, y: i64) -> T {
        let (w, h) = (self.size.0 as i64, self.size.1 as i64);
        image[(y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize]
    }

    /// The history at pixel position `p` (centres at +0.5) by a Catmull-Rom spline through
    /// the 4 x 4 texels around it, renormalised over those on screen, never negative.
    fn history_at(&self, p: Vec2) -> Vec4 {
        let (w, h) = (self.size.0 as i64, self.size.1 as i64);
        let spline = |t: f32| {
            // The cubic through four points at -1, 0, 1, 2 with tangents from their neighbours.
            [
                ((-t + 2.0) * t - 1.0) * t / 2.0,
                ((3.0 * t - 5.0) * t * t + 2.0) / 2.0,
                ((-3.0 * t + 4.0) * t + 1.0) * t / 2.0,
                (t - 1.0) * t * t / 2.0,
            ]
        };
        let f = p - Vec2::splat(0.5);
        let (x0, y0) = (f.x.floor() as i64 - 1, f.y.floor() as i64 - 1);
        let (wx, wy) = (spline(f.x - f.x.floor()), spline(f.y - f.y.floor()));
        let mut acc = Vec4::ZERO;
        let mut total = 0.0;
        for (j, wyj) in wy.iter().enumerate() {
            for (i, wxi) in wx.iter().enumerate() {
                let (x, y) = (x0 + i as i64, y0 + j as i64);
                if (0..w).contains(&x) && (0..h).contains(&y) {
                    acc += wxi * wyj * self.history[(y * w + x) as usize];
                    total += wxi * wyj;
                }
            }
        }
        if total.abs() < 1e-4 {
            Vec4::ZERO
        } else {
            (acc / total).max(Vec4::ZERO)
        }
    }

    /// The current frame's value at the centre of pixel (x, y): its own sample, or with
    /// [`Self::reconstruct_px`] the Gaussian-weighted mean of its 3x3 samples by their
    /// scene positions' distance from the centre.
    fn current_at_centre(&self, x: i64, y: i64) -> Vec3 {
        if self.reconstruct_px <= 0.0 {
            return self.at(self.current, x, y);
        }
        let mut sum = Vec3::ZERO;
        let mut weight = 0.0;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let offset = Vec2::new(dx as f32, dy as f32) - self.jitter;
                let w = (-offset.length_squared()
                    / (2.0 * self.reconstruct_px * self.reconstruct_px))
                    .exp();
                sum += w * self.at(self.current, x + dx, y + dy);
                weight += w;
            }
        }
        sum / weight
    }

    /// The next history at pixel (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> Vec4 {
        self.pixel_and_spread(x, y).0
    }

    /// The next history at pixel (x, y), and the pixel's spread for the next frame.
    pub fn pixel_and_spread(&self, x: u32, y: u32) -> (Vec4, Vec3) {
        let (xi, yi) = (x as i64, y as i64);
        let current = self.current_at_centre(xi, yi);
        let samples: Vec<Vec3> = (-1..=1)
            .flat_map(|dy| (-1..=1).map(move |dx| (dx, dy)))
            .map(|(dx, dy)| ycocg(self.at(self.current, xi + dx, yi + dy)))
            .collect();
        let depth = self.at(self.depth, xi, yi);
        let mean = samples.iter().copied().sum::<Vec3>() / 9.0;
        let variance = samples.iter().map(|s| *s * *s).sum::<Vec3>() / 9.0 - mean * mean;
        let sigma = variance.max(Vec3::ZERO).powf(0.5);
        let fresh = (current.extend(1.0), Vec3::ZERO);
        if self.reset {
            return fresh;
        }
        // The pixel's motion vector where what wrote it is still the pixel's surface (the
        // frame's depth is its own).
        let written = (!self.motion.is_empty())
            .then(|| self.at(self.motion, xi, yi))
            .filter(|m| m.w > 0.5 && (m.z - depth).abs() <= MOTION_DEPTH_TOLERANCE * depth);
        // A falling leaf's mark: its history does not hold it.
        if written.is_some_and(|m| m.w > 1.5) {
            return fresh;
        }
        let (w, h) = (self.size.0 as f32, self.size.1 as f32);
        let centre_px = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        // Where a point at this pixel and depth was in the last frame (None: behind the
        // last camera).
        let back = |depth: f32| {
            let ndc = Vec2::new(centre_px.x / w * 2.0 - 1.0, 1.0 - centre_px.y / h * 2.0);
            let then = self.reproject * Vec4::new(ndc.x, ndc.y, depth, 1.0);
            (then.w > 0.0).then(|| {
                let then_ndc = Vec2::new(then.x, then.y) / then.w;
                Vec2::new((then_ndc.x + 1.0) * 0.5 * w, (1.0 - then_ndc.y) * 0.5 * h)
            })
        };
        // A blade's own motion where the blade is still the pixel's surface, else the pixel's
        // depth reprojected; and what the blade moved beyond that reprojection (its sway).
        let (then_px, sway) = match written {
            Some(m) => {
                let own = centre_px - Vec2::new(m.x, m.y);
                (own, back(depth).map_or(0.0, |still| own.distance(still)))
            }
            None => match back(depth) {
                Some(p) => (p, 0.0),
                None => return fresh,
            },
        };
        if then_px.x < 0.0 || then_px.y < 0.0 || then_px.x >= w || then_px.y >= h {
            return fresh;
        }
        let old = self.history_at(then_px);
        if old.w < 1.0 {
            return fresh;
        }
        // The pixel's own spread over time, from the texel the surface was in.
        let own = if self.spread.is_empty() {
            Vec3::ZERO
        } else {
            self.at(self.spread, then_px.x as i64, then_px.y as i64)
                .truncate()
                .max(Vec3::ZERO)
        };
        let now = ycocg(current);
        let moved = then_px.distance(centre_px);
        // What it moved beyond the camera's turn (a point at infinity, reverse-Z depth 0,
        // moves by the turn alone).
        let parallax = back(0.0).map_or(moved, |turned| then_px.distance(turned));
        // The box: the neighbourhood's spread around its mean, reaching the current sample's
        // own spread where that is asked for, less for a surface that moved (the pixel's
        // past samples then saw other blades).
        let mut lo = mean - self.clip_sigma * sigma;
        let mut hi = mean + self.clip_sigma * sigma;
        if self.pixel_spread > 0.0 {
            let reach =
                self.pixel_spread * own.powf(0.5) * (1.0 - moved / SPREAD_MOTION_PX).max(0.0);
            lo = lo.min(now - reach);
            hi = hi.max(now + reach);
        }
        // Pull the history toward the box's centre along the line to it, just far enough.
        let centre = (lo + hi) * 0.5;
        let half = ((hi - lo) * 0.5).max(Vec3::splat(1e-5));
        let offset = ycocg(old.truncate()) - centre;
        let outside = (offset.abs() / half).max_element();
        let (kept, shortened) = if outside > 1.0 {
            (centre + offset / outside, outside)
        } else {
            (ycocg(old.truncate()), 1.0)
        };
        // A surface that moved keeps a shorter history (each frame's resampling blurs it).
        let most = (self.max_samples
            / (1.0
                + self.motion_falloff * moved
                + self.parallax_falloff * parallax
                + self.sway_falloff * sway))
            .max(self.min_samples);
        let n = (old.w + 1.0).min(most);
        let weight = 1.0 / n;
        let kept_rgb = rgb(kept);
        // The spread shrinks as the history was pulled in, then takes in the current sample
        // (the exponentially weighted variance of the samples).
        let error = now - kept;
        let spread = (1.0 - weight) * (own / (shortened * shortened) + weight * error * error);
        ((kept_rgb + (current - kept_rgb) * weight).extend(n), spread)
    }

    /// The next history, every pixel.
    pub fn resolve(&self) -> Vec<Vec4> {
        self.resolve_with_spread().0
    }

    /// The next history and the next spreads (xyz; w 0), every pixel.
    pub fn resolve_with_spread(&self) -> (Vec<Vec4>, Vec<Vec4>) {
        let (w, h) = self.size;
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let (history, spread) = self.pixel_and_spread(x, y);
                (history, spread.extend(0.0))
            })
            .unzip()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(size: (u32, u32), c: Vec3) -> Vec<Vec3> {
        vec![c; (size.0 * size.1) as usize]
    }

    #[test]
    fn a_still_scene_averages_its_jittered_samples() {
        // A pixel that sees white in one sample out of four, beside a pixel that is white
        // throughout (so that the neighbourhood spans the pixel's range), converges to a
        // quarter white, the box filter's answer, with no reprojection error.
        let size = (5, 5);
        let depth = vec![0.5; 25];
        let mut history = vec![Vec4::ZERO; 25];
        for frame in 0..40 {
            let mut current = flat(size, Vec3::ZERO);
            current[13] = Vec3::ONE;
            if frame % 4 == 0 {
                current[12] = Vec3::ONE;
            }
            let input = ResolveInput {
                motion: &[],
                spread: &[],
                pixel_spread: 0.0,
                parallax_falloff: 0.0,
                min_samples: 2.0,
                jitter: Vec2::ZERO,
                reconstruct_px: 0.0,
                sway_falloff: 0.0,
                size,
                current: &current,
                depth: &depth,
                history: &history,
                reproject: Mat4::IDENTITY,
                max_samples: 1000.0,
                clip_sigma: 1.0,
                motion_falloff: 0.25,
                reset: frame == 0,
            };
            history = input.resolve();
        }
        assert!((history[12].x - 0.25).abs() < 0.02, "{}", history[12]);
        assert_eq!(history[12].w, 40.0);
    }

    #[test]
    fn a_leaf_marked_in_the_motion_vectors_shows_its_current_sample_alone() {
        // A still green field with a long history; a small leaf (a bright pixel) appears in
        // the middle. Reprojected through its depth, the pixel's history is the field, which the
        // neighbourhood (the leaf and eight green pixels) keeps: the leaf would show at 1 / n.
        let size = (5, 5);
        let green = Vec3::new(0.1, 0.3, 0.05);
        let leaf = Vec3::new(0.9, 0.6, 0.2);
        let mut current = flat(size, green);
        current[12] = leaf;
        let depth = vec![0.5; 25];
        let history = vec![green.extend(24.0); 25];
        let marked = |w: f32, z: f32| {
            let mut m = vec![Vec4::ZERO; 25];
            m[12] = Vec4::new(0.0, 0.0, z, w);
            m
        };
        let resolve = |motion: &[Vec4]| {
            ResolveInput {
                motion,
                spread: &[],
                pixel_spread: 0.0,
                parallax_falloff: 2.0,
                min_samples: 1.0,
                jitter: Vec2::ZERO,
                reconstruct_px: 0.0,
                sway_falloff: 0.0,
                size,
                current: &current,
                depth: &depth,
                history: &history,
                reproject: Mat4::IDENTITY,
                max_samples: 24.0,
                clip_sigma: 2.5,
                motion_falloff: 1.0,
                reset: false,
            }
            .pixel(2, 2)
        };
        let unmarked = resolve(&[]);
        assert!((unmarked.x - leaf.x).abs() > 0.5, "{unmarked}");
        assert_eq!(resolve(&marked(2.0, 0.5)), leaf.extend(1.0));
        // A mark under something drawn over the leaf since (the frame's depth is not the
        // mark's) is not the pixel's: its history is blended as before.
        assert_eq!(resolve(&marked(2.0, 0.25)), unmarked);
    }

    /// A pixel that sees a white blade in one sample out of four while its whole
    /// neighbourhood is black in the other three: the history after `frames` frames.
    fn sub_pixel_blade(pixel_spread: f32, frames: u32) -> Vec4 {
        let size = (5, 5);
        let depth = vec![0.5; 25];
        let mut history = vec![Vec4::ZERO; 25];
        let mut spread = vec![Vec4::ZERO; 25];
        for frame in 0..frames {
            let mut current = flat(size, Vec3::ZERO);
            if frame % 4 == 0 {
                current[12] = Vec3::ONE;
            }
            let input = ResolveInput {
                motion: &[],
                spread: &spread,
                pixel_spread,
                parallax_falloff: 0.0,
                min_samples: 2.0,
                jitter: Vec2::ZERO,
                reconstruct_px: 0.0,
                sway_falloff: 0.0,
                size,
                current: &current,
                depth: &depth,
                history: &history,
                reproject: Mat4::IDENTITY,
                max_samples: 1000.0,
                clip_sigma: 2.5,
                motion_falloff: 0.25,
                reset: frame == 0,
            };
            (history, spread) = input.resolve_with_spread();
        }
        history[12]
    }

    #[test]
    fn the_pixels_own_spread_keeps_a_blade_the_neighbourhood_missed() {
        // Clipped to the neighbourhood alone, the history is pulled to black in every frame
        // that misses the blade: it holds far less than the quarter the pixel covers.
        let clipped = sub_pixel_blade(0.0, 81);
        assert!(clipped.x < 0.15, "{clipped}");
        // With the pixel's own spread, the frames that miss the blade are explained by the
        // pixel's past: it converges to the box filter's quarter.
        let kept = sub_pixel_blade(2.5, 81);
        assert!((kept.x - 0.25).abs() < 0.04, "{kept}");
    }

    #[test]
    fn a_ghost_the_pixel_never_showed_is_clipped_with_its_own_spread_too() {
        // The history says white, with no spread of its own, where the pixel and its
        // neighbourhood are black: the pixel's past cannot explain it, and it goes.
        let size = (3, 3);
        let current = flat(size, Vec3::new(0.1, 0.1, 0.1));
        let history = vec![Vec4::new(1.0, 1.0, 1.0, 8.0); 9];
        let spread = vec![Vec4::new(1e-4, 1e-5, 1e-5, 0.0); 9];
        let input = ResolveInput {
            motion: &[],
            spread: &spread,
            pixel_spread: 2.5,
            parallax_falloff: 0.0,
            min_samples: 2.0,
            jitter: Vec2::ZERO,
            reconstruct_px: 0.0,
            sway_falloff: 0.0,
            size,
            current: &current,
            depth: &[0.5; 9],
            history: &history,
            reproject: Mat4::IDENTITY,
            max_samples: 12.0,
            clip_sigma: 1.0,
            motion_falloff: 0.25,
            reset: false,
        };
        let (out, own) = input.pixel_and_spread(1, 1);
        // At most its own small spread (2.5 x 0.01 in luma) above the black it now shows.
        assert!(
            (out.truncate() - Vec3::splat(0.1)).max_element() < 0.03,
            "{out}"
        );
        assert!(own.max_element() < 1e-3, "{own}");
    }

    #[test]
    fn a_ghost_outside_the_neighbourhood_is_clipped_away() {
        // The history says white where the whole neighbourhood is now black: it is pulled to
        // the neighbourhood and does not linger.
        let size = (3, 3);
        let current = flat(size, Vec3::new(0.1, 0.1, 0.1));
        let history = vec![Vec4::new(1.0, 1.0, 1.0, 8.0); 9];
        let input = ResolveInput {
            motion: &[],
            spread: &[],
            pixel_spread: 0.0,
            parallax_falloff: 0.0,
            min_samples: 2.0,
            jitter: Vec2::ZERO,
            reconstruct_px: 0.0,
            sway_falloff: 0.0,
            size,
            current: &current,
            depth: &[0.5; 9],
            history: &history,
            reproject: Mat4::IDENTITY,
            max_samples: 12.0,
            clip_sigma: 1.0,
            motion_falloff: 0.25,
            reset: false,
        };
        let out = input.pixel(1, 1);
        assert!((out.truncate() - Vec3::splat(0.1)).length() < 1e-3, "{out}");
        assert_eq!(out.w, 9.0);
    }

    /// The samples the history holds after one frame at pixel (32, 24) of a flat 64 x 48
    /// scene 25 m away whose history held 20, the last camera `last`, the current `now`.
    fn samples_after(
        last: crate::Camera,
        now: crate::Camera,
        parallax_falloff: f32,
        min_samples: f32,
    ) -> f32 {
        let size = (64, 48);
        let aspect = 64.0 / 48.0;
        let current = flat(size, Vec3::splat(0.3));
        // Reverse-Z with an infinite far plane: depth = near / distance.
        let depth = vec![now.near_m / 25.0; 64 * 48];
        let history = vec![Vec4::new(0.3, 0.3, 0.3, 20.0); 64 * 48];
        let input = ResolveInput {
            motion: &[],
            spread: &[],
            pixel_spread: 0.0,
            parallax_falloff,
            min_samples,
            jitter: Vec2::ZERO,
            reconstruct_px: 0.0,
            sway_falloff: 0.0,
            size,
            current: &current,
            depth: &depth,
            history: &history,
            reproject: crate::aa::taa::reprojection(
                last.view_proj_relative(aspect),
                last.position,
                now.view_proj_relative(aspect),
                now.position,
            ),
            max_samples: 24.0,
            clip_sigma: 2.5,
            motion_falloff: 1.0,
            reset: false,
        };
        input.pixel(32, 24).w
    }

    #[test]
    fn parallax_shortens_the_history_and_a_turn_does_not() {
        let camera = crate::Camera::new(glam::DVec3::new(0.0, 0.0, 10.0), 0.0, -5.0);
        let mut turned = camera;
        turned.yaw_deg += 0.2;
        let mut moved = camera;
        moved.position += glam::DVec3::new(0.1, 0.1, 0.0);
        // A turn moves the pixel's surface as far as a point at infinity: no parallax.
        let turn = samples_after(camera, turned, 0.0, 2.0);
        assert!(turn < 21.0, "the turn moved nothing: {turn}");
        assert_eq!(samples_after(camera, turned, 4.0, 2.0), turn);
        // A move shifts the surface against the infinity behind it: a shorter history.
        let plain = samples_after(camera, moved, 0.0, 2.0);
        let short = samples_after(camera, moved, 4.0, 2.0);
        assert!(plain > 1.0 && short > 1.0, "{plain} {short}");
        assert!(short < plain - 1.0, "{short} against {plain}");
    }

    #[test]
    fn a_blades_own_sway_shortens_its_history_and_the_cameras_move_does_not() {
        // A blade's pixel whose motion vector (if any) says it moved `m` pixels, where the
        // camera's move (`reproject`) says it moved as its depth does.
        let size = (9, 9);
        let current = flat(size, Vec3::splat(0.3));
        let depth = vec![0.2; 81];
        let history = vec![Vec4::new(0.3, 0.3, 0.3, 20.0); 81];
        let samples = |m: Option<f32>, reproject: Mat4, sway_falloff: f32| {
            let mut motion = vec![Vec4::ZERO; 81];
            if let Some(m) = m {
                motion[40] = Vec4::new(m, 0.0, 0.2, 1.0);
            }
            ResolveInput {
                motion: &motion,
                spread: &[],
                pixel_spread: 0.0,
                parallax_falloff: 0.0,
                min_samples: 1.0,
                jitter: Vec2::ZERO,
                reconstruct_px: 0.0,
                sway_falloff,
                size,
                current: &current,
                depth: &depth,
                history: &history,
                reproject,
                max_samples: 24.0,
                clip_sigma: 2.5,
                motion_falloff: 0.0,
                reset: false,
            }
            .pixel(4, 4)
            .w
        };
        let still = Mat4::IDENTITY;
        // No sway, or no falloff for it: the whole history (20 samples, one more now).
        assert_eq!(samples(Some(0.0), still, 4.0), 21.0);
        assert_eq!(samples(Some(0.5), still, 0.0), 21.0);
        // Half a pixel of sway at a falloff of 4: at most 24 / 3 samples.
        assert_eq!(samples(Some(0.5), still, 4.0), 8.0);
        // A pixel that moved with the camera (no motion vector: its depth reprojected) has no
        // sway, however far it moved.
        let moved = Mat4::from_translation(glam::Vec3::new(0.1, 0.0, 0.0));
        assert_eq!(samples(None, moved, 4.0), 21.0);
        // Nor has a blade whose motion vector is the camera's move (0.1 of the frame's half
        // width: 0.45 pixels); the same vector with a still camera is all sway.
        assert!((samples(Some(-0.45), moved, 4.0) - 21.0).abs() < 1e-3);
        assert!(samples(Some(-0.45), still, 4.0) < 9.0);
    }

    #[test]
    fn a_surface_that_moved_far_keeps_the_fewest_samples_asked_for() {
        let camera = crate::Camera::new(glam::DVec3::new(0.0, 0.0, 10.0), 0.0, -5.0);
        let mut far = camera;
        far.position += glam::DVec3::new(0.0, 8.0, 0.0);
        // Moved so far that the longest history it may keep is under one sample.
        assert_eq!(samples_after(camera, far, 2.0, 2.0), 2.0);
        assert_eq!(samples_after(camera, far, 2.0, 1.0), 1.0);
        // A small move keeps more than either floor, whichever is asked for.
        let mut near = camera;
        near.position += glam::DVec3::new(0.0, 0.1, 0.0);
        let (two, one) = (
            samples_after(camera, near, 2.0, 2.0),
            samples_after(camera, near, 2.0, 1.0),
        );
        assert!(two > 2.0 && two == one, "{two} {one}");
    }

    #[test]
    fn the_current_frame_is_reconstructed_at_the_pixels_centres_not_the_jitters() {
        // A ramp across the frame drawn with its samples shifted by the jitter: each pixel's
        // own sample shows the ramp 0.4 pixels left of its centre.
        let size = (8, 3);
        let jitter = Vec2::new(0.4, 0.0);
        let ramp = |x: f32| 0.1 + 0.05 * x;
        let current: Vec<Vec3> = (0..3)
            .flat_map(|_| (0..8).map(|x| Vec3::splat(ramp(x as f32 + 0.5 - jitter.x))))
            .collect();
        let input = |reconstruct_px| ResolveInput {
            motion: &[],
            spread: &[],
            pixel_spread: 0.0,
            parallax_falloff: 0.0,
            min_samples: 2.0,
            jitter,
            reconstruct_px,
            sway_falloff: 0.0,
            size,
            current: &current,
            depth: &[0.5; 24],
            history: &[Vec4::ZERO; 24],
            reproject: Mat4::IDENTITY,
            max_samples: 24.0,
            clip_sigma: 2.5,
            motion_falloff: 1.0,
            reset: true,
        };
        let truth = ramp(4.5);
        let own = (input(0.0).pixel(4, 1).x - truth).abs();
        let rebuilt = (input(0.4).pixel(4, 1).x - truth).abs();
        assert!((own - 0.02).abs() < 1e-5, "{own}");
        assert!(rebuilt < own / 4.0, "{rebuilt} against {own}");
        // With no jitter the reconstruction is symmetric: the ramp's centre exactly.
        let still = ResolveInput {
            jitter: Vec2::ZERO,
            ..input(0.4)
        };
        let centred: Vec<Vec3> = (0..3)
            .flat_map(|_| (0..8).map(|x| Vec3::splat(ramp(x as f32 + 0.5))))
            .collect();
        let still = ResolveInput {
            current: &centred,
            ..still
        };
        assert!((still.pixel(4, 1).x - truth).abs() < 1e-6);
    }

    #[test]
    fn history_that_comes_from_off_screen_starts_again() {
        let size = (4, 2);
        let current = flat(size, Vec3::new(0.2, 0.4, 0.6));
        let history = vec![Vec4::new(0.9, 0.9, 0.9, 5.0); 8];
        // Everything moved two screens to the right: no history is on screen.
        let input = ResolveInput {
            motion: &[],
            spread: &[],
            pixel_spread: 0.0,
            parallax_falloff: 0.0,
            min_samples: 2.0,
            jitter: Vec2::ZERO,
            reconstruct_px: 0.0,
            sway_falloff: 0.0,
            size,
            current: &current,
            depth: &[0.5; 8],
            history: &history,
            reproject: Mat4::from_translation(Vec3::new(4.0, 0.0, 0.0)),
            max_samples: 12.0,
            clip_sigma: 10.0,
            motion_falloff: 0.25,
            reset: false,
        };
        assert!(
            input
                .resolve()
                .iter()
                .all(|p| *p == Vec4::new(0.2, 0.4, 0.6, 1.0))
        );
    }
}
