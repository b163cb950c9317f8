//! Progress bars that appear only for long work: a run that ends within a second prints nothing
//! but its result, a longer one shows how far it is (on stderr, so that stdout stays clean).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long work runs before its bar appears.
const DELAY: Duration = Duration::from_secs(1);

/// A bar of `len` steps, hidden until the work has taken [`DELAY`]. Safe to advance from any
/// thread.
pub struct LateBar {
    bar: ProgressBar,
    start: Instant,
    shown: AtomicBool,
}

impl LateBar {
    /// `unit` names a step ("rows", "settings").
    pub fn new(len: u64, unit: &str) -> Self {
        let style = ProgressStyle::with_template(&format!("{{bar:40}} {{pos}}/{{len}} {unit} {{elapsed}} {{msg}}"))
            .expect("the template is valid");
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden()).with_style(style);
        Self { bar, start: Instant::now(), shown: AtomicBool::new(false) }
    }

    pub fn inc(&self, steps: u64) {
        self.bar.inc(steps);
        if self.start.elapsed() >= DELAY && !self.shown.swap(true, Ordering::Relaxed) {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
        }
    }

    pub fn set_message(&self, msg: String) {
        self.bar.set_message(msg);
    }

    /// Removes the bar (if it was shown).
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
