//! `verdant eval sway`: the sway spring's integrators ([`crate::wind::spring`]) measured against a
//! fine reference at frame times from 1/240 s to 1/5 s and at a 0.5 s hitch: RMS and largest
//! error, cost per step, and whether the sway blew up; CSV and charts.

use std::cmp::Ordering::{Equal, Less};
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use crate::tools::metrics::{Chart, ChartPoint, LineChart, Series, Summary};
use crate::tools::stop::{Stop, chart_title};
use crate::tools::sway_integrators::{EulerLimits, Integrator, Preset, RENDERER_INTEGRATOR};
use crate::wind::spring::{SwaySpring, SwayState, exact_step};

/// Simulated time of each run of the eval, seconds.
pub const EVAL_SECONDS: f64 = 20.0;
/// Step of the reference trajectory, seconds.
pub const REFERENCE_DT: f64 = 1.0 / 4800.0;
/// The frame hitch the renderer must survive, seconds.
pub const HITCH_S: f64 = 0.5;
/// The time steps of the eval: frame times from 1/240 s to 1/5 s, log-spaced (roughly a factor
/// 2 apart, with the common refresh rates 144 and 120 Hz), then the hitch.
pub const EVAL_STEPS_S: [f64; 9] = [
    1.0 / 240.0,
    1.0 / 144.0,
    1.0 / 120.0,
    1.0 / 60.0,
    1.0 / 30.0,
    1.0 / 20.0,
    1.0 / 10.0,
    1.0 / 5.0,
    HITCH_S,
];
/// A run blew up when `|x|` exceeded this many times the forcing amplitude (or stopped being
/// finite).
pub const BLOW_UP_FACTOR: f64 = 100.0;

/// Scale of the eval's wind forcing, 1/s^2.
const GUST_SCALE: f64 = 20.0;
/// Largest `|f|` the forcing can reach, 1/s^2.
const GUST_PEAK: f64 = 2.0 * GUST_SCALE;

/// The eval's gusty wind forcing `f(t)`, 1/s^2: a breeze of three sines (0.13, 0.71 and 2.3 Hz,
/// the last near the springs' own frequencies) and three gust fronts (steps up at 3.1 s and
/// 9.37 s, a lull from 14.05 s), repeating every 20 s. Deterministic.
pub fn gust_forcing(t: f64) -> f64 {
    use std::f64::consts::TAU;
    let mut s = 0.5
        + 0.3 * (TAU * 0.13 * t).sin()
        + 0.2 * (TAU * 0.71 * t + 1.0).sin()
        + 0.1 * (TAU * 2.3 * t + 2.0).sin();
    let p = t.rem_euclid(EVAL_SECONDS);
    if (3.1..5.6).contains(&p) {
        s += 0.6;
    }
    if (9.37..10.1).contains(&p) {
        s += 0.9;
    }
    if (14.05..16.6).contains(&p) {
        s -= 0.4;
    }
    GUST_SCALE * s
}

/// The forcing amplitude as a displacement: the largest equilibrium `|f| / k` the gusts can
/// push the spring toward, radians.
pub fn forcing_amplitude(spring: &SwaySpring) -> f64 {
    GUST_PEAK / f64::from(spring.stiffness)
}

fn target_at(spring: &SwaySpring, t: f64) -> f64 {
    gust_forcing(t) / f64::from(spring.stiffness)
}

/// The spring at rest at the equilibrium of the wind at time 0, where every run starts.
fn start_state(spring: &SwaySpring) -> SwayState {
    SwayState {
        x: target_at(spring, 0.0) as f32,
        v: 0.0,
    }
}

/// Whether `integrator` keeps the sway bounded (finite and within [`BLOW_UP_FACTOR`] times the
/// forcing amplitude) for `seconds` of simulated time of the gusty wind, stepping by `dt`, with
/// every `n`-th step a hitch of the given length when `hitch_every` is `Some((n, hitch_dt))`.
pub fn bounded_for(
    integrator: Integrator,
    spring: &SwaySpring,
    dt: f32,
    seconds: f32,
    hitch_every: Option<(usize, f32)>,
) -> bool {
    let limit = BLOW_UP_FACTOR * forcing_amplitude(spring);
    let mut s = start_state(spring);
    let mut t = 0.0f64;
    let mut i = 0usize;
    while t < f64::from(seconds) {
        i += 1;
        let h = match hitch_every {
            Some((n, hitch)) if n > 0 && i.is_multiple_of(n) => hitch,
            _ => dt,
        };
        s = integrator.step(spring, s, target_at(spring, t) as f32, h);
        if !(f64::from(s.x.abs()) <= limit && s.v.is_finite()) {
            return false;
        }
        t += f64::from(h);
    }
    true
}

/// The reference trajectory: the exact solution in f64 on a grid of [`REFERENCE_DT`] with the
/// wind sampled at the start of each grid step (so as good as continuous forcing), split where
/// a query time falls inside a grid step.
struct Reference {
    k: f64,
    c: f64,
    spring: SwaySpring,
    x: f64,
    v: f64,
    t: f64,
    next: u64,
}

impl Reference {
    fn new(spring: &SwaySpring) -> Self {
        let s = start_state(spring);
        Self {
            k: f64::from(spring.stiffness),
            c: f64::from(spring.damping),
            spring: *spring,
            x: f64::from(s.x),
            v: 0.0,
            t: 0.0,
            next: 1,
        }
    }

    fn step_to(&mut self, t: f64) {
        let h = t - self.t;
        if h > 0.0 {
            let target = target_at(&self.spring, self.t);
            (self.x, self.v) = exact_step(self.k, self.c, self.x, self.v, target, h);
        }
        self.t = t;
    }

    /// Advances to time `t` and returns the displacement there.
    fn x_at(&mut self, t: f64) -> f64 {
        loop {
            let grid = self.next as f64 * REFERENCE_DT;
            if grid <= t + 1e-12 {
                self.step_to(grid);
                self.next += 1;
            } else {
                self.step_to(t.max(self.t));
                return self.x;
            }
        }
    }
}

/// What one integrator achieved on one spring at one time step.
#[derive(Clone, Debug)]
pub struct SwayResult {
    /// The preset's name.
    pub preset: String,
    /// The integrator.
    pub integrator: Integrator,
    /// Time step, seconds.
    pub dt_s: f64,
    /// RMS of `x` minus the reference's, radians, over the steps of the run (up to and
    /// including the step where it blew up, if it did).
    pub rms_error: f64,
    /// Largest `|x - x_reference|`, radians, over the same steps.
    pub max_error: f64,
    /// CPU time per step, nanoseconds (median of repeated timed runs).
    pub ns_per_step: f64,
    /// The run stayed bounded for the whole [`EVAL_SECONDS`].
    pub stable: bool,
    /// Simulated time at which it blew up, seconds.
    pub blew_up_at_s: Option<f64>,
    /// Largest `|x|` of the run, radians (up to the blow-up).
    pub max_abs_x: f64,
    /// The forcing amplitude (largest `|f| / k`), radians.
    pub forcing_amplitude: f64,
}

/// Median CPU time of one step, nanoseconds: several timed runs of many steps, the inputs
/// hidden from the optimiser so that each step is computed from scratch.
fn ns_per_step(integrator: Integrator, spring: &SwaySpring, dt: f64) -> f64 {
    const STEPS: usize = 50_000;
    const RUNS: usize = 9;
    let targets: Vec<f32> = (0..1024)
        .map(|i| target_at(spring, i as f64 * dt) as f32)
        .collect();
    let limit = (BLOW_UP_FACTOR * forcing_amplitude(spring)) as f32;
    let start = start_state(spring);
    let mut times = Vec::with_capacity(RUNS);
    for _ in 0..RUNS {
        let mut s = start;
        let clock = Instant::now();
        for i in 0..STEPS {
            s = black_box(integrator).step(
                black_box(spring),
                s,
                targets[i & 1023],
                black_box(dt as f32),
            );
            // An unstable run starts again, so that it is timed on ordinary numbers (a NaN
            // counts as unstable).
            if !matches!(s.x.abs().partial_cmp(&limit), Some(Less | Equal)) {
                s = start;
            }
        }
        black_box(s);
        times.push(clock.elapsed().as_nanos() as f64 / STEPS as f64);
    }
    Summary::of(&times).median
}

/// Runs `integrator` on `preset` at step `dt` for [`EVAL_SECONDS`] of the gusty wind and
/// compares it with the reference at the end of every step.
pub fn evaluate(preset: Preset, integrator: Integrator, dt: f64) -> SwayResult {
    let spring = preset.spring();
    let amplitude = forcing_amplitude(&spring);
    let limit = BLOW_UP_FACTOR * amplitude;
    let steps = (EVAL_SECONDS / dt).round() as usize;
    let mut reference = Reference::new(&spring);
    let mut s = start_state(&spring);
    let (mut se, mut max_error, mut max_abs_x, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    let mut blew_up_at_s = None;
    for i in 0..steps {
        let t0 = i as f64 * dt;
        let t1 = (i + 1) as f64 * dt;
        s = integrator.step(&spring, s, target_at(&spring, t0) as f32, dt as f32);
        let x = f64::from(s.x);
        let e = (x - reference.x_at(t1)).abs();
        se += e * e;
        max_error = max_error.max(e);
        max_abs_x = max_abs_x.max(x.abs());
        n += 1;
        if !(x.abs() <= limit && s.v.is_finite()) {
            if !x.is_finite() {
                (max_error, max_abs_x) = (f64::INFINITY, f64::INFINITY);
            }
            blew_up_at_s = Some(t1);
            break;
        }
    }
    SwayResult {
        preset: preset.name().into(),
        integrator,
        dt_s: dt,
        rms_error: (se / n.max(1) as f64).sqrt(),
        max_error,
        ns_per_step: ns_per_step(integrator, &spring, dt),
        stable: blew_up_at_s.is_none(),
        blew_up_at_s,
        max_abs_x,
        forcing_amplitude: amplitude,
    }
}

/// Every preset, integrator and step of the eval (preset by preset, then integrator, then
/// step).
pub fn evaluate_all() -> Vec<SwayResult> {
    evaluate_until(&Stop::default(), &mut |_, _| {})
}

/// Every run [`evaluate_all`] makes, in its order, until `stop` is asked for (between runs:
/// then the runs made so far); `progress` hears the runs done and their total after each.
pub fn evaluate_until(stop: &Stop, progress: &mut dyn FnMut(u64, u64)) -> Vec<SwayResult> {
    let runs: Vec<(Preset, Integrator, f64)> = Preset::ALL
        .into_iter()
        .flat_map(|p| {
            Integrator::ALL
                .into_iter()
                .flat_map(move |i| EVAL_STEPS_S.map(|dt| (p, i, dt)))
        })
        .collect();
    let mut out = Vec::new();
    for (preset, integrator, dt) in runs.iter().copied() {
        if stop.requested() {
            break;
        }
        out.push(evaluate(preset, integrator, dt));
        progress(out.len() as u64, runs.len() as u64);
    }
    out
}

/// The integrators that stayed bounded in every run of `results` and were run at every step
/// of [`EVAL_STEPS_S`] with both presets (an integrator that an eval stopped early ran only in
/// part is not among them).
pub fn stable_everywhere(results: &[SwayResult]) -> Vec<Integrator> {
    Integrator::ALL
        .into_iter()
        .filter(|i| {
            let runs: Vec<&SwayResult> = results.iter().filter(|r| r.integrator == *i).collect();
            let ran_everywhere = Preset::ALL.iter().all(|p| {
                EVAL_STEPS_S
                    .iter()
                    .all(|dt| runs.iter().any(|r| r.preset == p.name() && r.dt_s == *dt))
            });
            ran_everywhere && runs.iter().all(|r| r.stable)
        })
        .collect()
}

/// A time step as people say it: `1/60` for a frame rate, `0.5 s` otherwise.
pub fn dt_label(dt: f64) -> String {
    let rate = 1.0 / dt;
    if dt < 0.5 && (rate - rate.round()).abs() < 1e-6 {
        format!("1/{}", rate.round())
    } else {
        format!("{dt} s")
    }
}

/// The files [`run_sway_eval`] writes into its output folder.
const FILES: [&str; 4] = [
    "sway.csv",
    "sway_error.png",
    "sway_error_soft.png",
    "sway_stability.png",
];

/// Runs the eval ([`evaluate_all`]) and writes into `out` (created if needed):
///
/// - `sway.csv`: one row per preset, integrator and time step: `rms_error`, `max_error` and
///   `max_abs_x` in radians, `ns_per_step`, `stable`, `blew_up_at_s` (empty when stable). For
///   a run that blew up the errors cover the steps up to and including the one that blew up.
/// - `sway_error.png` (stiff preset) and `sway_error_soft.png` (soft preset): RMS error against
///   ns per step, a point per integrator and step, the renderer's integrator highlighted, the
///   Pareto front taken over the runs that stayed bounded. A run that blew up has no
///   meaningful error: it is drawn above every measured error (from ten times the largest
///   stable error up, a factor 2 apart) and labelled "blew up".
/// - `sway_stability.png`: largest `|x|` against the time step, one line per integrator, for the
///   stiff preset, with the blow-up threshold and the theoretical limits of the two Euler
///   steps.
///
/// `progress` hears the runs done and their total. Stopped early (`stop`, Ctrl-C on the command
/// line), it writes the runs made so far, the charts' titles saying so and the report marked
/// interrupted; stopped before the first run, it writes nothing.
pub fn run_sway_eval(
    out: &Path,
    stop: &Stop,
    progress: &mut dyn FnMut(u64, u64),
) -> anyhow::Result<SwayEvalReport> {
    let out_dir = crate::tools::fly::OutDir::create_for(
        out,
        "eval sway",
        &crate::tools::fly::Outputs::named(&FILES),
    )?;
    let results = evaluate_until(stop, progress);
    let interrupted =
        results.len() < Preset::ALL.len() * Integrator::ALL.len() * EVAL_STEPS_S.len();
    if results.is_empty() {
        return Ok(SwayEvalReport {
            results,
            stable: Vec::new(),
            interrupted,
        });
    }
    write_csv(&results, &out.join("sway.csv"))?;
    for (preset, file) in [
        (Preset::Stiff, "sway_error.png"),
        (Preset::Soft, "sway_error_soft.png"),
    ] {
        // Only runs that stayed bounded make the Pareto front: a blown-up run's error is a
        // placeholder.
        let mut chart = error_chart(&results, preset);
        chart.title = chart_title(chart.title, interrupted);
        chart.write_png_with_front(&out.join(file), 1100, 750, |p| !p.label.ends_with(BLEW_UP))?;
    }
    let mut chart = stability_chart(&results, Preset::Stiff);
    chart.title = chart_title(chart.title, interrupted);
    chart.write_png(&out.join("sway_stability.png"), 1000, 650)?;
    out_dir.keep();
    let stable = stable_everywhere(&results);
    Ok(SwayEvalReport {
        results,
        stable,
        interrupted,
    })
}

/// What [`run_sway_eval`] measured.
pub struct SwayEvalReport {
    /// One result per preset, integrator and time step ([`evaluate_all`]).
    pub results: Vec<SwayResult>,
    /// The integrators that stayed bounded in every run ([`stable_everywhere`]; of a run
    /// stopped early, in every run made).
    pub stable: Vec<Integrator>,
    /// Whether the eval was stopped before its last run: `results` holds the runs made.
    pub interrupted: bool,
}

impl SwayEvalReport {
    /// Whether the renderer's integrator ([`RENDERER_INTEGRATOR`]) stayed bounded in every run.
    pub fn renderer_bounded(&self) -> bool {
        self.stable.contains(&RENDERER_INTEGRATOR)
    }
}

fn write_csv(results: &[SwayResult], path: &Path) -> anyhow::Result<()> {
    let mut csv = String::from(
        "preset,integrator,dt_s,rms_error,max_error,ns_per_step,stable,blew_up_at_s,max_abs_x\n",
    );
    for r in results {
        let _ = writeln!(
            csv,
            "{},{},{:.6},{:.6e},{:.6e},{:.2},{},{},{:.6e}",
            r.preset,
            r.integrator.name(),
            r.dt_s,
            r.rms_error,
            r.max_error,
            r.ns_per_step,
            r.stable,
            r.blew_up_at_s.map_or(String::new(), |t| format!("{t:.4}")),
            r.max_abs_x
        );
    }
    Ok(crate::tools::fly::write_text(path, &csv)?)
}

/// Ends the chart label of a run that blew up.
const BLEW_UP: &str = " blew up";

fn error_chart(results: &[SwayResult], preset: Preset) -> Chart {
    let spring = preset.spring();
    let rows: Vec<&SwayResult> = results
        .iter()
        .filter(|r| r.preset == preset.name())
        .collect();
    let worst = rows
        .iter()
        .filter(|r| r.stable)
        .map(|r| r.rms_error)
        .fold(0.0f64, f64::max);
    let cap = 10.0 * if worst > 0.0 { worst } else { 1.0 };
    let mut points = Vec::new();
    for integrator in Integrator::ALL {
        let mut above = 0;
        for r in rows.iter().filter(|r| r.integrator == integrator) {
            let label = format!("{} {}", integrator.name(), dt_label(r.dt_s));
            let (label, y) = if r.stable {
                (label, r.rms_error)
            } else {
                above += 1;
                (format!("{label} blew up"), cap * 2f64.powi(above - 1))
            };
            points.push(ChartPoint {
                label,
                x: r.ns_per_step,
                y,
                chosen: integrator == RENDERER_INTEGRATOR,
            });
        }
    }
    Chart {
        title: format!(
            "Sway, {} spring ({:.2} Hz, damping ratio {:.2}): error against cost; blown-up runs drawn from {cap:.2e} up",
            preset.name(),
            spring.natural_frequency_hz(),
            spring.damping_ratio(),
        ),
        x_label: "CPU time per step (ns)".into(),
        y_label: "RMS error of x over 20 s (rad)".into(),
        log_x: false,
        log_y: true,
        points,
    }
}

fn stability_chart(results: &[SwayResult], preset: Preset) -> LineChart {
    let spring = preset.spring();
    let rows: Vec<&SwayResult> = results
        .iter()
        .filter(|r| r.preset == preset.name())
        .collect();
    let amplitude = forcing_amplitude(&spring);
    let mut series: Vec<Series> = Integrator::ALL
        .into_iter()
        .map(|i| Series {
            name: format!("{} Euler", i.name()).replace("exact Euler", "exact"),
            points: rows
                .iter()
                .filter(|r| r.integrator == i)
                .map(|r| (r.dt_s, r.max_abs_x))
                .collect(),
        })
        .collect();
    let (lo, hi) = (EVAL_STEPS_S[0], HITCH_S);
    series.push(Series {
        name: format!("blow-up threshold ({BLOW_UP_FACTOR}x forcing amplitude)"),
        points: vec![
            (lo, BLOW_UP_FACTOR * amplitude),
            (hi, BLOW_UP_FACTOR * amplitude),
        ],
    });
    series.push(Series {
        name: "forcing amplitude (largest |f| / k)".into(),
        points: vec![(lo, amplitude), (hi, amplitude)],
    });
    let top = rows
        .iter()
        .map(|r| r.max_abs_x)
        .filter(|v| v.is_finite())
        .fold(BLOW_UP_FACTOR * amplitude, f64::max);
    for (name, dt) in [
        ("explicit Euler limit c/k", spring.explicit_euler_max_dt()),
        (
            "semi-implicit Euler limit",
            spring.semi_implicit_euler_max_dt(),
        ),
    ] {
        series.push(Series {
            name: format!("{name} ({:.1} ms)", dt * 1e3),
            points: vec![(dt, amplitude / 3.0), (dt, top)],
        });
    }
    LineChart {
        title: format!(
            "Sway, {} spring ({:.2} Hz, damping ratio {:.2}): largest |x| in 20 s of gusts",
            preset.name(),
            spring.natural_frequency_hz(),
            spring.damping_ratio()
        ),
        x_label: "time step (s)".into(),
        y_label: "largest |x| (rad)".into(),
        log_x: true,
        log_y: true,
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_converges() {
        // The reference at 1/4800 s agrees with one at a quarter of that step far below the
        // errors the eval reports.
        let spring = Preset::Stiff.spring();
        let mut r = Reference::new(&spring);
        let (k, c) = (f64::from(spring.stiffness), f64::from(spring.damping));
        let (mut x, mut v) = (r.x, 0.0);
        let h = REFERENCE_DT / 4.0;
        let mut worst = 0.0f64;
        for i in 0..(4.0 / h) as usize {
            let t = i as f64 * h;
            (x, v) = exact_step(k, c, x, v, target_at(&spring, t), h);
            if (i + 1) % 400 == 0 {
                worst = worst.max((x - r.x_at((i + 1) as f64 * h)).abs());
            }
        }
        assert!(worst < 1e-4, "{worst}");
    }

    #[test]
    fn dt_labels() {
        assert_eq!(dt_label(1.0 / 60.0), "1/60");
        assert_eq!(dt_label(1.0 / 144.0), "1/144");
        assert_eq!(dt_label(0.5), "0.5 s");
    }
}
