//! `verdant view`: its options and the summary it prints.

use std::path::PathBuf;

use anyhow::Result;

use super::args::{MAX_FRAMES, StreamArgs, parse_size, resolve_world};
use super::out::say;

// The options of `verdant view`.
#[derive(clap::Args)]
pub(crate) struct ViewArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address.
    #[arg(default_value = "santa-cruz")]
    pub(crate) world: std::ffi::OsString,
    /// Window size, WIDTHxHEIGHT, 1..=16384 pixels a side.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub(crate) size: (u32, u32),
    /// Present as fast as possible instead of waiting for the display's refresh.
    #[arg(long)]
    pub(crate) no_vsync: bool,
    /// Camera path to start on and follow with P (default: the manifest's first).
    #[arg(long)]
    pub(crate) path: Option<String>,
    /// Follow the camera path from the start.
    #[arg(long)]
    pub(crate) follow: bool,
    /// Render this many frames (a fixed 1/60 s apart) and exit, 1..=4294967295.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=MAX_FRAMES))]
    pub(crate) frames: Option<u32>,
    /// Write the last of --frames N frames to this PNG file.
    #[arg(long, requires = "frames")]
    pub(crate) screenshot: Option<PathBuf>,
    /// Wind scene to start with (default: the path's wind keys, else breeze).
    #[arg(long)]
    pub(crate) wind: Option<String>,
    /// Anti-aliasing to start with: taa (the default), off or msaa; T cycles through them.
    #[arg(long)]
    pub(crate) aa: Option<verdant::aa::AntiAliasing>,
    #[command(flatten)]
    pub(crate) stream: StreamArgs,
}

pub(crate) fn view(args: ViewArgs) -> Result<()> {
    let ViewArgs {
        world,
        size,
        no_vsync,
        path,
        follow,
        frames,
        screenshot,
        wind,
        aa,
        stream,
    } = args;
    let summary = verdant::tools::view::run_view(verdant::tools::view::ViewOptions {
        world: resolve_world(&world)?,
        http: stream.http(),
        size,
        vsync: !no_vsync,
        path,
        follow,
        frames,
        screenshot: screenshot.clone(),
        service: stream.service(),
        wind_scene: wind,
        aa,
        // No handler: a signal ends the view at once. Caught, it left the viewer drawing on
        // after a SIGTERM to its whole group had ended its X server, and winit panics then.
        stop: None,
    })?;
    // A session the user ends reports nothing.
    let Some(n) = frames else {
        return Ok(());
    };
    if summary.stopped {
        let shot = screenshot.as_ref().map_or(String::new(), |f| {
            format!("; {} was not written", f.display())
        });
        return Err(super::Interrupted(format!(
            "the view was stopped after {} of {n} frames{shot}",
            summary.frames
        ))
        .into());
    }
    if summary.frames < 2 {
        // One frame has no time between frames to take a median of.
        say!("{} frame on {}", summary.frames, summary.adapter)?;
    } else {
        say!(
            "{} frames, median {:.1} ms a frame ({:.1} fps) on {}",
            summary.frames,
            summary.median_frame_ms,
            1e3 / summary.median_frame_ms.max(1e-3),
            summary.adapter
        )?;
    }
    if let Some(file) = screenshot {
        say!("wrote {}", file.display())?;
    }
    // A run of N frames (a session the user ends reports no frames) that drew sky alone.
    if summary.frames > 0
        && let Some(warning) = verdant::tools::fly::no_terrain_drawn(
            summary.tiles_drawn_max,
            &if follow {
                format!("the view followed camera path {:?}", summary.path)
            } else {
                format!(
                    "the view stood at the first key of camera path {:?}",
                    summary.path
                )
            },
        )
    {
        log::warn!("{warning}");
    }
    Ok(())
}
