//! `verdant eval`: the evaluations' subcommands and the tables they print.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Subcommand;
use indicatif::ProgressBar;

use verdant::tools::stop::Stop;

use super::out::{note, say};
use super::progress::{bar, lines};

#[derive(Subcommand)]
pub(crate) enum EvalCommand {
    /// Downsample a DEM by K, derive it back with each method (nearest, bilinear, bicubic,
    /// bicubic + fixed detail, inherited detail, a kernel fitted to the coarse grid, and the
    /// calibrated detail fitted to it), and chart height and slope error against time per tile.
    #[command(allow_negative_numbers = true)]
    Derive {
        /// The DEM: a GeoTIFF, an SRTM .hgt, or a 16-bit PNG with its JSON sidecar.
        #[arg(long)]
        dem: PathBuf,
        /// Spacing of the DEM's samples in metres, M or EW,NS (each above 0 and at most 1e6), in
        /// place of what the file says (needed for a TIFF without GeoTIFF tags), as bake takes it.
        #[arg(long, value_name = "M|EW,NS", value_parser = super::args::parse_cell_size)]
        dem_cell_size: Option<[f64; 2]>,
        /// Downsampling factor, a power of two in 2..=64.
        #[arg(long, default_value_t = 4, value_parser = super::args::power_of_two_in(2, 64))]
        factor: u32,
        /// Output folder for derive.csv and the charts.
        #[arg(long, default_value = "out/eval-derive")]
        out: PathBuf,
    },
    /// Step the grass sway spring (stiff and soft presets) with explicit Euler, semi-implicit
    /// Euler and the exact solution at frame times from 1/240 s to 1/5 s and at a 0.5 s hitch;
    /// chart error against cost and where each blows up.
    #[command(allow_negative_numbers = true)]
    Sway {
        /// Output folder for sway.csv and the charts.
        #[arg(long, default_value = "out/eval-sway")]
        out: PathBuf,
    },
}

pub(crate) fn eval_derive(
    dem_path: &Path,
    dem_cell_size: Option<[f64; 2]>,
    factor: usize,
    out: &Path,
) -> Result<()> {
    use verdant::tools::eval_derive as eval;
    // Ctrl-C stops the eval after the method under way, writing the methods run; a second one
    // ends the process at once.
    let stop = Stop::new(Some(super::stop_on_signals()?));
    let lines = lines();
    let mut pb: Option<ProgressBar> = None;
    let dem = verdant::world::DemOptions {
        cell_size_m: dem_cell_size,
    };
    let report = eval::run_derive_eval(
        dem_path,
        &dem,
        factor,
        out,
        &stop,
        &mut |method, done, total| {
            if lines {
                note!("methods: {done}/{total}");
            }
            let pb = pb.get_or_insert_with(|| bar(total, "methods"));
            pb.set_message(method.to_owned());
            pb.set_position(done);
        },
    );
    let interrupted = report.as_ref().is_ok_and(|r| r.interrupted);
    super::progress::end_bar(pb.as_ref(), interrupted);
    let report = report?;
    if report.results.is_empty() {
        return Err(nothing_measured());
    }
    say!(
        "{:<22} {:>9} {:>9} {:>10} {:>10} {:>9} {:>11}  parameters",
        "method",
        "RMSE m",
        "max m",
        "slope deg",
        "bias deg",
        "rough",
        "ms/tile"
    )?;
    for r in &report.results {
        let rough = if r.roughness_ratio.is_nan() {
            "-".to_owned()
        } else {
            format!("{:.3}", r.roughness_ratio)
        };
        say!(
            "{:<22} {:>9.3} {:>9.2} {:>10.3} {:>10.3} {:>9} {:>11.4}  {}",
            r.method,
            r.rmse_m,
            r.max_m,
            r.slope_rmse_deg,
            r.slope_bias_deg,
            rough,
            r.ms_per_tile,
            r.parameters()
        )?;
    }
    if report.results.iter().any(|r| r.roughness_ratio.is_nan()) {
        say!(
            "roughness: not measured, the DEM is smoother than the {} mm of curvature a ratio \
             is measured against (a plane)",
            verdant::tools::eval_derive::MIN_ROUGHNESS_M * 1e3
        )?;
    }
    if let Some(fit) = report.calibration() {
        say!("calibration from the coarse grid: {}", fit.note)?;
    }
    say!(
        "on the joint Pareto front (time, height, slope, flattening, roughness): {}",
        report.front.join(", ")
    )?;
    let runtime = if !report
        .results
        .iter()
        .any(|r| r.method == eval::RUNTIME_METHOD)
    {
        "not run"
    } else if report.runtime_on_front() {
        "on the joint front"
    } else {
        "NOT on the joint front"
    };
    say!(
        "runtime method: {} ({runtime}); wrote derive.csv and charts to {}{}",
        eval::RUNTIME_METHOD,
        out.display(),
        partial(report.interrupted)
    )?;
    if report.interrupted {
        let total = eval::methods().len() + 2;
        return Err(super::Interrupted(format!(
            "stopped after {} of {total} methods; {} holds those",
            report.results.len(),
            out.join("derive.csv").display()
        ))
        .into());
    }
    Ok(())
}

/// The words after a summary's "wrote ..." of an eval that was stopped early.
fn partial(interrupted: bool) -> &'static str {
    if interrupted {
        " (partial: the eval was interrupted)"
    } else {
        ""
    }
}

/// The error that ends an eval stopped before its first result (status 130).
fn nothing_measured() -> anyhow::Error {
    super::Interrupted("stopped before the first measurement; nothing written".to_owned()).into()
}

pub(crate) fn eval_sway(out: &Path) -> Result<()> {
    use verdant::tools::eval_sway as sway;
    use verdant::tools::sway_integrators::{EulerLimits, Integrator, Preset, RENDERER_INTEGRATOR};
    // Ctrl-C stops the eval after the run under way, writing the runs made; a second one ends
    // the process at once.
    let stop = Stop::new(Some(super::stop_on_signals()?));
    let lines = lines();
    let mut pb: Option<ProgressBar> = None;
    let report = sway::run_sway_eval(out, &stop, &mut |done, total| {
        if lines {
            note!("runs: {done}/{total}");
        }
        pb.get_or_insert_with(|| bar(total, "runs"))
            .set_position(done);
    });
    let interrupted = report.as_ref().is_ok_and(|r| r.interrupted);
    super::progress::end_bar(pb.as_ref(), interrupted);
    let report = report?;
    if report.results.is_empty() {
        return Err(nothing_measured());
    }
    for preset in Preset::ALL {
        let spring = preset.spring();
        say!(
            "{} spring (grass stiffness {}): k {:.1} 1/s^2, c {:.2} 1/s ({:.3} Hz, damping ratio {:.2}); \
             explicit Euler stable below {:.1} ms, semi-implicit below {:.1} ms",
            preset.name(),
            preset.grass_stiffness(),
            spring.stiffness,
            spring.damping,
            spring.natural_frequency_hz(),
            spring.damping_ratio(),
            spring.explicit_euler_max_dt() * 1e3,
            spring.semi_implicit_euler_max_dt() * 1e3
        )?;
    }
    say!(
        "{:<7} {:<14} {:>7} {:>11} {:>11} {:>8}  stable",
        "preset",
        "integrator",
        "dt",
        "RMS rad",
        "max rad",
        "ns/step"
    )?;
    for r in &report.results {
        say!(
            "{:<7} {:<14} {:>7} {:>11.3e} {:>11.3e} {:>8.1}  {}",
            r.preset,
            r.integrator.name(),
            sway::dt_label(r.dt_s),
            r.rms_error,
            r.max_error,
            r.ns_per_step,
            match r.blew_up_at_s {
                None => "yes".to_owned(),
                Some(t) => format!("NO, blew up at {t:.2} s"),
            }
        )?;
    }
    let names: Vec<&str> = report.stable.iter().map(Integrator::name).collect();
    say!(
        "stable at every step and at the 0.5 s hitch, both presets: {}",
        match (names.is_empty(), report.interrupted) {
            (true, true) => "not known: the eval stopped before every run was made".to_owned(),
            (true, false) => "none".to_owned(),
            (false, true) => format!(
                "{} (the others not run at every step: the eval was stopped)",
                names.join(", ")
            ),
            (false, false) => names.join(", "),
        }
    )?;
    say!(
        "renderer integrator: {} ({}); wrote sway.csv and charts to {}{}",
        RENDERER_INTEGRATOR.name(),
        if !report
            .results
            .iter()
            .any(|r| r.integrator == RENDERER_INTEGRATOR)
        {
            "not run"
        } else if report.renderer_bounded() {
            "bounded in every run above, and exact for wind held over a frame"
        } else {
            "NOT bounded in every run above"
        },
        out.display(),
        partial(report.interrupted)
    )?;
    if report.interrupted {
        let total = Preset::ALL.len() * Integrator::ALL.len() * sway::EVAL_STEPS_S.len();
        return Err(super::Interrupted(format!(
            "stopped after {} of {total} runs; {} holds those",
            report.results.len(),
            out.join("sway.csv").display()
        ))
        .into());
    }
    Ok(())
}

/// Runs the evaluation asked for.
pub(crate) fn run(what: EvalCommand) -> Result<()> {
    match what {
        EvalCommand::Derive {
            dem,
            dem_cell_size,
            factor,
            out,
        } => eval_derive(&dem, dem_cell_size, factor as usize, &out),
        EvalCommand::Sway { out } => eval_sway(&out),
    }
}
