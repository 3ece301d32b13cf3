//! Progress reporting for long loops.
//!
//! Algorithms take a `&Progress` and call [`Progress::inc`] as work completes; the CLI decides
//! whether anything is drawn. Bars go to stderr and only when stderr is a terminal and the user
//! did not ask for `--quiet`; in pipelines and tests a `Progress` is silent and nearly free.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A progress counter that may or may not be drawn. Cheap to clone and to share across threads.
#[derive(Clone)]
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A bar over `total` units of work labelled `what`, drawn on stderr when `visible` and
    /// stderr is a terminal.
    pub fn new(total: u64, what: &str, visible: bool) -> Progress {
        let bar = ProgressBar::with_draw_target(Some(total), draw_target(visible));
        bar.set_style(
            ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} ({eta})")
                .expect("static template")
                .progress_chars("=> "),
        );
        bar.set_message(what.to_string());
        Progress { bar }
    }

    /// A progress that never draws (library callers and tests).
    pub fn hidden() -> Progress {
        Progress {
            bar: ProgressBar::hidden(),
        }
    }

    /// Start a new phase of `total` units labelled `what` on the same bar.
    pub fn phase(&self, total: u64, what: &str) {
        self.bar.set_length(total);
        self.bar.set_position(0);
        self.bar.set_message(what.to_string());
    }

    /// Record `n` more units done.
    #[inline]
    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
    }

    /// Remove the bar from the terminal.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

fn draw_target(visible: bool) -> ProgressDrawTarget {
    use std::io::IsTerminal;
    if visible && std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    }
}
