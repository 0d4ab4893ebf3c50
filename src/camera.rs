//! The camera and the camera paths of a world's manifest: a leaf that every part of the crate
//! may use.

use glam::{DVec2, DVec3, Mat4, Vec2, Vec3};

use crate::world::{CameraPath, Manifest};

/// A camera in world space: position in metres (f64), looking along yaw and pitch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position, metres (x east, y north, z up).
    pub position: DVec3,
    /// Heading in degrees: 0 looks east, 90 north.
    pub yaw_deg: f64,
    /// Degrees above the horizon; negative looks down.
    pub pitch_deg: f64,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
    /// Near plane, metres (the far plane is at infinity: reverse-Z).
    pub near_m: f32,
    /// The caller's own view and projection, used instead of yaw, pitch, field of view and
    /// near plane when set.
    pub custom: Option<CustomView>,
}

/// A view and projection of the caller's own for a camera at [`Camera::position`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CustomView {
    /// World-to-view rotation with the eye at the origin (no translation: positions reach the
    /// GPU camera-relative), right-handed, looking along -z of view space, x east, y north,
    /// z up in world space.
    pub view: Mat4,
    /// Projection into wgpu's clip space, reverse-Z (depth 1 at the near plane, 0 far; an
    /// infinite far plane is best), e.g.
    /// `glam::camera::rh::proj::directx::perspective_infinite_reverse`.
    pub proj: Mat4,
}

impl Camera {
    /// A camera at `position` looking along `yaw_deg`/`pitch_deg` with a 60 degree field of view.
    pub fn new(position: DVec3, yaw_deg: f64, pitch_deg: f64) -> Self {
        Self {
            position,
            yaw_deg,
            pitch_deg,
            fov_y_deg: 60.0,
            near_m: 0.5,
            custom: None,
        }
    }

    /// A camera at `position` with the caller's own `view` rotation and `proj`ection (see
    /// [`CustomView`]).
    pub fn with_view(position: DVec3, view: Mat4, proj: Mat4) -> Self {
        let mut c = Self::new(position, 0.0, 0.0);
        c.custom = Some(CustomView { view, proj });
        let f = c.forward();
        c.yaw_deg = f.y.atan2(f.x).to_degrees();
        c.pitch_deg = f.z.clamp(-1.0, 1.0).asin().to_degrees();
        c
    }

    /// Why this camera cannot be drawn from, or `Ok`: its position, yaw and pitch must be
    /// finite; its field of view between 0 and 180 degrees (exclusive) and its near plane above
    /// zero; or, with the caller's own view and projection, both matrices finite and
    /// invertible.
    pub fn check(&self) -> Result<(), String> {
        if !self.position.is_finite() {
            return Err(format!("camera position {} is not finite", self.position));
        }
        if !(self.yaw_deg.is_finite() && self.pitch_deg.is_finite()) {
            return Err(format!(
                "camera yaw {} and pitch {} degrees must be finite",
                self.yaw_deg, self.pitch_deg
            ));
        }
        if let Some(c) = &self.custom {
            for (what, m) in [("view", c.view), ("projection", c.proj)] {
                let det = m.determinant();
                if !m.is_finite() || !det.is_finite() || det == 0.0 {
                    return Err(format!(
                        "the caller's {what} matrix must be finite and invertible: {m}"
                    ));
                }
            }
            return Ok(());
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return Err(format!(
                "camera field of view {} degrees: must be between 0 and 180 (exclusive)",
                self.fov_y_deg
            ));
        }
        if !(self.near_m > 0.0 && self.near_m.is_finite()) {
            return Err(format!(
                "camera near plane {} m: must be finite and above zero",
                self.near_m
            ));
        }
        Ok(())
    }

    /// Unit view direction.
    pub fn forward(&self) -> DVec3 {
        if let Some(c) = &self.custom {
            let f = c.view.inverse().transform_vector3(-Vec3::Z);
            return f.normalize_or(Vec3::X).as_dvec3();
        }
        let (yaw, pitch) = (self.yaw_deg.to_radians(), self.pitch_deg.to_radians());
        DVec3::new(
            yaw.cos() * pitch.cos(),
            yaw.sin() * pitch.cos(),
            pitch.sin(),
        )
    }

    /// View-projection with the eye at the origin: positions fed to it must be camera-relative.
    /// Reverse-Z with an infinite far plane (depth 1 at the near plane, 0 at infinity).
    pub fn view_proj_relative(&self, aspect: f32) -> Mat4 {
        let (view, proj) = self.view_and_projection(aspect);
        proj * view
    }

    /// The view (rotation only: the eye at the origin) and the projection, apart.
    pub fn view_and_projection(&self, aspect: f32) -> (Mat4, Mat4) {
        if let Some(c) = &self.custom {
            return (c.view, c.proj);
        }
        use glam::camera::rh::{proj::directx, view::look_to_mat4};
        let view = look_to_mat4(Vec3::ZERO, self.forward().as_vec3(), Vec3::Z);
        // wgpu's clip space is Direct3D's: z in [0, 1], y up.
        let proj =
            directx::perspective_infinite_reverse(self.fov_y_deg.to_radians(), aspect, self.near_m);
        (view, proj)
    }

    /// This camera with its image shifted by `offset_px` pixels (x right, y down) on a
    /// `width` x `height` target: the projection is translated in clip space, so that every
    /// point moves by the same sub-pixel amount on screen. A zero offset returns the camera
    /// unchanged.
    pub fn jittered(&self, offset_px: Vec2, width: u32, height: u32, aspect: f32) -> Camera {
        if offset_px == Vec2::ZERO {
            return *self;
        }
        let (view, proj) = self.view_and_projection(aspect);
        // Clip-space x' = x + tx w moves normalised x by tx: 2 / width per pixel (y is up in
        // normalised coordinates and down in pixels).
        let shift = Mat4::from_translation(Vec3::new(
            2.0 * offset_px.x / width.max(1) as f32,
            -2.0 * offset_px.y / height.max(1) as f32,
            0.0,
        ));
        let mut c = *self;
        c.custom = Some(CustomView {
            view,
            proj: shift * proj,
        });
        c
    }
}

/// The camera on `path` at time `t_s` (clamped to the path's keys, from
/// [`CameraPath::start_s`] to [`CameraPath::end_s`]): Catmull-Rom through the key positions,
/// yaw and pitch interpolated the short way round.
pub fn sample_path(path: &CameraPath, t_s: f64) -> Camera {
    let keys = &path.keys;
    let last = keys.len() - 1;
    let t = t_s.clamp(path.start_s(), path.end_s());
    let i = keys
        .windows(2)
        .position(|w| t <= w[1].t_s)
        .unwrap_or(last.saturating_sub(1));
    let (k1, k2) = (&keys[i], &keys[(i + 1).min(last)]);
    let span = k2.t_s - k1.t_s;
    let u = if span > 0.0 { (t - k1.t_s) / span } else { 0.0 };
    let p = |k: usize| DVec3::from_array(keys[k].position_m);
    let (p0, p1, p2, p3) = (
        p(i.saturating_sub(1)),
        p(i),
        p((i + 1).min(last)),
        p((i + 2).min(last)),
    );
    let position = catmull_rom(p0, p1, p2, p3, u);
    let mut dyaw = (k2.yaw_deg - k1.yaw_deg) % 360.0;
    if dyaw > 180.0 {
        dyaw -= 360.0;
    } else if dyaw < -180.0 {
        dyaw += 360.0;
    }
    let yaw_deg = k1.yaw_deg + dyaw * u;
    let pitch_deg = k1.pitch_deg + (k2.pitch_deg - k1.pitch_deg) * u;
    Camera::new(position, yaw_deg, pitch_deg)
}

/// Where the trail in the grass is left at `t_s` along `path`: on the path's `walker` path of
/// `manifest` (validation guarantees it exists), else under the camera.
pub fn walker_at(manifest: &Manifest, path: &CameraPath, t_s: f64) -> DVec2 {
    let walker = path
        .walker
        .as_deref()
        .and_then(|name| manifest.path(name))
        .unwrap_or(path);
    sample_path(walker, t_s).position.truncate()
}

fn catmull_rom(p0: DVec3, p1: DVec3, p2: DVec3, p3: DVec3, u: f64) -> DVec3 {
    let u2 = u * u;
    let u3 = u2 * u;
    0.5 * ((2.0 * p1)
        + (p2 - p0) * u
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * u2
        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * u3)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::CameraKey;

    fn key(t_s: f64, x: f64, yaw_deg: f64) -> CameraKey {
        CameraKey {
            t_s,
            position_m: [x, 0.0, 100.0],
            yaw_deg,
            pitch_deg: -10.0,
        }
    }

    #[test]
    fn path_passes_through_its_keys_and_turns_the_short_way() {
        let path = CameraPath {
            name: "test".into(),
            duration_s: 20.0,
            walker: None,
            wind: Vec::new(),
            keys: vec![
                key(0.0, 0.0, 350.0),
                key(10.0, 100.0, 10.0),
                key(20.0, 300.0, 10.0),
            ],
        };
        for k in &path.keys {
            let c = sample_path(&path, k.t_s);
            assert!((c.position - DVec3::from_array(k.position_m)).length() < 1e-9);
        }
        let mid = sample_path(&path, 5.0);
        // 350 -> 10 degrees goes through 0, not through 180.
        assert!(
            (mid.yaw_deg.rem_euclid(360.0) - 0.0).abs() < 1e-9
                || (mid.yaw_deg - 360.0).abs() < 1e-9
        );
        assert!(mid.position.x > 0.0 && mid.position.x < 100.0);
    }

    #[test]
    fn forward_follows_yaw_and_pitch() {
        let c = Camera::new(DVec3::ZERO, 90.0, 0.0);
        assert!((c.forward() - DVec3::Y).length() < 1e-12);
        let down = Camera::new(DVec3::ZERO, 0.0, -90.0);
        assert!((down.forward() - DVec3::NEG_Z).length() < 1e-12);
    }

    #[test]
    fn jitter_moves_every_point_by_the_offset_in_pixels() {
        let c = Camera::new(DVec3::ZERO, 30.0, -10.0);
        let (w, h) = (640u32, 360u32);
        let aspect = w as f32 / h as f32;
        let offset = Vec2::new(0.25, -0.375);
        let j = c.jittered(offset, w, h, aspect);
        assert!((j.forward() - c.forward()).length() < 1e-6);
        let to_px = |m: Mat4, p: Vec3| {
            let clip = m * p.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            (
                Vec2::new(
                    (ndc.x + 1.0) * 0.5 * w as f32,
                    (1.0 - ndc.y) * 0.5 * h as f32,
                ),
                ndc.z,
            )
        };
        for p in [Vec3::new(40.0, 30.0, -5.0), Vec3::new(400.0, 180.0, 20.0)] {
            let (a, za) = to_px(c.view_proj_relative(aspect), p);
            let (b, zb) = to_px(j.view_proj_relative(aspect), p);
            assert!((b - a - offset).length() < 1e-3, "{a} -> {b}");
            assert!((za - zb).abs() < 1e-6);
        }
        assert_eq!(c.jittered(Vec2::ZERO, w, h, aspect), c);
    }
}
