//! Wind: the wind field around the camera and the grass's sway springs in it.
//!
//! Each GPU stage is one file, its CPU mirror beside it (`_cpu`), its shader named after the
//! module and the stage (`shaders/wind_<stage>.wgsl`).
//! - [`spring`]: the damped spring each grass blade sways on and the exact step the renderer
//!   advances it with ([`RENDERER_INTEGRATOR`]; chosen by `verdant eval sway`, which measures
//!   its error, cost and stability against the Euler steps).
//! - [`config`]: a wind scene of the manifest made ready to run ([`WindConfig`]) and each
//!   frame's uniforms ([`FieldDriver`], [`FieldParams`], [`WindLookup`]).
//! - [`field`]: the wind field on the GPU ([`WindField`], `shaders/wind_field.wgsl`): ambient
//!   noise that never repeats, sources (directional, omni, vortex), decay toward the ambient
//!   wind and the walker's trail, in a toroidal grid of cells that follows the camera; how
//!   another shader reads it (`shaders/shared/wind_lookup.wgsl`).
//! - [`field_cpu`]: its CPU mirror ([`WindFieldCpu`], [`ambient_at`]).
//! - [`sway`]: the springs advanced on the GPU ([`SwayField`], `shaders/wind_sway.wgsl`), per
//!   cell of the field and grass type.
//! - [`sway_cpu`]: its CPU mirror ([`update_sway`]).

pub mod config;
pub mod field;
pub mod field_cpu;
pub mod spring;
pub mod sway;
pub mod sway_cpu;

pub use config::{
    AmbientWind, CellState, FieldDriver, FieldParams, SceneAt, SceneChange, SourceConfig,
    SourceGpu, WindConfig, WindError, WindLookup,
};
pub use field::WindField;
pub use field_cpu::{WindFieldCpu, ambient_at};
pub use spring::{ExactStep, RENDERER_INTEGRATOR, SwaySpring, SwayState};
pub use sway::{
    GRASS_SWAY_TYPES, PLANT_SWAY_TYPES, SWAY_TYPES, SwayConfig, SwayField, SwayParams,
    plant_lean_gain,
};
pub use sway_cpu::{sway_at, sway_state_at, update_sway};
