//! Writes a copy of the default world with two tree types added, oaks and firs in the tall and
//! the dry grass (the README's "Trees" example), for looking at and measuring the trees' layer:
//!
//! ```sh
//! cargo run --release --example forest_world -- out/forest
//! verdant fly out/forest --path tour --frames 6 --size 1920x1080
//! ```
//!
//! The world's tiles are copied as they are; only `world.toml` gains the `[[plant_types]]` of
//! the trees, after the world's own plants.

use std::path::{Path, PathBuf};

/// The trees, as the README shows them.
const TREES: &str = r#"[[plant_types]]
name = "oak"
mesh = "broadleaf"
color = [0.08, 0.2, 0.035]
size_m = [7.0, 13.0]
density = { "tall grass" = 0.02, "dry grass" = 0.008, meadow = 0.0005 }
max_slope_deg = 40.0
clump_m = 60.0
clump_cover = 0.5
seed = 11
wind = { bend = 0.004, stiffness = 0.8, sway_spring_hz = 0.35, sway_damping = 0.3, detail_amplitude = 0.12 }

[[plant_types]]
name = "fir"
mesh = "conifer"
color = [0.035, 0.11, 0.04]
size_m = [12.0, 26.0]
density = { "tall grass" = 0.012, "dry grass" = 0.004 }
max_slope_deg = 45.0
clump_m = 80.0
clump_cover = 0.45
seed = 12
wind = { bend = 0.003, stiffness = 0.85, sway_spring_hz = 0.3, sway_damping = 0.3, detail_amplitude = 0.1 }

"#;

fn copy_dir(from: &Path, to: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(to)?;
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        if entry.file_type()?.is_dir() {
            copy_dir(&entry.path(), &target)?;
        } else {
            std::fs::copy(entry.path(), &target)?;
        }
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    use anyhow::Context;
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .context("usage: forest_world OUT (a folder to write the world into)")?,
    );
    if out.exists() {
        anyhow::bail!("{} exists already: give a new folder", out.display());
    }
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
    copy_dir(&source, &out).with_context(|| format!("copying the world to {}", out.display()))?;
    let manifest_path = out.join("world.toml");
    let manifest = std::fs::read_to_string(&manifest_path)?;
    let at = manifest
        .find("[wind]")
        .context("the default world's manifest has a [wind] table")?;
    let edited = format!("{}{TREES}{}", &manifest[..at], &manifest[at..]);
    std::fs::write(&manifest_path, edited)?;
    // The world opens, and the two types are trees.
    let world = verdant::world::World::open(&out)?;
    let trees = world
        .manifest
        .plant_types
        .iter()
        .filter(|t| t.is_tree())
        .count();
    anyhow::ensure!(trees == 2, "expected two tree types, found {trees}");
    println!(
        "wrote {} ({} plant types, {trees} of them trees)",
        out.display(),
        world.manifest.plant_types.len()
    );
    Ok(())
}
