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
//! The renderer steps the spring by a frame time `dt` with the exact solution of the oscillator
//! over the step, the forcing held constant ([`ExactStep`], [`RENDERER_INTEGRATOR`]).
//! `verdant eval sway` (`tools::eval_sway`, with the Euler steps it compares in
//! `tools::sway_integrators`) measures it against a fine reference at frame times from 1/240 s
//! to 1/5 s and at a 0.5 s hitch: it is the one step that stayed bounded everywhere.

use std::ops::{Add, Div, Mul, Neg, Sub};

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
}

/// A blade's sway: displacement (bend angle, radians) and its rate (rad/s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SwayState {
    /// Displacement.
    pub x: f32,
    /// Velocity.
    pub v: f32,
}

/// The step the renderer advances the sway spring with: the closed-form solution of the damped
/// oscillator over the frame with the target held constant, exact for piecewise-constant
/// forcing and stable at any step.
///
/// In `verdant eval sway` (see the README) it is the only one of three steps that stays bounded
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExactStep;

/// The renderer's step of the sway spring (see [`ExactStep`]).
pub const RENDERER_INTEGRATOR: ExactStep = ExactStep;

/// The arithmetic the exact step needs, for running it in f32 (as the shader does) and in f64
/// (for the reference).
pub(crate) trait Real:
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
pub(crate) fn exact_step<R: Real>(k: R, c: R, x: R, v: R, target: R, dt: R) -> (R, R) {
    let (cc, s) = free_response(k, c, dt);
    let a = R::of(0.5) * c;
    let y = x - target;
    (
        target + cc * y + s * (v + a * y),
        cc * v - s * (a * v + k * y),
    )
}

impl ExactStep {
    /// Short name for tables, charts and the CSV.
    pub fn name(&self) -> &'static str {
        "exact"
    }

    /// Advances `state` by `dt` seconds on `spring`, the wind pushing toward the equilibrium
    /// `target` (`f / k`) all through the step.
    pub fn step(&self, spring: &SwaySpring, state: SwayState, target: f32, dt: f32) -> SwayState {
        let (x, v) = exact_step(
            spring.stiffness,
            spring.damping,
            state.x,
            state.v,
            target,
            dt,
        );
        SwayState { x, v }
    }

    /// The matrix the step applies to the deviation `(x - x_eq, v)` from a constant target.
    pub fn amplification(&self, spring: &SwaySpring, dt: f64) -> [[f64; 2]; 2] {
        let (k, c) = (f64::from(spring.stiffness), f64::from(spring.damping));
        let (cc, s) = free_response(k, c, dt);
        let a = c / 2.0;
        [[cc + a * s, s], [-k * s, cc - a * s]]
    }
}

/// Spectral radius of a step's amplification matrix: the step is stable when it is below 1.
pub fn spectral_radius(m: [[f64; 2]; 2]) -> f64 {
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

#[cfg(test)]
pub(crate) mod tests {
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

    /// Springs over the whole range of damping, for the tests of the steps.
    pub(crate) fn springs() -> Vec<(&'static str, SwaySpring)> {
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
                    let s = ExactStep.step(&spring, SwayState { x: x0, v: v0 }, 0.0, dt as f32);
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
                        s = ExactStep.step(&spring, s, 0.0, dt as f32);
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
                let rho = spectral_radius(ExactStep.amplification(&spring, dt));
                assert!(rho < 1.0, "{name} dt {dt}: spectral radius {rho}");
            }
            let mut s = SwayState::default();
            for _ in 0..2000 {
                s = ExactStep.step(&spring, s, 0.25, 0.5);
            }
            assert!(
                (s.x - 0.25).abs() < 1e-5 && s.v.abs() < 1e-4,
                "{name}: {s:?}"
            );
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
}
