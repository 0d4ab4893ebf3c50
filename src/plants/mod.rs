//! Plants beyond grass: flowers, ferns and bushes, placed per grass tile on the GPU and bent by
//! the same wind as the blades.
//!
//! - [`mesh`]: the vertex record every plant mesh uses.
//! - [`recipe`]: the procedural flowers, ferns and bushes, at two levels of detail.
//! - [`card`]: their far level, crossed cards with a picture rendered from the mesh.

pub mod card;
pub mod mesh;
pub mod recipe;

pub use card::{crossed_cards, render_card};
pub use mesh::{PlantImage, PlantMesh, PlantVertex};
pub use recipe::{PlantLods, Recipe, generate};
