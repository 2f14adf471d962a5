//! Progress on a terminal, silence otherwise: bars count things in their own unit ("frames",
//! "runs") with the rate in that unit per second; spinners show iterations with their
//! convergence measure where the number of iterations is not known in advance.

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};

fn target() -> ProgressDrawTarget {
    if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    }
}

/// A progress bar over `len` things of `unit` (plural, e.g. "frames") on stderr, with the
/// rate in `unit`/s; hidden when stderr is not a terminal.
pub fn bar(len: u64, what: &str, unit: &'static str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(len), target());
    let style =
        ProgressStyle::with_template("{msg:>12} [{bar:32}] {pos}/{len} {unit} ({rate}, eta {eta})")
            .map(|s| {
                s.with_key(
                    "unit",
                    move |_: &ProgressState, w: &mut dyn std::fmt::Write| {
                        let _ = w.write_str(unit);
                    },
                )
                .with_key(
                    "rate",
                    move |st: &ProgressState, w: &mut dyn std::fmt::Write| {
                        let r = st.per_sec();
                        let _ = if r >= 10.0 {
                            write!(w, "{r:.0} {unit}/s")
                        } else {
                            write!(w, "{r:.1} {unit}/s")
                        };
                    },
                )
            })
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
    pb.set_style(style);
    pb.set_message(what.to_string());
    pb
}

/// A spinner with a message (for iterations whose number is not known in advance); hidden
/// when stderr is not a terminal.
pub fn spinner(what: &str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(None, target());
    let style = ProgressStyle::with_template("{spinner} {elapsed:>4} {msg}")
        .unwrap_or_else(|_| ProgressStyle::default_spinner());
    pb.set_style(style);
    pb.set_message(what.to_string());
    if !pb.is_hidden() {
        pb.enable_steady_tick(std::time::Duration::from_millis(200));
    }
    pb
}

/// The command's observer of library pipelines: warnings to stderr, stages as progress bars.
#[derive(Default)]
pub struct Bars(std::sync::Mutex<Option<ProgressBar>>);

impl monovo_pipelines::Observer for Bars {
    fn warn(&self, message: &str) {
        crate::warn(format_args!("{message}"));
    }
    fn begin(&self, len: u64, what: &str, unit: &'static str) {
        if let Ok(mut b) = self.0.lock() {
            *b = Some(bar(len, what, unit));
        }
    }
    fn advance(&self, n: u64) {
        if let Ok(b) = self.0.lock() {
            if let Some(b) = b.as_ref() {
                b.inc(n);
            }
        }
    }
    fn status(&self, message: &str) {
        if let Ok(mut b) = self.0.lock() {
            match b.as_ref() {
                Some(pb) => pb.set_message(message.to_string()),
                None => *b = Some(spinner(message)),
            }
        }
    }
    fn finish(&self) {
        if let Ok(mut b) = self.0.lock() {
            if let Some(b) = b.take() {
                b.finish_and_clear();
            }
        }
    }
}
