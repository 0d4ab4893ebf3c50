//! Progress bars of the long-running commands.

use indicatif::{ProgressBar, ProgressStyle};

use super::out::note;

/// The progress bars of [`stage_bars`], shared with its update function.
pub(crate) type StageBars = std::rc::Rc<std::cell::RefCell<Vec<(String, ProgressBar)>>>;

/// Progress bars for a run of named stages, one bar a stage.
pub(crate) fn stage_bars() -> (StageBars, impl FnMut(&str, u64, u64)) {
    let bars = std::rc::Rc::new(std::cell::RefCell::new(Vec::<(String, ProgressBar)>::new()));
    let inner = bars.clone();
    let lines = lines();
    let update = move |stage: &str, done: u64, total: u64| {
        if lines {
            note!("{stage}: {done}/{total}");
        }
        let mut bars = inner.borrow_mut();
        if bars.last().is_none_or(|(s, _)| s != stage) {
            if let Some((_, pb)) = bars.last() {
                pb.finish();
            }
            bars.push((stage.to_owned(), bar(total, stage)));
        }
        if let Some((_, pb)) = bars.last() {
            pb.set_position(done);
        }
    };
    (bars, update)
}

/// Ends the bars of a run: the last one finished, or left where it stopped if the run was
/// `interrupted`.
pub(crate) fn finish_bars(
    bars: &std::cell::RefCell<Vec<(String, ProgressBar)>>,
    interrupted: bool,
) {
    end_bar(bars.borrow().last().map(|(_, pb)| pb), interrupted);
}

/// Ends a run's bar, if it drew one: finished, or left where it stopped if the run was
/// `interrupted`.
pub(crate) fn end_bar(pb: Option<&ProgressBar>, interrupted: bool) {
    let Some(pb) = pb else { return };
    if interrupted {
        pb.abandon();
    } else {
        pb.finish();
    }
    // The bar leaves the cursor at the end of its line: what is printed next (a summary on
    // standard output) starts a line of its own.
    if !pb.is_hidden() {
        note!("");
    }
}

/// Whether progress is written a line a step: without a terminal (a batch job's log) the bars
/// draw nothing.
pub(crate) fn lines() -> bool {
    !std::io::IsTerminal::is_terminal(&std::io::stderr())
}

pub(crate) fn bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template(
            "{msg:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
        )
        .expect("static template")
        .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}

/// A bar for one run of `total` steps, named `name`, that also logs a line a tenth of the way
/// (`{prefix} {done}/{total} {unit}`) where there is no terminal for the bar (a batch job's log).
pub(crate) struct TenthsBar {
    name: &'static str,
    prefix: &'static str,
    unit: &'static str,
    pb: Option<ProgressBar>,
    log_lines: bool,
    /// The tenths of the way logged so far.
    logged: Option<u64>,
}

impl TenthsBar {
    pub(crate) fn new(name: &'static str, prefix: &'static str, unit: &'static str) -> Self {
        Self {
            name,
            prefix,
            unit,
            pb: None,
            log_lines: lines(),
            logged: None,
        }
    }

    pub(crate) fn set(&mut self, done: u64, total: u64) {
        if self.log_lines {
            let tenth = (done * 10).checked_div(total).unwrap_or(10);
            if self.logged.is_none_or(|t| tenth > t) {
                self.logged = Some(tenth);
                note!("{} {done}/{total} {}", self.prefix, self.unit);
            }
        }
        let name = self.name;
        self.pb
            .get_or_insert_with(|| bar(total, name))
            .set_position(done);
    }

    /// Ends the bar as [`end_bar`] does.
    pub(crate) fn end(&self, interrupted: bool) {
        end_bar(self.pb.as_ref(), interrupted);
    }
}
