//! `verdant check`: its options and what it prints.

use anyhow::{Result, bail};

use verdant::tools::check::{CheckOptions, MAX_CHECK_THREADS, check_world};

use super::args::{HttpArgs, resolve_world};
use super::out::{note, say};
use super::progress::{bar, end_bar, lines};
use super::{Interrupted, terminal_safe};

/// The options of `verdant check`.
#[derive(clap::Args)]
pub(crate) struct CheckArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address.
    #[arg(default_value = "santa-cruz")]
    pub(crate) world: String,
    /// Tiles read at once, 1..=64 (several hide a server's latency).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=MAX_CHECK_THREADS as u64))]
    pub(crate) threads: u64,
    #[command(flatten)]
    pub(crate) http: HttpArgs,
}

/// Most failed tiles listed one a line; the rest are counted.
const LISTED: usize = 50;

pub(crate) fn check(args: CheckArgs) -> Result<()> {
    let location = resolve_world(&args.world)?;
    let (world, source) = verdant::tools::open_world(&location, &args.http.options())?;
    let cancel = super::stop_on_signals()?;
    let options = CheckOptions {
        threads: args.threads as usize,
        cancel: Some(cancel),
    };
    let mut pb = None;
    let log_lines = lines();
    // The tenths of the way logged so far.
    let mut logged = None;
    let report = check_world(&world, source.as_ref(), &options, &mut |done, total| {
        if log_lines {
            // A line a tenth of the way, for a batch job's log.
            let tenth = (done * 10).checked_div(total).unwrap_or(10);
            if logged.is_none_or(|t| tenth > t) {
                logged = Some(tenth);
                note!("checked {done}/{total} tiles");
            }
        }
        pb.get_or_insert_with(|| bar(total, "tiles"))
            .set_position(done);
    })?;
    end_bar(pb.as_ref(), report.interrupted);
    let name = terminal_safe(&world.manifest.name);
    for (id, why) in report.failed.iter().take(LISTED) {
        say!("L{}/{}_{}: {}", id.level, id.x, id.y, terminal_safe(why))?;
    }
    if report.failed.len() > LISTED {
        say!("and {} more tiles", report.failed.len() - LISTED)?;
    }
    let stamps = if report.stamped {
        "every file checked against its stamp"
    } else {
        "no stamps checked: the world has no bake_id, baked before stamps or by hand"
    };
    let read = format!(
        "{} of {} tiles of {name} read in {:.1} s",
        report.checked, report.tiles, report.seconds
    );
    if report.interrupted {
        say!("{read}; stopped")?;
        return Err(Interrupted(format!(
            "check stopped after {} of {} tiles",
            report.checked, report.tiles
        ))
        .into());
    }
    if !report.failed.is_empty() {
        bail!(
            "{} of {} tiles of {name} cannot be read ({stamps})",
            report.failed.len(),
            report.tiles
        );
    }
    say!("{read}: every tile is whole ({stamps})")?;
    Ok(())
}
