//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use verdant::gpu::GpuContext;
use verdant::metrics::flip_compare;

/// The repository's root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The default world's folder.
pub fn default_world() -> PathBuf {
    root().join("worlds").join("santa-cruz")
}

/// Opens the GPU. A machine with no adapter fails the test: GPU tests never skip.
pub fn gpu() -> GpuContext {
    match GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => panic!("GPU tests need an adapter: {e}"),
    }
}

/// Where failing image tests leave their actual and difference images.
pub fn failure_dir() -> PathBuf {
    root().join("target").join("test-images")
}

/// Compares `actual` with `tests/reference/NAME.png` by FLIP. Fails when the mean error exceeds
/// `max_mean` or the 99th percentile exceeds `max_p99`, and then writes `NAME-actual.png` and
/// `NAME-difference.png` under `target/test-images`. A missing reference fails too, unless
/// `VERDANT_UPDATE_REFERENCES=1` asks for the reference to be (re)written; review a new
/// reference image before committing it.
pub fn check_reference(name: &str, actual: &image::RgbaImage, max_mean: f32, max_p99: f32) {
    let reference_path = root().join("tests").join("reference").join(format!("{name}.png"));
    let actual_rgb = image::DynamicImage::ImageRgba8(actual.clone()).to_rgb8();
    if std::env::var("VERDANT_UPDATE_REFERENCES").as_deref() == Ok("1") {
        actual_rgb.save(&reference_path).expect("write reference image");
        eprintln!("wrote reference {}", reference_path.display());
        return;
    }
    let dir = failure_dir();
    let write_failure = |diff: Option<&[u8]>| {
        std::fs::create_dir_all(&dir).expect("create failure image folder");
        let actual_file = dir.join(format!("{name}-actual.png"));
        actual_rgb.save(&actual_file).expect("write actual image");
        if let Some(diff) = diff {
            let (w, h) = actual_rgb.dimensions();
            let img = image::RgbImage::from_raw(w, h, diff.to_vec()).expect("difference size");
            img.save(dir.join(format!("{name}-difference.png"))).expect("write difference");
        }
        actual_file
    };
    let reference = match image::open(&reference_path) {
        Ok(img) => img.to_rgb8(),
        Err(e) => {
            let file = write_failure(None);
            panic!(
                "missing or unreadable reference {} ({e}); the actual image is {}. \
                 Run with VERDANT_UPDATE_REFERENCES=1 to create it, then review it.",
                reference_path.display(),
                file.display()
            );
        }
    };
    let result = match flip_compare(&reference, &actual_rgb) {
        Ok(r) => r,
        Err(e) => {
            let file = write_failure(None);
            panic!("{name}: {e}; actual image at {}", file.display());
        }
    };
    eprintln!("{name}: FLIP mean {:.4}, p99 {:.4}, max {:.4}", result.mean, result.p99, result.max);
    if result.mean > max_mean || result.p99 > max_p99 {
        let file = write_failure(Some(&result.difference_rgb));
        panic!(
            "{name}: FLIP mean {:.4} (limit {max_mean}), p99 {:.4} (limit {max_p99}); \
             actual and difference images beside {}",
            result.mean,
            result.p99,
            file.display()
        );
    }
}

/// Copies a folder tree (for tests that damage a copy of a world).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}
