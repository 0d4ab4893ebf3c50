//! verdant: a streaming open-world terrain service with GPU grass.

pub mod world;
