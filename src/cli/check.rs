//! `verdant check`: its options and what it prints.

use anyhow::{Result, bail};

use verdant::tools::check::{
    CheckOptions, FailedTile, MAX_CHECK_THREADS, check_world, stamp_world,
};

use super::args::{HttpArgs, resolve_world};
use super::out::{note, say};
use super::progress::TenthsBar;
use super::{Interrupted, terminal_safe};

/// The options of `verdant check`.
#[derive(clap::Args)]
pub(crate) struct CheckArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address
    /// (default: santa-cruz); with --stamp, a world folder's path, given.
    pub(crate) world: Option<std::ffi::OsString>,
    /// Tiles read at once, 1..=64 (several hide a server's latency).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=MAX_CHECK_THREADS as u64))]
    pub(crate) threads: u64,
    /// Stamp every tile file as a bake does (a world folder written by hand or by other tools,
    /// or whose maps were edited by hand): every tile is read first, and where one cannot be
    /// nothing is written; then each file is written again with its stamp and world.toml gets
    /// the new bake_id (its text otherwise kept).
    #[arg(long)]
    pub(crate) stamp: bool,
    /// Print the report as one JSON document on standard output instead of lines: the world,
    /// the tiles read and each that cannot be, with why (the exit status as without it).
    #[arg(long)]
    pub(crate) json: bool,
    #[command(flatten)]
    pub(crate) http: HttpArgs,
}

/// Most failed tiles listed one a line; the rest are counted.
const LISTED: usize = 50;

pub(crate) fn check(args: CheckArgs) -> Result<()> {
    if args.stamp {
        if args.json {
            bail!("--json reports a check; --stamp prints what it did as lines");
        }
        return stamp(args.world.as_deref());
    }
    let location = resolve_world(
        args.world
            .as_deref()
            .unwrap_or(std::ffi::OsStr::new("santa-cruz")),
    )?;
    let (world, source) = verdant::tools::open_world(&location, &args.http.options())?;
    let cancel = super::stop_on_signals()?;
    let options = CheckOptions {
        threads: args.threads as usize,
        cancel: Some(cancel),
    };
    let mut progress = TenthsBar::new("tiles", "checked", "tiles");
    let report = check_world(&world, source, &options, &mut |done, total| {
        progress.set(done, total)
    })?;
    progress.end(report.interrupted);
    // One line whatever the name holds (a manifest's name may hold a line break).
    let name = verdant::world::printable(&world.manifest.name);
    if args.json {
        let document = serde_json::json!({
            "world": world.manifest.name,
            "location": location.display().to_string(),
            "bake_id": world.manifest.bake_id,
            "report": report,
        });
        say!("{}", serde_json::to_string_pretty(&document)?)?;
    }
    if !args.json {
        for p in &report.failed_plants {
            // The error names the plant type and its file.
            say!("{}", terminal_safe(&p.error))?;
        }
        list_failed(&report.failed)?;
    }
    let stamps = if report.stamped {
        "every file checked against its stamp"
    } else {
        "no stamps checked: the world has no bake_id, baked before stamps or by hand"
    };
    let plants = match report.plant_files {
        0 => String::new(),
        1 => " and its plant file".to_string(),
        n => format!(" and its {n} plant files"),
    };
    let read = format!(
        "{} of {} tiles{plants} of {name} read in {:.1} s",
        report.checked, report.tiles, report.seconds
    );
    // With --json the summary goes to standard error: standard output holds the document alone.
    let json = args.json;
    let summary = |text: String| -> Result<()> {
        if json {
            note!("{text}");
        } else {
            say!("{text}")?;
        }
        Ok(())
    };
    if report.interrupted {
        summary(format!("{read}; stopped"))?;
        return Err(Interrupted(format!(
            "check stopped after {} of {} tiles",
            report.checked, report.tiles
        ))
        .into());
    }
    let plants_failed = match report.failed_plants.len() {
        0 => String::new(),
        n => format!(
            "{n} of {} plant files of {name} cannot be read{}",
            report.plant_files,
            if report.failed.is_empty() { "" } else { "; " }
        ),
    };
    if !report.failed.is_empty() {
        bail!(
            "{plants_failed}{} of {} tiles of {name} cannot be read ({stamps})",
            report.failed.len(),
            report.tiles
        );
    }
    if !plants_failed.is_empty() {
        bail!("{plants_failed} (every tile is whole; {stamps})");
    }
    let whole = if report.plant_files > 0 {
        "every tile and plant file is whole"
    } else {
        "every tile is whole"
    };
    summary(format!("{read}: {whole} ({stamps})"))?;
    Ok(())
}

/// `verdant check --stamp`.
fn stamp(given: Option<&std::ffi::OsStr>) -> Result<()> {
    // It writes: only where the user points, never a world found by name (the source tree's own).
    let Some(given) = given else {
        bail!("--stamp rewrites a world's files: name the world folder to stamp, by its path");
    };
    if let Some(url) = given.to_str().filter(|g| verdant::stream::http::is_url(g)) {
        bail!(
            "--stamp writes the files of a world folder, not of {}: stamp the folder it is \
             served from",
            terminal_safe(url)
        );
    }
    let dir = std::path::Path::new(given);
    if !dir.join("world.toml").is_file() {
        bail!(
            "{}: no world.toml there; --stamp takes a world folder's path (a name under \
             ./worlds is not looked up for a write)",
            super::shown(dir)
        );
    }
    let cancel = super::stop_on_signals()?;
    let mut progress = TenthsBar::new("stamping", "stamping:", "tile reads and writes");
    let report = stamp_world(dir, Some(&cancel), &mut |done, total| {
        progress.set(done, total)
    });
    progress.end(report.is_err());
    let report = match report {
        Err(verdant::world::WorldError::Cancelled { .. }) => {
            return Err(Interrupted(format!(
                "stamping {} stopped before anything was written: the world is as it was",
                super::shown(dir)
            ))
            .into());
        }
        Err(verdant::world::WorldError::StampIncomplete { ref source, .. })
            if matches!(**source, verdant::world::WorldError::Cancelled { .. }) =>
        {
            return Err(Interrupted(format!(
                "stamping {} stopped half way: the world reads as it is, unchecked (its \
                 world.toml has no bake_id), and stamping it again finishes the work",
                super::shown(dir)
            ))
            .into());
        }
        other => other?,
    };
    if report.temporaries_removed > 0 {
        note!(
            "removed {} temporar{} of tile files that a write cut short left in {}",
            report.temporaries_removed,
            if report.temporaries_removed == 1 {
                "y"
            } else {
                "ies"
            },
            super::shown(&dir.join("tiles"))
        );
    }
    list_failed(&report.failed)?;
    let Some(id) = &report.bake_id else {
        bail!(
            "{} of {} tiles of {} cannot be read: nothing stamped",
            report.failed.len(),
            report.tiles,
            super::shown(dir)
        );
    };
    say!(
        "stamped the {} tiles of {} with bake_id \"{id}\" in {:.1} s",
        report.tiles,
        super::shown(dir),
        report.seconds
    )?;
    Ok(())
}

/// Lists the tiles that cannot be read, one a line (the first [`LISTED`]; the rest counted).
fn list_failed(failed: &[FailedTile]) -> Result<()> {
    for f in failed.iter().take(LISTED) {
        let t = f.tile;
        say!("L{}/{}_{}: {}", t.level, t.x, t.y, terminal_safe(&f.error))?;
    }
    if failed.len() > LISTED {
        say!("and {} more tiles", failed.len() - LISTED)?;
    }
    Ok(())
}
