//! Progress bars of the long-running commands.

use indicatif::{ProgressBar, ProgressStyle};

/// The progress bars of [`stage_bars`], shared with its update function.
pub(crate) type StageBars = std::rc::Rc<std::cell::RefCell<Vec<(String, ProgressBar)>>>;

/// Progress bars for a run of named stages, one bar a stage.
pub(crate) fn stage_bars() -> (StageBars, impl FnMut(&str, u64, u64)) {
    let bars = std::rc::Rc::new(std::cell::RefCell::new(Vec::<(String, ProgressBar)>::new()));
    let inner = bars.clone();
    // Without a terminal (a batch job's log) the bars draw nothing: a line a step instead.
    let lines = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let update = move |stage: &str, done: u64, total: u64| {
        if lines {
            eprintln!("{stage}: {done}/{total}");
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

pub(crate) fn finish_bars(bars: &std::cell::RefCell<Vec<(String, ProgressBar)>>) {
    if let Some((_, pb)) = bars.borrow().last() {
        pb.finish();
    }
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
