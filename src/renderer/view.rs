//! The frame's view, worked out once in [`super::Renderer::prepare`] and handed to every
//! stage: the camera-relative view-projection (jittered when anti-aliasing asks for it) and
//! its frustum, the unjittered one the temporal resolve reprojects with, and the eye.

use glam::{DVec3, Mat4, Vec2};

use crate::camera::Camera;
use crate::lod::Frustum;

/// The view of one frame.
#[derive(Clone, Copy, Debug)]
pub struct FrameView {
    /// The camera as drawn (its projection jittered by [`FrameView::jitter_px`]).
    pub camera: Camera,
    /// The eye, world metres.
    pub eye: DVec3,
    /// Unit view direction.
    pub forward: DVec3,
    /// Camera-relative view-projection the passes draw with (jittered).
    pub view_proj: Mat4,
    /// The same without the jitter.
    pub unjittered: Mat4,
    /// The projection alone, without the jitter.
    pub projection: Mat4,
    /// The frustum of [`FrameView::view_proj`].
    pub frustum: Frustum,
    /// The sub-pixel offset of the image, pixels.
    pub jitter_px: Vec2,
}

impl FrameView {
    /// Refuses a view whose projection, as drawn, is not finite and invertible in 32 bits
    /// though each input was finite on its own (a field of view of 1e-40 degrees, a near plane
    /// of 1e-45 m, a jitter of 3e38 pixels, a custom view and projection whose product
    /// overflows): such a frame drew as flat sky, and the temporal history kept it.
    pub fn check(&self) -> Result<(), String> {
        for (what, m) in [("", self.unjittered), (" with its jitter", self.view_proj)] {
            if !(m.is_finite() && m.determinant().is_normal() && m.inverse().is_finite()) {
                return Err(format!(
                    "the camera's view-projection{what} is not finite and invertible in 32 bits \
                     (a field of view, near plane, jitter or custom matrix too extreme): {m}"
                ));
            }
        }
        Ok(())
    }

    /// The view of `camera` on a `width` x `height` target, shifted by `jitter_px`.
    pub fn new(camera: &Camera, jitter_px: Vec2, width: u32, height: u32) -> Self {
        let aspect = width as f32 / height as f32;
        let jittered = camera.jittered(jitter_px, width, height, aspect);
        let view_proj = jittered.view_proj_relative(aspect);
        Self {
            camera: jittered,
            eye: camera.position,
            forward: camera.forward(),
            view_proj,
            unjittered: camera.view_proj_relative(aspect),
            projection: camera.view_and_projection(aspect).1,
            frustum: Frustum::from_view_proj(view_proj),
            jitter_px,
        }
    }
}
