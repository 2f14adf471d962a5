//! Ctrl-C (SIGINT), SIGTERM and SIGHUP: every temporary output of the process is removed
//! (hidden `.NAME.tmp-PID-N` files and folders, see `dataset_io::remove_temporaries_and_block`)
//! and the process exits with the conventional code 128 + the signal number (130 for
//! SIGINT, 143 for SIGTERM).

/// Installs the handler: a thread that waits for the signals.
#[cfg(unix)]
pub fn install() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    use std::io::Write;
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
        return;
    };
    let spawned = std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                let removed = dataset_io::remove_temporaries_and_block();
                let what = match sig {
                    SIGINT => "interrupted",
                    SIGTERM => "terminated",
                    _ => "hung up",
                };
                let mut e = std::io::stderr().lock();
                let _ = writeln!(
                    e,
                    "\nmonovo: {what}; {}",
                    match removed.len() {
                        0 => "nothing written".to_string(),
                        1 => "the unfinished output was removed".to_string(),
                        n => format!("{n} unfinished outputs were removed"),
                    }
                );
                std::process::exit(128 + sig);
            }
        });
    drop(spawned);
}

/// Without Unix signals nothing is installed; temporaries left by an interrupt are removed
/// by the next run where the system tells which processes run.
#[cfg(not(unix))]
pub fn install() {}
