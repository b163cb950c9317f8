//! What every program here does the same way: a command-line mistake is one line and exit status
//! 2, an error is one line and exit status 1, output read only in part (`| head -1`) ends the
//! program quietly, and progress bars appear only on work that takes more than a second.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::Write;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

/// Parses the command line. Help and version print as clap prints them; a mistake prints clap's
/// first line (which names the option and the value) and nothing else, and exits with status 2.
pub fn parse<T: clap::Parser>() -> T {
    match T::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                e.exit();
            }
            let text = e.render().to_string();
            let line = text.lines().map(str::trim_end).find(|l| !l.is_empty()).unwrap_or("error: invalid command line");
            let _ = writeln!(std::io::stderr(), "{line} (see --help)");
            std::process::exit(2)
        }
    }
}

/// Runs a program's body: half-written outputs are removed if the user interrupts it, and an
/// error ends it with `error: <sentence>` and exit status 1.
pub fn run(body: impl FnOnce() -> Result<(), String>) -> ExitCode {
    crate::output::remove_partial_outputs_on_interrupt();
    match body() {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            let _ = writeln!(std::io::stderr(), "error: {message}");
            ExitCode::FAILURE
        }
    }
}

static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);

/// Prints one line on standard output. When the reader has gone away (`| head -1`) the rest is
/// dropped quietly, as command-line tools do; `println!` would panic instead.
pub fn say(line: &str) {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    if let Err(e) = writeln!(std::io::stdout().lock(), "{line}") {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            let _ = writeln!(std::io::stderr(), "warning: cannot write to standard output: {e}");
        }
    }
}

/// `println!` through [`say`].
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => { $crate::cli::say(&format!($($arg)*)) };
}

/// How long work runs before its progress bar appears.
pub const PROGRESS_DELAY: Duration = Duration::from_secs(1);

/// A progress bar on standard error that stays hidden for its first second (short work shows
/// nothing) and entirely when `quiet` is set or standard error is not a terminal.
pub struct Progress {
    bar: ProgressBar,
    start: Instant,
    quiet: bool,
    shown: AtomicBool,
}

impl Progress {
    /// A bar counting `len` steps, `template` in indicatif's syntax.
    pub fn new(len: u64, template: &str, quiet: bool) -> Progress {
        let style = ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar());
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden()).with_style(style);
        Progress { bar, start: Instant::now(), quiet, shown: AtomicBool::new(false) }
    }

    fn show_if_due(&self) {
        if !self.quiet && !self.shown.load(Ordering::Relaxed) && self.start.elapsed() >= PROGRESS_DELAY {
            self.shown.store(true, Ordering::Relaxed);
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
        }
    }

    pub fn set_position(&self, pos: u64) {
        self.bar.set_position(pos);
        self.show_if_due();
    }

    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
        self.show_if_due();
    }

    pub fn set_message(&self, msg: String) {
        self.bar.set_message(msg);
        self.show_if_due();
    }

    /// Redraws (a spinner or the elapsed time moves on) without progress to report.
    pub fn tick(&self) {
        self.show_if_due();
        self.bar.tick();
    }

    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }

    /// Runs `work` on this thread (which may hold what cannot move between threads, such as a
    /// Vulkan renderer) while a helper thread redraws the bar every 100 ms, so that the elapsed
    /// time moves on during long steps that report nothing. The helper waits on a channel rather
    /// than sleeping, so that it ends the moment `work` does instead of up to 100 ms later.
    pub fn ticking<T>(&self, work: impl FnOnce() -> T) -> T {
        let (done, finished) = std::sync::mpsc::channel::<()>();
        std::thread::scope(|s| {
            s.spawn(move || {
                while finished.recv_timeout(Duration::from_millis(100)) == Err(RecvTimeoutError::Timeout) {
                    self.tick();
                }
            });
            let result = work();
            drop(done);
            self.finish();
            result
        })
    }

    /// Runs `work` on a worker thread while calling `poll` (which updates this bar) every 50 ms.
    /// The worker's end wakes this thread at once (a sleep here cost `bvhc compile` 25 ms on
    /// average per phase).
    pub fn around<T: Send>(&self, work: impl FnOnce() -> T + Send, poll: impl Fn(&Progress)) -> T {
        let (done, finished) = std::sync::mpsc::channel::<()>();
        std::thread::scope(|s| {
            // Dropped when the work ends or panics, which ends the wait below.
            let worker = s.spawn(move || {
                let _done = done;
                work()
            });
            poll(self);
            while finished.recv_timeout(Duration::from_millis(50)) == Err(RecvTimeoutError::Timeout) {
                poll(self);
            }
            self.finish();
            worker.join().unwrap_or_else(|p| std::panic::resume_unwind(p))
        })
    }
}

/// A rate in the unit that shows it: rays/s, krays/s, Mrays/s or Grays/s, three significant
/// digits, so that a small figure never reads "0.0 Mrays/s".
pub fn rays_per_second(rays: u64, seconds: f64) -> String {
    if seconds.is_nan() || seconds <= 0.0 {
        return "rate not measurable".to_owned();
    }
    let r = rays as f64 / seconds;
    let (v, unit) = match r {
        r if r >= 1e9 => (r / 1e9, "Grays/s"),
        r if r >= 1e6 => (r / 1e6, "Mrays/s"),
        r if r >= 1e3 => (r / 1e3, "krays/s"),
        r => (r, "rays/s"),
    };
    let decimals = if v >= 100.0 {
        0
    } else if v >= 10.0 {
        1
    } else {
        2
    };
    format!("{v:.decimals$} {unit}")
}

/// A duration in the unit that shows it (ms below ten seconds, else seconds).
pub fn duration(seconds: f64) -> String {
    if seconds < 10.0 { format!("{:.3} ms", seconds * 1e3) } else { format!("{seconds:.2} s") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_pick_a_unit_that_shows_the_figure() {
        assert_eq!(rays_per_second(40, 1e-3), "40.0 krays/s");
        assert_eq!(rays_per_second(12, 1.0), "12.0 rays/s");
        assert_eq!(rays_per_second(3_000_000, 1.0), "3.00 Mrays/s");
        assert_eq!(rays_per_second(4_388_000_000, 1.0), "4.39 Grays/s");
        assert_eq!(rays_per_second(1, 0.0), "rate not measurable");
        assert!(!rays_per_second(1, 10.0).starts_with("0.0 "));
    }
}
