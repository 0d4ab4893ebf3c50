//! Where a render's error against the truth lies by scale, from images already written (the
//! truth and the renders of `aa_error_by_distance`, or the last frames of `bench aa`).
//!
//! `cargo run --release --example error_by_scale -- TRUTH.png RENDER.png [RENDER.png ...]`
//!
//! For each render: its pixel FLIP and coarse FLIP against the truth; the pixel FLIP left when
//! its mean colour in every block of B x B pixels is the truth's (B = 2, 4, 8, 16, 32, 64; in
//! linear light, its own detail within the blocks kept), so that the fall from its own FLIP is
//! the part of the error at B pixels and coarser; and its pixel FLIP with random detail of the
//! truth's spread in blocks of 8 added (`+spread8`, the mean of three draws), and the same on
//! the render given the truth's block means first (`means8+spread8`): what a texture of the
//! truth's statistics, drawn elsewhere than the truth's blades, does to the error.
use anyhow::{Context, Result};
use verdant::tools::metrics::{flip_compare, with_block_means_of, with_block_spread_of};

const BLOCKS: [u32; 6] = [2, 4, 8, 16, 32, 64];

fn load(path: &str) -> Result<image::RgbImage> {
    Ok(image::open(path)
        .with_context(|| format!("reading {path}"))?
        .to_rgb8())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(
        args.len() >= 2,
        "usage: error_by_scale TRUTH.png RENDER.png [RENDER.png ...]"
    );
    let truth = load(&args[0])?;
    let flip =
        |img: &image::RgbImage| -> Result<f64> { Ok(f64::from(flip_compare(&truth, img)?.mean)) };
    print!("{:<32} {:>7} {:>7}", "render", "FLIP", "coarse");
    for b in BLOCKS {
        print!(" {:>7}", format!("means{b}"));
    }
    println!(" {:>9} {:>15}", "+spread8", "means8+spread8");
    for path in &args[1..] {
        let img = load(path)?;
        let name = std::path::Path::new(path)
            .file_stem()
            .map_or(path.clone(), |s| s.to_string_lossy().into_owned());
        print!(
            "{name:<32} {:>7.4} {:>7.4}",
            flip(&img)?,
            verdant::tools::metrics::coarse_flip(
                &truth,
                &img,
                verdant::tools::metrics::COARSE_FACTOR
            )?
        );
        let mut means8 = None;
        for b in BLOCKS {
            let means = with_block_means_of(&img, &truth, b)?;
            print!(" {:>7.4}", flip(&means)?);
            if b == 8 {
                means8 = Some(means);
            }
        }
        let means8 = means8.expect("BLOCKS holds 8");
        let mut spread = [0.0; 2];
        for seed in 1..=3 {
            spread[0] += flip(&with_block_spread_of(&img, &truth, 8, seed)?)? / 3.0;
            spread[1] += flip(&with_block_spread_of(&means8, &truth, 8, seed)?)? / 3.0;
        }
        println!(" {:>9.4} {:>15.4}", spread[0], spread[1]);
    }
    Ok(())
}
