//! Writes the far-card picture of each plant recipe as PNG, and a contact sheet of the three side
//! by side (each stretched back to its card's proportions, over a sky-grey background), with the
//! reduced level of detail drawn the same way in a second row.
//!
//! ```sh
//! cargo run --example plant_cards -- out/plants [SEED]
//! ```

use std::path::{Path, PathBuf};

use image::{Rgba, RgbaImage, imageops};
use verdant::plants::{PlantImage, Recipe, generate, render_card};

/// Each recipe's accent colour (linear RGB): a pink flower, green fern and bush leaves.
fn accent(recipe: Recipe) -> [f32; 3] {
    match recipe {
        Recipe::Flower => [0.8, 0.12, 0.3],
        Recipe::Fern => [0.1, 0.32, 0.05],
        Recipe::Bush => [0.08, 0.24, 0.04],
        Recipe::Broadleaf => [0.09, 0.22, 0.04],
        Recipe::Conifer => [0.04, 0.13, 0.05],
    }
}

/// Height of each plant on the contact sheet, pixels.
const SHEET_HEIGHT: u32 = 256;

fn main() {
    if let Err(e) = run() {
        eprintln!("plant_cards: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().ok_or("usage: plant_cards OUT_FOLDER [SEED]")?);
    let seed = match args.next() {
        Some(s) => s
            .parse::<u32>()
            .map_err(|e| format!("SEED {s:?}: {e} (must be in 0..=4294967295)"))?,
        None => 1,
    };
    std::fs::create_dir_all(&dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;

    let mut tiles = Vec::new();
    for recipe in Recipe::ALL {
        let plant = generate(recipe, seed, accent(recipe));
        let picture = to_image(&plant.card_image)?;
        save(&picture, &dir.join(format!("{}.png", recipe.name())))?;
        let m = &plant.lods[0];
        println!(
            "{}: {} / {} triangles, {:.2} m high, {:.2} m wide",
            recipe.name(),
            m.triangles(),
            plant.lods[1].triangles(),
            m.height(),
            2.0 * m.radius()
        );
        let width = (SHEET_HEIGHT as f32 * 2.0 * m.radius() / m.height())
            .round()
            .max(1.0) as u32;
        let reduced = to_image(&render_card(&plant.lods[1], plant.card_image.width))?;
        for (row, picture) in [&picture, &reduced].into_iter().enumerate() {
            let tile =
                imageops::resize(picture, width, SHEET_HEIGHT, imageops::FilterType::Triangle);
            tiles.push((row as u32, tile));
        }
    }

    let gap = 16;
    let width = tiles
        .iter()
        .filter(|t| t.0 == 0)
        .map(|t| t.1.width() + gap)
        .sum::<u32>()
        + gap;
    let height = 2 * (SHEET_HEIGHT + gap) + gap;
    let mut sheet = RgbaImage::from_pixel(width, height, Rgba([196, 208, 220, 255]));
    let mut x = gap;
    for (row, tile) in &tiles {
        let y = gap + row * (SHEET_HEIGHT + gap);
        imageops::overlay(&mut sheet, tile, x as i64, y as i64);
        if *row == 1 {
            x += tile.width() + gap;
        }
    }
    save(&sheet, &dir.join("plants.png"))
}

fn to_image(p: &PlantImage) -> Result<RgbaImage, String> {
    RgbaImage::from_raw(p.width, p.height, p.rgba.clone())
        .ok_or_else(|| "card picture of the wrong length".to_string())
}

fn save(img: &RgbaImage, path: &Path) -> Result<(), String> {
    img.save(path)
        .map_err(|e| format!("writing {}: {e}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}
