//! Wind: the grass sway spring and the wind field around the camera.
//!
//! - [`sway`]: the damped spring each grass blade sways on and the exact step the renderer
//!   advances it with ([`RENDERER_INTEGRATOR`]; chosen by `verdant eval sway`, which measures
//!   its error, cost and stability against the Euler steps).
//! - [`config`]: a wind scene of the manifest made ready to run ([`WindConfig`]) and each
//!   frame's uniforms ([`FieldDriver`], [`FieldParams`], [`WindLookup`]).
//! - [`field`]: the wind field on the GPU ([`WindField`], `shaders/wind_field.wgsl`): ambient
//!   noise that never repeats, sources (directional, omni, vortex), decay toward the ambient
//!   wind and the walker's trail, in a toroidal grid of cells that follows the camera; how
//!   another shader reads it (`shaders/wind_lookup.wgsl`).
//! - [`field_cpu`]: its CPU mirror ([`WindFieldCpu`], [`ambient_at`]).

pub mod config;
pub mod field;
pub mod field_cpu;
pub mod sway;
pub mod sway_field;

pub use config::{
    AmbientWind, CellState, FieldDriver, FieldParams, SceneAt, SceneChange, SourceConfig,
    SourceGpu, WindConfig, WindError, WindLookup,
};
pub use field::WindField;
pub use field_cpu::{WindFieldCpu, ambient_at};
pub use sway::{ExactStep, RENDERER_INTEGRATOR, SwaySpring, SwayState};
pub use sway_field::{SWAY_TYPES, SwayConfig, SwayField, SwayParams, update_sway};
