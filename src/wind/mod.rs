//! Wind: the sway spring and its integrators (the wind field follows).
//!
//! - [`sway`]: the damped spring each grass blade sways on, three ways to step it
//!   ([`Integrator`]), the one the renderer uses ([`RENDERER_INTEGRATOR`]), and
//!   `verdant eval sway`, which measures their error, cost and stability at frame times from
//!   1/240 s to 1/5 s and at 0.5 s hitches.

pub mod sway;

pub use sway::{
    Integrator, Preset, RENDERER_INTEGRATOR, SwayResult, SwaySpring, SwayState, bounded_for,
    run_sway_eval,
};
