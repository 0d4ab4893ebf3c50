//! `verdant soak`: its options and the summary it prints.

use std::path::PathBuf;

use anyhow::{Result, bail};
use indicatif::ProgressBar;

use verdant::tools::{SoakOptions, run_soak};

use super::args::{StreamArgs, float_in, parse_size, resolve_world};
use super::out::{note, say};
use super::progress::bar;

// The options of `verdant soak`.
#[derive(clap::Args)]
pub(crate) struct SoakArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address.
    #[arg(default_value = "santa-cruz")]
    pub(crate) world: std::ffi::OsString,
    /// Simulated flight time, seconds (0.1 s a frame), 4.6..=604800 (a week; the least leaves
    /// room for the memory check after the warm-up's 3 s).
    #[arg(long, default_value_t = 60.0, value_parser = float_in(verdant::tools::soak::MIN_SOAK_S, 604_800.0))]
    pub(crate) seconds: f64,
    /// Camera speed, metres a second, 0..=1000 (and at most 4% of the world's width a frame,
    /// 0.1 s: the camera must stay over the world).
    #[arg(long, default_value_t = 50.0, value_parser = float_in(0.0, 1000.0))]
    pub(crate) speed: f64,
    /// Seed of the turns and teleports.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Image size, WIDTHxHEIGHT, 1..=16384 pixels a side.
    #[arg(long, default_value = "320x180", value_parser = parse_size)]
    pub(crate) size: (u32, u32),
    /// Output folder.
    #[arg(long, default_value = "out/soak")]
    pub(crate) out: PathBuf,
    /// Fly without grass and its wind: the streaming system alone.
    #[arg(long)]
    pub(crate) no_grass: bool,
    /// Anti-aliasing while flying: off, taa or msaa (default: the renderer's).
    #[arg(long)]
    pub(crate) aa: Option<verdant::aa::AntiAliasing>,
    /// A teleport must reach full detail within this many frames, 1..=100000, or within
    /// the simulated time they stand for (0.1 s each) of wall time, on a machine that
    /// renders faster than that.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub(crate) max_recovery_frames: u32,
    /// No frame may take longer than this, milliseconds (wall time), 1..=3600000.
    #[arg(long, default_value_t = 5000.0, value_parser = float_in(1.0, 3_600_000.0))]
    pub(crate) max_stall_ms: f64,
    /// Inject faults while flying, 0..=1 (0: none). A world on disk is flown from a copy
    /// in --out whose tile files (level 1 and finer) are removed, truncated, overwritten
    /// with garbage, emptied or replaced by a folder, this share of them at any moment,
    /// a fresh set every 2 s of flight; a world over HTTP through a proxy that fails this
    /// share of tile requests (errors, stalls, resets, short bodies). The checks stay the
    /// same: broken tiles are drawn from their ancestors (no holes) and retried.
    #[arg(long, default_value_t = 0.0, value_parser = float_in(0.0, 1.0))]
    pub(crate) faults: f64,
    #[command(flatten)]
    pub(crate) stream: StreamArgs,
}

impl SoakArgs {
    pub(crate) fn options(self) -> Result<SoakOptions> {
        let SoakArgs {
            world,
            seconds,
            speed,
            seed,
            size,
            out,
            no_grass,
            aa,
            max_recovery_frames,
            max_stall_ms,
            faults,
            stream,
        } = self;
        Ok(SoakOptions {
            world: resolve_world(&world)?,
            http: stream.http(),
            seconds,
            speed_mps: speed,
            seed,
            size,
            out,
            service: stream.service(),
            no_grass,
            aa: aa.unwrap_or_default(),
            max_recovery_frames,
            max_stall_ms,
            faults,
            ..SoakOptions::default()
        })
    }
}

pub(crate) fn soak(mut opts: SoakOptions) -> Result<()> {
    // Ctrl-C ends the soak after the frame under way, checking and reporting what was flown; a
    // second one ends the process at once.
    opts.stop = Some(super::stop_on_signals()?);
    let mut pb: Option<ProgressBar> = None;
    let r = run_soak(&opts, &mut |done, total| {
        pb.get_or_insert_with(|| bar(total, "frames"))
            .set_position(done);
    })?;
    super::progress::end_bar(pb.as_ref(), r.interrupted);
    let mib = |b: u64| b as f64 / 1048576.0;
    say!(
        "{} frames ({} s at {} m/s) on {}: frame p50 {:.1} ms, p99 {:.1} ms",
        r.frames,
        verdant::world::error::short_number(r.seconds),
        r.speed_mps,
        r.adapter.name,
        r.frame_ms.median,
        r.frame_ms.p99
    )?;
    say!(
        "peak RSS {:.1} MiB, growth after warm-up {:.1} MiB (halves {:.1} and {:.1} MiB); cache peak {:.1} of {:.1} MiB; atlas peak {} of {} slots",
        mib(r.rss_peak_bytes),
        mib(r.rss_growth_bytes),
        r.rss_growth_halves_bytes[0] as f64 / 1048576.0,
        r.rss_growth_halves_bytes[1] as f64 / 1048576.0,
        mib(r.cache_peak_bytes),
        mib(r.cache_ceiling_bytes),
        r.atlas_peak_slots,
        r.atlas_slots
    )?;
    if r.plants_drawn_peak + r.trees_drawn_peak > 0 {
        say!(
            "most drawn in a frame: {} blades, {} plants, {} trees; {} plant and tree instances \
             thinned out where their pool's regions were crowded, {} overflowed",
            r.grass_blades_drawn_peak,
            r.plants_drawn_peak,
            r.trees_drawn_peak,
            r.plants_crowded_total,
            r.plants_overflow_total
        )?;
    }
    // A run shorter than the time to its first teleport has none to measure: say so, rather
    // than that full detail was never reached.
    let detail = match (r.teleports.len(), r.full_detail_after_teleport_s) {
        (0, _) => format!(
            "no teleport in this run (the first comes after {} s of flight)",
            opts.teleport_every_s
        ),
        (n, Some(s)) => format!("full detail {s:.1} s after a teleport (median of {n})"),
        (n, None) => format!("full detail never reached after a teleport ({n} teleports)"),
    };
    say!(
        "loads: {} completed, {} cancelled, {} failed; {} evictions; cache hit rate {:.0}%; \
         {detail}",
        r.loads_completed,
        r.loads_cancelled,
        r.loads_failed,
        r.evictions,
        100.0 * r.cache_hit_rate,
    )?;
    if let Some(f) = &r.faults {
        let injected = match (&f.files, &f.http) {
            (Some(c), _) => format!("{} tile files broken", c.injected()),
            (_, Some(h)) => format!("{} of {} requests faulted", h.faults(), h.requests),
            _ => "none injected".to_owned(),
        };
        say!(
            "faults at rate {}: {injected}, {} loads failed, {} tiles healed, at most {} \
             desired tiles drawn from an ancestor for a fault",
            f.rate,
            f.loads_failed,
            f.tiles_healed,
            f.fault_blocked_peak
        )?;
    }
    say!("wrote {}", opts.out.join("soak.json").display())?;
    if !r.violations.is_empty() {
        for v in r.violations.iter().take(20) {
            note!("violation: {v}");
        }
        if r.interrupted {
            return Err(super::Interrupted(format!(
                "stopped after {} frames; {} describes those",
                r.frames,
                opts.out.join("soak.json").display()
            ))
            .into());
        }
        bail!("the soak failed {} check(s)", r.violation_count);
    }
    Ok(())
}
