//! The sway spring's steps that `verdant eval sway` compares: explicit and semi-implicit Euler
//! beside the renderer's exact step ([`crate::wind::spring::ExactStep`]), their stability limits,
//! and the two springs the eval measures them on.

use crate::wind::spring::{ExactStep, SwaySpring, SwayState, spectral_radius};

/// The stability limits of the Euler steps on a spring.
pub trait EulerLimits {
    /// Largest time step at which explicit Euler is stable (strictly below it).
    ///
    /// Explicit Euler multiplies each mode by `1 + dt lambda`, with `lambda` the eigenvalues of
    /// `[[0, 1], [-k, -c]]`: `-c/2 +- sqrt(c^2/4 - k)`. Under-damped, `|1 + dt lambda|^2 =
    /// 1 - c dt + k dt^2`, below 1 exactly when `dt < c / k` (that is `2 zeta / w`: an
    /// undamped spring is never stable). Over-damped, the eigenvalues are real and the bound is
    /// `2 / |lambda|` of the faster one.
    fn explicit_euler_max_dt(&self) -> f64;

    /// Largest time step at which semi-implicit Euler is stable (strictly below it).
    ///
    /// Its step matrix `[[1 - k dt^2, dt (1 - c dt)], [-k dt, 1 - c dt]]` has trace
    /// `2 - c dt - k dt^2` and determinant `1 - c dt`; both eigenvalues lie inside the unit
    /// circle (Jury's conditions) exactly when `k dt^2 + 2 c dt < 4`, that is
    /// `dt < (sqrt(c^2 + 4 k) - c) / k`: `2 / w` without damping, a little less with it.
    fn semi_implicit_euler_max_dt(&self) -> f64;
}

impl EulerLimits for SwaySpring {
    fn explicit_euler_max_dt(&self) -> f64 {
        let (k, c) = (f64::from(self.stiffness), f64::from(self.damping));
        let disc = c * c / 4.0 - k;
        if disc < 0.0 {
            c / k
        } else {
            2.0 / (c / 2.0 + disc.sqrt())
        }
    }

    fn semi_implicit_euler_max_dt(&self) -> f64 {
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
/// The renderer's step among the [`Integrator`]s: [`Integrator::Exact`], as
/// [`crate::wind::spring::RENDERER_INTEGRATOR`] (why: see there).
pub const RENDERER_INTEGRATOR: Integrator = Integrator::Exact;

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
            Self::Exact => ExactStep.step(spring, state, target, dt),
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
            Self::Exact => ExactStep.amplification(spring, dt),
        }
    }

    /// Spectral radius of [`Self::amplification`]: the step is stable when it is below 1.
    pub fn spectral_radius(&self, spring: &SwaySpring, dt: f64) -> f64 {
        spectral_radius(self.amplification(spring, dt))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_limits_agree_with_the_spectral_radius() {
        for (name, spring) in crate::wind::spring::tests::springs() {
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
}
