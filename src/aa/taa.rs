//! The temporal anti-aliasing stage (`shaders/aa_taa.wgsl`): the frame is drawn into a
//! texture of the stage's with a jittered projection, then resolved against the history into
//! the caller's colour target. See the shader's header for the method; the CPU mirror is
//! [`crate::aa::taa_cpu`].

use glam::{DMat4, DVec3, Mat4, Vec2};

use crate::gpu::layout::{
    UNFILTERABLE_FLOAT, bind_group_layout, storage_buffer_read_only, texture_2d, texture_depth_2d,
    texture_storage_2d, view as view_of, with_indices,
};
use crate::gpu::pass::render_pass;
use crate::gpu::pipeline::{DepthBound, buffer, compute_pipeline_with_constants, render_pipeline};

/// Format of the history: linear colour in rgb, the samples it holds in alpha.
pub const HISTORY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// Format of the pixels' own spread over time, kept beside the history: the variance of their
/// samples per YCoCg channel in rgb (alpha unused).
pub const SPREAD_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The format of the blades' motion vectors (`MotionOut` in `shaders/grass_draw.wgsl`): the
/// pixels a blade's point moved since the last frame (x, y), its depth (z), and 1 where a
/// blade wrote it (w; 0 elsewhere: the resolve reprojects those pixels through their depth).
pub const MOTION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// Settings of the temporal anti-aliasing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaaSettings {
    /// Most samples a pixel's history holds: the current frame's weight is never below one
    /// over this. More converges further in a still scene and lags longer in a moving one.
    pub max_samples: u32,
    /// The history is clipped to the current neighbourhood's mean plus and minus this many
    /// standard deviations (per YCoCg channel).
    pub clip_sigma: f32,
    /// A surface that moved `p` pixels since the last frame keeps at most
    /// `max_samples / (1 + motion_falloff * p)` samples (at least [`Self::min_samples`];
    /// fewer with its parallax, [`Self::parallax_falloff`]): a history resampled frame after
    /// frame blurs, so a moving one is kept shorter.
    pub motion_falloff: f32,
    /// A camera that moves further than this in one frame (metres) starts every history again.
    pub cut_distance_m: f64,
    /// A camera that turns by more than this in one frame (degrees) starts every history again.
    pub cut_angle_deg: f64,
    /// A projection whose focal length (horizontal or vertical: a change of aspect counts) or
    /// near plane changes by more than this factor in one frame (a change of lens, a zoom cut,
    /// a near plane pushed past the scene and back) starts every history again: the history
    /// drawn through the other lens is too blurred or too far off (a frame whose near plane
    /// clipped the ground away left sky in it). 1..=1e6.
    pub cut_zoom: f32,
    /// Whether the grass blades write their own motion vectors (their wind over the frame) for the
    /// resolve, where otherwise a blade's pixel is reprojected through its depth (the camera's move
    /// alone). Off by default: measured on the meadow at 60 frames a second in its breeze, a blade
    /// moves a small part of a pixel a frame and the motion vectors changed the error and the
    /// flicker by less than 0.001 and 0.01 (docs/anti-aliasing.md), while their second target cost
    /// 0.40 ms of grass drawing at 1920x1080 (NVIDIA H200); measured again in every sequence and
    /// along the paths, they took 5% from the still view's error at 1920x1080 and 1-3% from the
    /// wind tour's, nothing from the meadow's and the tour's, for 0.54 ms (9% of the frame;
    /// docs/anti-aliasing.md, "The history against the wind's sway"). A storm, or a low frame rate,
    /// moves blades further.
    pub blade_motion: bool,
    /// The clip's box also reaches the current sample plus and minus this many of the pixel's
    /// own standard deviations over time (its samples' exponentially weighted spread, kept
    /// beside the history): a blade thinner than a pixel that the pixel's past samples caught
    /// and the current neighbourhood missed stays in the history. The reach falls with the
    /// pixels the surface moved, to nothing at half a pixel
    /// ([`crate::aa::taa_cpu::SPREAD_MOTION_PX`]): blades at other depths then slide past
    /// each other, and the pixel's past samples saw other blades. 0: the neighbourhood's box
    /// alone.
    pub pixel_spread: f32,
    /// A surface with `q` pixels of parallax (what it moved beyond the camera's turn: the
    /// camera's move against its depth, or a blade's own motion) keeps at most
    /// `max_samples / (1 + motion_falloff * p + parallax_falloff * q)` samples: blades at
    /// other depths slide past each other within the pixel, and its history mixes blades that
    /// are no longer there, where a turn moves every depth alike.
    pub parallax_falloff: f32,
    /// The fewest samples a moving surface's history keeps, however far it moved: 2 keeps
    /// half of a resampled history in every pixel, 1 lets a surface that moved far enough
    /// (`max_samples / (1 + motion_falloff * p + parallax_falloff * q)` below 2) lean on its
    /// current sample, down to the current sample alone, where a history would only blur it.
    /// At least 1, at most [`Self::max_samples`].
    pub min_samples: f32,
    /// The current frame's value at each pixel's centre is reconstructed from its 3x3
    /// neighbourhood's samples, each weighted by a Gaussian of this standard deviation
    /// (pixels) of its distance from the centre: the samples lie the frame's jitter away from
    /// their pixels' centres, and a short history (a moving surface's) would otherwise show
    /// the image shifted by the last few jitters. 0: each pixel's own sample.
    pub reconstruct_px: f32,
    /// With [`Self::blade_motion`]: a blade whose own motion (its motion vector beyond where the
    /// pixel's depth alone would have taken it: its sway in the wind) moved `s` pixels keeps at
    /// most `max_samples / (1 + motion_falloff * p + parallax_falloff * q + sway_falloff * s)`
    /// samples. A swaying blade changes its bend and its light from frame to frame, and its
    /// resampled history lags it; a still view of grass in the wind erred less against the truth
    /// the shorter the history (docs/anti-aliasing.md, "The history against the wind's sway"),
    /// while ground, stems and far blades keep the long history that averages the jitter. 0 (the
    /// default): the sway counts only as parallax. Measured in `bench aa` at 960x540 and 1920x1080,
    /// 4 and 16 changed every sequence and path by at most 0.0007 FLIP but the wind tour at
    /// 1920x1080 (1.6% less at 16): the blades sway too little a frame for it to shorten their
    /// history much.
    pub sway_falloff: f32,
}

impl Default for TaaSettings {
    fn default() -> Self {
        Self {
            // Measured against the truth (docs/anti-aliasing.md, `bench aa` with 36 frames of
            // run-up): a still view's history of 16 lets the jitter through (flicker 1.26 times the
            // truth's), 20 gives 1.02, 28 0.75 at a higher error (the wind's sway lags); 24
            // between.
            max_samples: 24,
            // Measured against the truth (docs/anti-aliasing.md, `bench aa`): 1.25 drops too much
            // history in the grass's thin blades (a still view flickers 1.6 times the truth's), 4
            // keeps ghosts 3 frames after a teleport; 2.5 between.
            clip_sigma: 2.5,
            // A moving surface's history shortens fast: at 1 (half the samples at a pixel
            // moved) the dolly errs 0.090 against the truth where 0.25 erred 0.110 (less
            // than no anti-aliasing's 0.098).
            motion_falloff: 1.0,
            cut_distance_m: 20.0,
            cut_angle_deg: 30.0,
            cut_zoom: 2.0,
            blade_motion: false,
            // Measured against the truth (docs/anti-aliasing.md, `bench aa`): off, the spread takes
            // 7% off a still view's error at 960x540 but nothing at 1920x1080, and costs the
            // meadow's path 2%.
            pixel_spread: 0.0,
            // Measured against the truth (docs/anti-aliasing.md, `bench aa`): 2 takes 4-5% off the
            // dolly's and the meadow path's error at 960x540 and 1920x1080 and leaves the pan's,
            // where a falloff of 3 for every motion cost the pan 14%.
            parallax_falloff: 2.0,
            // Measured against the truth (docs/anti-aliasing.md, `bench aa`), with the
            // reconstruction: at 1920x1080 a floor of 1 takes the dolly from 0.0785 to 0.0729 and
            // the meadow's path from 0.0828 to 0.0763 (no anti-aliasing: 0.0770 and 0.0797); at
            // 960x540 it costs them 0.0017 and 0.0014.
            min_samples: 1.0,
            // Measured against the truth (docs/anti-aliasing.md, `bench aa`): without it a short
            // history shows the image shifted by the last few jitters, and the temporal method
            // erred more than no anti-aliasing in motion at 1920x1080; 0.45 lowers every sequence's
            // error at both sizes, 0.6 blurs more than it gains (960x540).
            reconstruct_px: 0.45,
            // Measured in `bench aa`: off (docs/anti-aliasing.md, "The history against the
            // wind's sway").
            sway_falloff: 0.0,
        }
    }
}

/// Uniforms of `shaders/aa_taa.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TaaParams {
    /// From the current frame's unjittered normalised coordinates and depth to the last
    /// frame's unjittered clip space.
    pub reproject: [[f32; 4]; 4],
    /// Target width and height, most samples, 1 to start every pixel again.
    pub size: [f32; 4],
    /// The clip's standard deviations, the motion falloff, the pixel's own spread's standard
    /// deviations, the parallax falloff.
    pub clip: [f32; 4],
    /// The fewest samples a moving surface's history keeps, the current frame's jitter
    /// (pixels, x right, y down), the reconstruction's standard deviation (pixels; 0: none).
    pub hold: [f32; 4],
    /// The sway falloff; the rest unused.
    pub sway: [f32; 4],
}

/// The matrix that takes a pixel of the current frame (normalised coordinates of the
/// unjittered projection, and its depth) to where its surface was in the last frame's
/// unjittered clip space: both view-projections are camera-relative, so the camera's move
/// from `last_eye` to `eye` is added in between (in f64, so that a far camera keeps its
/// precision).
pub fn reprojection(last_view_proj: Mat4, last_eye: DVec3, view_proj: Mat4, eye: DVec3) -> Mat4 {
    let last = DMat4::from_cols_array(&last_view_proj.to_cols_array().map(f64::from));
    let current = DMat4::from_cols_array(&view_proj.to_cols_array().map(f64::from));
    (last * DMat4::from_translation(eye - last_eye) * current.inverse()).as_mat4()
}

/// Whether the projection changed its lens by more than `factor` between two frames: its
/// horizontal or vertical focal length (the field of view) or its depth term (the near plane
/// of a reverse-Z projection) grew or shrank by more than `factor`, or changed sign.
pub fn lens_changed(last: Mat4, now: Mat4, factor: f32) -> bool {
    [
        (last.x_axis.x, now.x_axis.x),
        (last.y_axis.y, now.y_axis.y),
        (last.w_axis.z, now.w_axis.z),
    ]
    .into_iter()
    .any(|(a, b)| {
        if a == b {
            return false;
        }
        let ratio = a / b;
        !(ratio > 0.0 && ratio <= factor && ratio >= 1.0 / factor)
    })
}

/// The camera of the last resolved frame.
#[derive(Clone, Copy, Debug)]
struct LastView {
    view_proj: Mat4,
    projection: Mat4,
    eye: DVec3,
    forward: DVec3,
}

/// The temporal anti-aliasing stage: the texture the frame is drawn into, the two histories
/// (read one, write the other, swapped every frame) and the resolve and output passes.
pub struct Taa {
    settings: TaaSettings,
    resolve: wgpu::ComputePipeline,
    resolve_layout: wgpu::BindGroupLayout,
    output: wgpu::RenderPipeline,
    output_layout: wgpu::BindGroupLayout,
    color_format: wgpu::TextureFormat,
    /// The blades' motion vectors ([`MOTION_FORMAT`]), cleared every frame.
    motion: wgpu::TextureView,
    /// The frame's texture, the histories and spreads, the output's bind groups.
    textures: Textures,
    resolve_groups: [DepthBound; 2],
    params: TaaParams,
    buffer: wgpu::Buffer,
    /// The history the next resolve reads (it writes the other).
    read: usize,
    last: Option<LastView>,
    /// The last frame's unjittered view-projection from this frame's camera-relative
    /// positions (this frame's own after a cut).
    last_view_proj: Mat4,
    /// Frames prepared: the index into the jitter sequence.
    frames: u64,
}

/// The stage's textures at `size`: the frame's, the two histories, the two spreads beside them,
/// and the output pass's bind groups over the histories.
fn textures(
    device: &wgpu::Device,
    output_layout: &wgpu::BindGroupLayout,
    color_format: wgpu::TextureFormat,
    size: (u32, u32),
) -> Textures {
    // Copies in are for tests that set a frame of their own.
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
        | wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::COPY_DST;
    let scene = crate::gpu::target_texture(device, "taa frame", color_format, usage, size)
        .create_view(&Default::default());
    let history = [0, 1].map(|i| {
        crate::gpu::target_texture(
            device,
            &format!("taa history {i}"),
            HISTORY_FORMAT,
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
            size,
        )
        .create_view(&Default::default())
    });
    let spread = [0, 1].map(|i| {
        crate::gpu::target_texture(
            device,
            &format!("taa spread {i}"),
            SPREAD_FORMAT,
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
            size,
        )
        .create_view(&Default::default())
    });
    let output_groups = [0, 1].map(|i| {
        crate::gpu::layout::bind_group_with_indices(
            device,
            "taa output",
            output_layout,
            [(5, view_of(&history[i]))],
        )
    });
    Textures {
        scene,
        history,
        spread,
        output_groups,
    }
}

/// What [`textures`] makes.
struct Textures {
    scene: wgpu::TextureView,
    history: [wgpu::TextureView; 2],
    spread: [wgpu::TextureView; 2],
    output_groups: [wgpu::BindGroup; 2],
}

/// The blades' motion vectors at `size` ([`MOTION_FORMAT`]).
fn motion_texture(device: &wgpu::Device, size: (u32, u32)) -> wgpu::TextureView {
    // Copies in are for tests that set motion of their own.
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
        | wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::COPY_DST;
    crate::gpu::target_texture(device, "taa motion", MOTION_FORMAT, usage, size)
        .create_view(&Default::default())
}

impl Taa {
    /// The stage for `targets`, with `settings`.
    pub fn new(
        device: &wgpu::Device,
        targets: &crate::gpu::Targets,
        settings: TaaSettings,
    ) -> Self {
        let module = crate::shaders::module(device, "aa_taa.wgsl");
        let resolve_layout = bind_group_layout(
            device,
            "taa resolve",
            &with_indices(
                wgpu::ShaderStages::COMPUTE,
                [
                    // A read-only storage buffer, not a uniform buffer: software Vulkan
                    // (lavapipe) compiles a variant of a shader for each value of the uniforms
                    // that its branches depend on, and keeps them all; this one's change every
                    // frame (the reprojection, the jitter), which grew memory by 0.7 MiB a
                    // frame in `verdant soak`.
                    (0, storage_buffer_read_only()),
                    (1, texture_2d(UNFILTERABLE_FLOAT)),
                    (2, texture_depth_2d()),
                    (3, texture_2d(UNFILTERABLE_FLOAT)),
                    (4, texture_storage_2d(HISTORY_FORMAT)),
                    // The blades' motion (binding 5 is the output pass's).
                    (6, texture_2d(UNFILTERABLE_FLOAT)),
                    (7, texture_2d(UNFILTERABLE_FLOAT)),
                    (8, texture_storage_2d(SPREAD_FORMAT)),
                ],
            ),
        );
        let decode = [("DECODE_SRGB", targets.encode_srgb())];
        let resolve = compute_pipeline_with_constants(
            device,
            "taa resolve",
            &module,
            "cs_taa_resolve",
            &[&resolve_layout],
            &decode,
        );
        let output_layout = bind_group_layout(
            device,
            "taa output",
            &with_indices(
                wgpu::ShaderStages::FRAGMENT,
                [(5, texture_2d(UNFILTERABLE_FLOAT))],
            ),
        );
        let encode = [("ENCODE_SRGB", targets.encode_srgb())];
        let output = render_pipeline(
            "taa output",
            &module,
            ("vs_full", "fs_taa_output"),
            targets.color_format,
        )
        .layouts(&[&output_layout])
        .constants(&[], &encode)
        .build(device);
        let buffer = buffer(
            device,
            "taa",
            std::mem::size_of::<TaaParams>() as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        );
        let textures = textures(
            device,
            &output_layout,
            targets.color_format,
            (targets.width, targets.height),
        );
        Self {
            settings,
            resolve,
            resolve_layout,
            output,
            output_layout,
            color_format: targets.color_format,
            motion: motion_texture(device, (targets.width, targets.height)),
            textures,
            resolve_groups: Default::default(),
            params: TaaParams {
                reproject: Mat4::IDENTITY.to_cols_array_2d(),
                size: [
                    targets.width as f32,
                    targets.height as f32,
                    settings.max_samples as f32,
                    1.0,
                ],
                clip: [
                    settings.clip_sigma,
                    settings.motion_falloff,
                    settings.pixel_spread,
                    settings.parallax_falloff,
                ],
                hold: [settings.min_samples, 0.0, 0.0, settings.reconstruct_px],
                sway: [settings.sway_falloff, 0.0, 0.0, 0.0],
            },
            buffer,
            read: 0,
            last: None,
            last_view_proj: Mat4::IDENTITY,
            frames: 0,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &TaaSettings {
        &self.settings
    }

    /// Follows a resize of the targets: new textures, and every history starts again.
    pub fn resize(&mut self, device: &wgpu::Device, width: u32, height: u32) {
        self.textures = textures(
            device,
            &self.output_layout,
            self.color_format,
            (width, height),
        );
        self.motion = motion_texture(device, (width, height));
        self.resolve_groups = Default::default();
        self.params.size[0] = width as f32;
        self.params.size[1] = height as f32;
        self.last = None;
    }

    /// Starts every pixel's history again at the next frame (a cut the camera's move does not
    /// show, such as a change of scene).
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// The texture the frame's passes draw into instead of the caller's colour target.
    pub fn scene_view(&self) -> &wgpu::TextureView {
        &self.textures.scene
    }

    /// The texture the blades write their motion vectors into ([`MOTION_FORMAT`]; cleared by
    /// [`Self::record_clear_motion`]).
    pub fn motion_view(&self) -> &wgpu::TextureView {
        &self.motion
    }

    /// The last frame's unjittered view-projection from this frame's camera-relative
    /// positions, as the last [`Self::prepare`] found it (this frame's own after a cut): what
    /// the blades' motion vectors are taken against.
    pub fn last_view_proj(&self) -> Mat4 {
        self.last_view_proj
    }

    /// Records the clearing of the motion vectors: no blade has written any yet.
    pub fn record_clear_motion(&self, encoder: &mut wgpu::CommandEncoder) {
        render_pass(
            encoder,
            "taa motion clear",
            (&self.motion, wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT)),
            None,
            None,
        );
    }

    /// The sub-pixel offset of the next frame to prepare.
    pub fn next_jitter(&self) -> Vec2 {
        super::jitter(self.frames)
    }

    /// Sets up the resolve of the frame drawn from `view_proj` (camera-relative, unjittered,
    /// whose projection alone is `projection`) at `eye` looking along `forward`: the
    /// reprojection from the last frame, or a start from scratch after a cut (a move, a turn
    /// or a change of projection past the settings' limits). Returns whether the histories
    /// start again.
    pub fn prepare(
        &mut self,
        queue: &wgpu::Queue,
        view_proj: Mat4,
        projection: Mat4,
        eye: DVec3,
        forward: DVec3,
    ) -> bool {
        let cut = match self.last {
            None => true,
            Some(last) => {
                let angle = last
                    .forward
                    .dot(forward)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                (eye - last.eye).length() > self.settings.cut_distance_m
                    || angle > self.settings.cut_angle_deg
                    || lens_changed(last.projection, projection, self.settings.cut_zoom)
            }
        };
        self.params.reproject = match self.last {
            Some(last) if !cut => reprojection(last.view_proj, last.eye, view_proj, eye),
            _ => Mat4::IDENTITY,
        }
        .to_cols_array_2d();
        self.last_view_proj = match self.last {
            Some(last) if !cut => reprojection(last.view_proj, last.eye, Mat4::IDENTITY, eye),
            _ => view_proj,
        };
        self.params.size[3] = if cut { 1.0 } else { 0.0 };
        // The frame being resolved was drawn with the jitter [`Self::next_jitter`] gave.
        let jitter = self.next_jitter();
        self.params.hold[1] = jitter.x;
        self.params.hold[2] = jitter.y;
        queue.write_buffer(&self.buffer, 0, bytemuck::bytes_of(&self.params));
        self.last = Some(LastView {
            view_proj,
            projection,
            eye,
            forward,
        });
        self.frames += 1;
        cut
    }

    /// Records the resolve of the frame drawn into [`Taa::scene_view`] (with its depth in
    /// `depth`) against the history into the next history (compute, `taa_resolve`), then that
    /// into `color` (`taa_output`).
    pub fn record(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        timer: &mut crate::gpu::GpuTimer,
    ) {
        let (read, write) = (self.read, 1 - self.read);
        let (scene, history, spread, buffer, layout, motion) = (
            &self.textures.scene,
            &self.textures.history,
            &self.textures.spread,
            &self.buffer,
            &self.resolve_layout,
            &self.motion,
        );
        let group = self.resolve_groups[read].get(depth, |depth| {
            crate::gpu::layout::bind_group_with_indices(
                device,
                "taa resolve",
                layout,
                [
                    (0, buffer.as_entire_binding()),
                    (1, view_of(scene)),
                    (2, view_of(depth)),
                    (3, view_of(&history[read])),
                    (4, view_of(&history[write])),
                    (6, view_of(motion)),
                    (7, view_of(&spread[read])),
                    (8, view_of(&spread[write])),
                ],
            )
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("taa resolve"),
                timestamp_writes: timer.compute_pass("taa_resolve"),
            });
            // The frame's size (the caller's depth may be a view of one level of a larger
            // texture).
            let size = self.textures.scene.texture().size();
            pass.set_pipeline(&self.resolve);
            pass.set_bind_group(0, group, &[]);
            pass.dispatch_workgroups(size.width.div_ceil(8), size.height.div_ceil(8), 1);
        }
        let mut pass = render_pass(
            encoder,
            "taa output",
            (color, wgpu::LoadOp::Clear(wgpu::Color::BLACK)),
            None,
            timer.render_pass("taa_output"),
        );
        pass.set_pipeline(&self.output);
        pass.set_bind_group(0, &self.textures.output_groups[write], &[]);
        pass.draw(0..3, 0..1);
        self.read = write;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_still_camera_reprojects_every_pixel_onto_itself_and_a_move_shifts_it() {
        let camera = crate::Camera::new(DVec3::new(1e5, -2e5, 300.0), 40.0, -8.0);
        let vp = camera.view_proj_relative(1.5);
        let m = reprojection(vp, camera.position, vp, camera.position);
        assert!(m.abs_diff_eq(Mat4::IDENTITY, 1e-4), "{m}");
        // One metre east: a point 10 m ahead and 1 m below moves on screen, and the pixel of
        // the current frame lands where that point was in the last one.
        let mut moved = camera;
        moved.position.x += 1.0;
        let m = reprojection(vp, camera.position, vp, moved.position);
        let p = glam::Vec3::new(8.0, 6.0, -1.0);
        let now = vp * (p - glam::Vec3::X).extend(1.0);
        let then = vp * p.extend(1.0);
        let back = m * (now / now.w);
        assert!(((back / back.w) - then / then.w).length() < 1e-4);
    }

    #[test]
    fn a_change_of_lens_past_the_factor_is_a_cut_and_a_smaller_one_is_not() {
        let mut camera = crate::Camera::new(DVec3::ZERO, 0.0, 0.0);
        let lens = |c: &crate::Camera| c.view_and_projection(16.0 / 9.0).1;
        let start = lens(&camera);
        assert!(!lens_changed(start, start, 2.0));
        // A zoom from 60 to 45 degrees (focal length x1.39) is followed by the reprojection;
        // to 25 degrees (x2.6) it starts again.
        camera.fov_y_deg = 45.0;
        assert!(!lens_changed(start, lens(&camera), 2.0));
        camera.fov_y_deg = 25.0;
        assert!(lens_changed(start, lens(&camera), 2.0));
        assert!(lens_changed(lens(&camera), start, 2.0));
        // The near plane: 0.5 m to 0.7 m goes on, to 100 m (the ground clipped away) and back
        // starts again.
        camera.fov_y_deg = 60.0;
        camera.near_m = 0.7;
        assert!(!lens_changed(start, lens(&camera), 2.0));
        camera.near_m = 100.0;
        assert!(lens_changed(start, lens(&camera), 2.0));
        assert!(lens_changed(lens(&camera), start, 2.0));
        // A projection of another kind (an orthographic one of the same scale: no depth term).
        let mut ortho = start;
        ortho.w_axis.z = 0.0;
        assert!(lens_changed(start, ortho, 2.0));
        assert!(lens_changed(ortho, start, 2.0));
    }
}
