//! The sway spring: each grass blade bends on a damped spring, one per grass type,
//!
//! ```text
//! x'' = -k x - c x' + f(t)
//! ```
//!
//! where `x` is the blade's sway (its bend angle, radians), `k` the spring's stiffness (1/s^2),
//! `c` its damping (1/s) and `f` the wind's forcing (1/s^2). The wind pushes the blade toward
//! the equilibrium `x_eq = f / k`; the renderer holds that target constant over a frame.
//!
//! Three integrators step the spring by a frame time `dt` ([`Integrator`]): explicit Euler,
//! semi-implicit (symplectic) Euler, and the exact solution of the oscillator over the step with
//! the forcing held constant. `verdant eval sway` ([`run_sway_eval`]) measures each against a
//! fine reference at frame times from 1/240 s to 1/5 s and at a 0.5 s hitch: RMS and largest
//! error, cost per step, and whether the sway blew up. The renderer's choice,
//! [`RENDERER_INTEGRATOR`], is the one that stayed bounded everywhere.

use std::fmt::Write as _;
use std::hint::black_box;
use std::ops::{Add, Div, Mul, Neg, Sub};
use std::path::Path;
use std::time::Instant;

use anyhow::Context;

use crate::metrics::{Chart, ChartPoint, LineChart, Series, Summary};

/// The damped spring a blade sways on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwaySpring {
    /// Spring stiffness `k`, 1/s^2 (the square of the natural angular frequency).
    pub stiffness: f32,
    /// Damping `c`, 1/s (twice the damping ratio times the natural angular frequency).
    pub damping: f32,
}

impl SwaySpring {
    /// Natural frequency of the softest grass (manifest stiffness 0), Hz.
    pub const SOFTEST_HZ: f32 = 0.5;
    /// Natural frequency of the stiffest grass (manifest stiffness 1), Hz.
    pub const STIFFEST_HZ: f32 = 3.0;
    /// Damping ratio of the softest grass.
    pub const SOFTEST_DAMPING_RATIO: f32 = 0.3;
    /// Damping ratio of the stiffest grass.
    pub const STIFFEST_DAMPING_RATIO: f32 = 0.1;

    /// The spring of a grass type from the manifest's `stiffness` (0 bends freely, 1 barely
    /// moves; clamped to 0..=1).
    ///
    /// The natural frequency rises linearly from 0.5 Hz (stiffness 0) to 3 Hz (stiffness 1),
    /// the range measured for grass and cereal stems swaying in wind: tall grass (0.35) sways at
    /// 1.375 Hz, meadow (0.6) at 2 Hz. The damping ratio falls linearly from 0.3 to 0.1: soft,
    /// leafy blades lose more of their motion to the air than stiff stems, which ring longer.
    /// Then `k = w^2` and `c = 2 zeta w` with `w = 2 pi f`: always under-damped.
    pub fn from_grass(stiffness: f32) -> Self {
        let s = if stiffness.is_finite() {
            stiffness.clamp(0.0, 1.0)
        } else {
            0.5
        };
        let hz = Self::SOFTEST_HZ + (Self::STIFFEST_HZ - Self::SOFTEST_HZ) * s;
        let zeta = Self::SOFTEST_DAMPING_RATIO
            + (Self::STIFFEST_DAMPING_RATIO - Self::SOFTEST_DAMPING_RATIO) * s;
        Self::from_frequency(hz, zeta)
    }

    /// The spring of natural frequency `hz` (Hz) and damping ratio `zeta` (1 is critical).
    pub fn from_frequency(hz: f32, zeta: f32) -> Self {
        let w = std::f32::consts::TAU * hz;
        Self {
            stiffness: w * w,
            damping: 2.0 * zeta * w,
        }
    }

    /// Natural angular frequency `w = sqrt(k)`, rad/s.
    pub fn omega(&self) -> f64 {
        f64::from(self.stiffness).sqrt()
    }

    /// Natural frequency, Hz.
    pub fn natural_frequency_hz(&self) -> f64 {
        self.omega() / std::f64::consts::TAU
    }

    /// Damping ratio `c / (2 sqrt(k))`: below 1 under-damped, 1 critical, above 1 over-damped.
    pub fn damping_ratio(&self) -> f64 {
        f64::from(self.damping) / (2.0 * self.omega())
    }

    /// Largest time step at which explicit Euler is stable (strictly below it).
    ///
    /// Explicit Euler multiplies each mode by `1 + dt lambda`, with `lambda` the eigenvalues of
    /// `[[0, 1], [-k, -c]]`: `-c/2 +- sqrt(c^2/4 - k)`. Under-damped, `|1 + dt lambda|^2 =
    /// 1 - c dt + k dt^2`, below 1 exactly when `dt < c / k` (that is `2 zeta / w`: an
    /// undamped spring is never stable). Over-damped, the eigenvalues are real and the bound is
    /// `2 / |lambda|` of the faster one.
    pub fn explicit_euler_max_dt(&self) -> f64 {
        let (k, c) = (f64::from(self.stiffness), f64::from(self.damping));
        let disc = c * c / 4.0 - k;
        if disc < 0.0 {
            c / k
        } else {
            2.0 / (c / 2.0 + disc.sqrt())
        }
    }

    /// Largest time step at which semi-implicit Euler is stable (strictly below it).
    ///
    /// Its step matrix `[[1 - k dt^2, dt (1 - c dt)], [-k dt, 1 - c dt]]` has trace
    /// `2 - c dt - k dt^2` and determinant `1 - c dt`; both eigenvalues lie inside the unit
    /// circle (Jury's conditions) exactly when `k dt^2 + 2 c dt < 4`, that is
    /// `dt < (sqrt(c^2 + 4 k) - c) / k`: `2 / w` without damping, a little less with it.
    pub fn semi_implicit_euler_max_dt(&self) -> f64 {
        let (k, c) = (f64::from(self.stiffness), f64::from(self.damping));
        ((c * c + 4.0 * k).sqrt() - c) / k
    }
}

/// The two springs `verdant eval sway` measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// The stiffest grass the manifest allows (stiffness 1): 3 Hz, damping ratio 0.1.
    Stiff,
    /// Tall grass of the default world (stiffness 0.35): 1.375 Hz, damping ratio 0.23.
    Soft,
}

impl Preset {
    /// Both presets.
    pub const ALL: [Preset; 2] = [Preset::Stiff, Preset::Soft];

    /// Name in tables, charts and the CSV.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Stiff => "stiff",
            Self::Soft => "soft",
        }
    }

    /// The manifest stiffness the preset stands for.
    pub fn grass_stiffness(&self) -> f32 {
        match self {
            Self::Stiff => 1.0,
            Self::Soft => 0.35,
        }
    }

    /// The preset's spring.
    pub fn spring(&self) -> SwaySpring {
        SwaySpring::from_grass(self.grass_stiffness())
    }
}

/// A blade's sway: displacement (bend angle, radians) and its rate (rad/s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SwayState {
    /// Displacement.
    pub x: f32,
    /// Velocity.
    pub v: f32,
}

/// A way to advance the sway spring by one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Integrator {
    /// `x += dt v; v += dt (k (x_eq - x) - c v)`, both from the old state.
    ExplicitEuler,
    /// `v += dt (k (x_eq - x) - c v); x += dt v`, the position from the new velocity.
    SemiImplicitEuler,
    /// The closed-form solution of the damped oscillator over the step with the target held
    /// constant: exact for piecewise-constant forcing and stable at any step.
    Exact,
}

/// The integrator the renderer steps the sway spring with: [`Integrator::Exact`].
///
/// In `verdant eval sway` (see the README) it is the only one of the three that stays bounded
/// at every frame time from 1/240 s to 1/5 s and at a 0.5 s hitch, for both presets: explicit
/// Euler blows up from 1/60 s on the stiff spring (its limit is `dt < c/k` = 10.6 ms) and from
/// 1/10 s on the soft one (limit 53 ms); semi-implicit Euler from 1/10 s on the stiff spring
/// (limit 96 ms) and at 1/5 s on the soft one (limit 184 ms); both blow up at the 0.5 s hitch.
/// Where the Euler steps are stable they are no less accurate (at 1/60 s on the stiff spring
/// the RMS error is 1.7e-3 rad for both exact and semi-implicit Euler: holding the wind over
/// the frame dominates), so what the exact step buys is stability, for about 10 to 13 ns a
/// step on the CPU against 7.5 for semi-implicit and 4 for explicit Euler. Its coefficients
/// depend only on the spring and the frame time, so a shader can compute them once per grass
/// type per frame. At a 0.5 s hitch its error is the wind's lag over the held step (RMS
/// 2.5e-2 rad on the stiff spring), never a blow-up.
pub const RENDERER_INTEGRATOR: Integrator = Integrator::Exact;

/// The arithmetic the exact step needs, for running it in f32 (as the shader does) and in f64
/// (for the reference).
trait Real:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    fn of(v: f64) -> Self;
    fn exp(self) -> Self;
    fn exp_m1(self) -> Self;
    fn cos(self) -> Self;
    fn sin(self) -> Self;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
}

macro_rules! real {
    ($t:ty) => {
        impl Real for $t {
            fn of(v: f64) -> Self {
                v as $t
            }
            fn exp(self) -> Self {
                <$t>::exp(self)
            }
            fn exp_m1(self) -> Self {
                <$t>::exp_m1(self)
            }
            fn cos(self) -> Self {
                <$t>::cos(self)
            }
            fn sin(self) -> Self {
                <$t>::sin(self)
            }
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
        }
    };
}
real!(f32);
real!(f64);

/// The free response of the spring over `t`, as two coefficients `(C, S)`: with `y = x - x_eq`
/// and `a = c / 2`,
///
/// ```text
/// y(t) = C y0 + S (v0 + a y0),    v(t) = C v0 - S (a v0 + k y0)
/// ```
///
/// where `C = e^(-a t) cos(wd t)` and `S = e^(-a t) sin(wd t) / wd` with `wd^2 = k - a^2`
/// (under-damped); `cosh` and `sinh` of `sqrt(a^2 - k) t` over-damped; `C = e^(-a t)` and
/// `S = t e^(-a t)` critically damped. Near critical damping (`|wd^2| t^2 < 0.01`) the series of
/// `cos(sqrt(q))` and `sin(sqrt(q)) / sqrt(q)` in `q = wd^2 t^2` covers all three cases without
/// cancellation.
fn free_response<R: Real>(k: R, c: R, t: R) -> (R, R) {
    let one = R::of(1.0);
    let a = R::of(0.5) * c;
    let d = k - a * a;
    let q = d * t * t;
    if q.abs() < R::of(1e-2) {
        let e = (-(a * t)).exp();
        let cos = one - q * (R::of(0.5) - q * (R::of(1.0 / 24.0) - q * R::of(1.0 / 720.0)));
        let sinc =
            one - q * (R::of(1.0 / 6.0) - q * (R::of(1.0 / 120.0) - q * R::of(1.0 / 5040.0)));
        (e * cos, e * t * sinc)
    } else if d > R::of(0.0) {
        let wd = d.sqrt();
        let e = (-(a * t)).exp();
        (e * (wd * t).cos(), e * (wd * t).sin() / wd)
    } else {
        // e^(-a t) cosh(b t) and e^(-a t) sinh(b t) / b through the slow mode e^(-(a - b) t)
        // (a - b = k / (a + b), without cancellation) and expm1, which stay accurate however
        // over-damped the spring.
        let b = (-d).sqrt();
        let slow = (-(k / (a + b) * t)).exp();
        let m = (-(R::of(2.0) * b * t)).exp_m1();
        (
            slow * (R::of(2.0) + m) * R::of(0.5),
            -(slow * m) / (R::of(2.0) * b),
        )
    }
}

/// One exact step of the spring toward the held `target`.
fn exact_step<R: Real>(k: R, c: R, x: R, v: R, target: R, dt: R) -> (R, R) {
    let (cc, s) = free_response(k, c, dt);
    let a = R::of(0.5) * c;
    let y = x - target;
    (
        target + cc * y + s * (v + a * y),
        cc * v - s * (a * v + k * y),
    )
}

impl Integrator {
    /// All three, cheapest first.
    pub const ALL: [Integrator; 3] = [
        Integrator::ExplicitEuler,
        Integrator::SemiImplicitEuler,
        Integrator::Exact,
    ];

    /// Short name for tables, charts and the CSV.
    pub fn name(&self) -> &'static str {
        match self {
            Self::ExplicitEuler => "explicit",
            Self::SemiImplicitEuler => "semi-implicit",
            Self::Exact => "exact",
        }
    }

    /// Advances `state` by `dt` seconds on `spring`, the wind pushing toward the equilibrium
    /// `target` (`f / k`) all through the step.
    pub fn step(&self, spring: &SwaySpring, state: SwayState, target: f32, dt: f32) -> SwayState {
        let (k, c) = (spring.stiffness, spring.damping);
        let SwayState { x, v } = state;
        match self {
            Self::ExplicitEuler => SwayState {
                x: x + dt * v,
                v: v + dt * (k * (target - x) - c * v),
            },
            Self::SemiImplicitEuler => {
                let v = v + dt * (k * (target - x) - c * v);
                SwayState { x: x + dt * v, v }
            }
            Self::Exact => {
                let (x, v) = exact_step(k, c, x, v, target, dt);
                SwayState { x, v }
            }
        }
    }

    /// The matrix the step applies to the deviation `(x - x_eq, v)` from a constant target.
    pub fn amplification(&self, spring: &SwaySpring, dt: f64) -> [[f64; 2]; 2] {
        let (k, c, h) = (f64::from(spring.stiffness), f64::from(spring.damping), dt);
        match self {
            Self::ExplicitEuler => [[1.0, h], [-k * h, 1.0 - c * h]],
            Self::SemiImplicitEuler => {
                [[1.0 - k * h * h, h * (1.0 - c * h)], [-k * h, 1.0 - c * h]]
            }
            Self::Exact => {
                let (cc, s) = free_response(k, c, h);
                let a = c / 2.0;
                [[cc + a * s, s], [-k * s, cc - a * s]]
            }
        }
    }

    /// Spectral radius of [`Self::amplification`]: the step is stable when it is below 1.
    pub fn spectral_radius(&self, spring: &SwaySpring, dt: f64) -> f64 {
        let m = self.amplification(spring, dt);
        let tr = m[0][0] + m[1][1];
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        let disc = tr * tr / 4.0 - det;
        if disc >= 0.0 {
            let r = disc.sqrt();
            (tr / 2.0 + r).abs().max((tr / 2.0 - r).abs())
        } else {
            det.sqrt()
        }
    }
}

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
            Some((n, hitch)) if n > 0 && i % n == 0 => hitch,
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
            // An unstable run starts again, so that it is timed on ordinary numbers.
            if !(s.x.abs() <= limit) {
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
    let mut out = Vec::new();
    for preset in Preset::ALL {
        for integrator in Integrator::ALL {
            for dt in EVAL_STEPS_S {
                out.push(evaluate(preset, integrator, dt));
            }
        }
    }
    out
}

/// The integrators that stayed bounded in every run of `results`.
pub fn stable_everywhere(results: &[SwayResult]) -> Vec<Integrator> {
    Integrator::ALL
        .into_iter()
        .filter(|i| {
            results
                .iter()
                .filter(|r| r.integrator == *i)
                .all(|r| r.stable)
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
pub fn run_sway_eval(out: &Path) -> anyhow::Result<Vec<SwayResult>> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let results = evaluate_all();
    write_csv(&results, &out.join("sway.csv"))?;
    for (preset, file) in [
        (Preset::Stiff, "sway_error.png"),
        (Preset::Soft, "sway_error_soft.png"),
    ] {
        // Only runs that stayed bounded make the Pareto front: a blown-up run's error is a
        // placeholder.
        error_chart(&results, preset)
            .write_png_with_front(&out.join(file), 1100, 750, |p| !p.label.ends_with(BLEW_UP))?;
    }
    stability_chart(&results, Preset::Stiff).write_png(
        &out.join("sway_stability.png"),
        1000,
        650,
    )?;
    Ok(results)
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
    std::fs::write(path, csv).with_context(|| format!("cannot write {}", path.display()))
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
            "Sway, {} spring ({:.2} Hz, damping ratio {:.2}): error against cost; blown-up runs above {cap:.0e}",
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

    /// The free oscillation `x'' = -k x - c x'` from `(x0, v0)`, evaluated at `t` in f64,
    /// from the roots of `r^2 + c r + k = 0` (written independently of [`free_response`]).
    fn analytic(k: f64, c: f64, x0: f64, v0: f64, t: f64) -> f64 {
        let disc = c * c - 4.0 * k;
        if disc > 0.0 {
            let (r1, r2) = ((-c + disc.sqrt()) / 2.0, (-c - disc.sqrt()) / 2.0);
            let b = (v0 - r1 * x0) / (r2 - r1);
            let a = x0 - b;
            a * (r1 * t).exp() + b * (r2 * t).exp()
        } else if disc == 0.0 {
            let r = -c / 2.0;
            (x0 + (v0 - r * x0) * t) * (r * t).exp()
        } else {
            // Amplitude and phase of the damped cosine.
            let (alpha, wd) = (c / 2.0, (-disc).sqrt() / 2.0);
            let b = (v0 + alpha * x0) / wd;
            let amp = (x0 * x0 + b * b).sqrt();
            let phase = b.atan2(x0);
            amp * (-alpha * t).exp() * (wd * t - phase).cos()
        }
    }

    fn springs() -> Vec<(&'static str, SwaySpring)> {
        let w = 2.0f32 * std::f32::consts::PI * 1.5;
        vec![
            ("under-damped", SwaySpring::from_grass(0.35)),
            ("lightly damped", SwaySpring::from_frequency(3.0, 0.02)),
            (
                "critically damped",
                SwaySpring {
                    stiffness: 64.0,
                    damping: 16.0,
                },
            ),
            ("over-damped", SwaySpring::from_frequency(1.5, 2.5)),
            ("very over-damped", SwaySpring::from_frequency(0.5, 40.0)),
            (
                "barely under-damped",
                SwaySpring {
                    stiffness: w * w,
                    damping: 2.0 * w * 0.9999,
                },
            ),
        ]
    }

    #[test]
    fn exact_matches_the_free_oscillation() {
        for (name, spring) in springs() {
            let (k, c) = (f64::from(spring.stiffness), f64::from(spring.damping));
            for dt in [1.0 / 240.0, 1.0 / 60.0, 1.0 / 10.0, 0.5, 2.0] {
                for (x0, v0) in [(0.3f32, 0.0f32), (0.0, 2.0), (-0.2, 1.5)] {
                    let scale = f64::from(x0.abs()).max(f64::from(v0.abs()) / spring.omega());
                    // One step.
                    let s =
                        Integrator::Exact.step(&spring, SwayState { x: x0, v: v0 }, 0.0, dt as f32);
                    let want = analytic(k, c, f64::from(x0), f64::from(v0), f64::from(dt as f32));
                    let err = (f64::from(s.x) - want).abs();
                    assert!(
                        err <= 4.0 * f64::from(f32::EPSILON) * scale,
                        "{name} dt {dt} from ({x0}, {v0}): {} against {want} (error {err:e})",
                        s.x
                    );
                    // Forty steps: the error grows no faster than an ulp or so a step.
                    let mut s = SwayState { x: x0, v: v0 };
                    for _ in 0..40 {
                        s = Integrator::Exact.step(&spring, s, 0.0, dt as f32);
                    }
                    let want = analytic(
                        k,
                        c,
                        f64::from(x0),
                        f64::from(v0),
                        40.0 * f64::from(dt as f32),
                    );
                    let err = (f64::from(s.x) - want).abs();
                    assert!(
                        err <= 40.0 * f64::from(f32::EPSILON) * scale,
                        "{name} dt {dt}, 40 steps from ({x0}, {v0}): {} against {want} \
                         (error {err:e})",
                        s.x
                    );
                }
            }
        }
    }

    #[test]
    fn exact_settles_on_the_target_and_is_unconditionally_stable() {
        for (name, spring) in springs() {
            for dt in [1e-4, 1.0 / 60.0, 0.5, 10.0] {
                let rho = Integrator::Exact.spectral_radius(&spring, dt);
                assert!(rho < 1.0, "{name} dt {dt}: spectral radius {rho}");
            }
            let mut s = SwayState::default();
            for _ in 0..2000 {
                s = Integrator::Exact.step(&spring, s, 0.25, 0.5);
            }
            assert!(
                (s.x - 0.25).abs() < 1e-5 && s.v.abs() < 1e-4,
                "{name}: {s:?}"
            );
        }
    }

    #[test]
    fn closed_form_limits_agree_with_the_spectral_radius() {
        for (name, spring) in springs() {
            for (integrator, limit) in [
                (Integrator::ExplicitEuler, spring.explicit_euler_max_dt()),
                (
                    Integrator::SemiImplicitEuler,
                    spring.semi_implicit_euler_max_dt(),
                ),
            ] {
                let below = integrator.spectral_radius(&spring, limit * 0.999);
                let above = integrator.spectral_radius(&spring, limit * 1.001);
                assert!(
                    below < 1.0 && above > 1.0,
                    "{name} {integrator:?}: limit {limit}, radius {below} below, {above} above"
                );
            }
        }
    }

    #[test]
    fn grass_stiffness_maps_to_sensible_springs() {
        for s in [0.0, 0.35, 0.5, 0.6, 1.0] {
            let spring = SwaySpring::from_grass(s);
            let (hz, zeta) = (spring.natural_frequency_hz(), spring.damping_ratio());
            assert!((0.5 - 1e-4..=3.0 + 1e-4).contains(&hz), "{s}: {hz} Hz");
            assert!(
                (0.1 - 1e-4..=0.3 + 1e-4).contains(&zeta),
                "{s}: zeta {zeta}"
            );
        }
        let tall = SwaySpring::from_grass(0.35);
        assert!((tall.natural_frequency_hz() - 1.375).abs() < 1e-4);
        assert!((SwaySpring::from_grass(0.6).natural_frequency_hz() - 2.0).abs() < 1e-4);
        assert!(
            SwaySpring::from_grass(0.6).stiffness > tall.stiffness,
            "stiffer grass, stiffer spring"
        );
        assert_eq!(SwaySpring::from_grass(7.0), SwaySpring::from_grass(1.0));
    }

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
