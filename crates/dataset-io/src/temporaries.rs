//! Temporary outputs: every output is first written under a hidden name next to its target,
//! `.NAME.tmp-PID-N` (a file for [`crate::write_atomic`], a folder for [`crate::OutputDir`]),
//! and renamed into place when complete. This module keeps the list of the temporaries this
//! process has in flight, so that an interrupt can remove them ([`remove_all_and_block`]),
//! and removes the temporaries that dead processes left behind ([`remove_stale`]).
//!
//! Every creation or rename of a temporary runs under a shared gate
//! ([`creating`]); [`remove_all_and_block`] takes the gate exclusively, removes what is
//! listed and never releases it, so that no thread can create a temporary, recreate a removed
//! folder or rename a temporary into place between the clean-up and the end of the process.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard, RwLock, RwLockReadGuard};

static COUNTER: AtomicU64 = AtomicU64::new(0);
static GATE: RwLock<()> = RwLock::new(());
static LIVE: Mutex<BTreeSet<PathBuf>> = Mutex::new(BTreeSet::new());

fn live() -> MutexGuard<'static, BTreeSet<PathBuf>> {
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Holds the gate shared while a temporary (or a file inside a staging folder) is created or
/// renamed. Blocks for ever once an interrupt is being handled.
pub(crate) fn creating() -> RwLockReadGuard<'static, ()> {
    GATE.read().unwrap_or_else(|e| e.into_inner())
}

/// The hidden name of a temporary for `target`: same folder, `.NAME.tmp-PID-N`, unique to
/// this process and call. Not yet registered for removal on an interrupt: the writers of this
/// crate register theirs when they create them.
pub fn temp_sibling(target: &Path) -> PathBuf {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let name = target
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    target.with_file_name(format!(".{name}.tmp-{}-{n}", std::process::id()))
}

/// Lists `path` as a temporary of this process (removed by [`remove_all_and_block`]).
pub(crate) fn register(path: &Path) {
    live().insert(path.to_path_buf());
}

/// Takes `path` off the list (it was renamed into place or removed).
pub(crate) fn unregister(path: &Path) {
    live().remove(path);
}

/// The temporaries of this process that exist now.
pub fn in_flight() -> Vec<PathBuf> {
    live().iter().filter(|p| p.exists()).cloned().collect()
}

fn remove_path(p: &Path) {
    // a folder may still be receiving a file from another thread: try a few times
    for _ in 0..20 {
        let r = if p.is_dir() {
            std::fs::remove_dir_all(p)
        } else {
            std::fs::remove_file(p)
        };
        if r.is_ok() || !p.exists() {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// For an interrupt (Ctrl-C, SIGTERM): removes every temporary of this process and blocks
/// every later creation or rename of an output, for the rest of the process, which is
/// expected to exit right after. Returns the paths removed.
pub fn remove_all_and_block() -> Vec<PathBuf> {
    let gate = GATE.write().unwrap_or_else(|e| e.into_inner());
    let paths: Vec<PathBuf> = std::mem::take(&mut *live()).into_iter().collect();
    for p in &paths {
        remove_path(p);
    }
    // never released: no output may appear or be renamed into place after the clean-up
    std::mem::forget(gate);
    paths
}

/// The process id in a temporary's name `.NAME.tmp-PID-N` made for `target_name`.
fn temp_pid(entry: &str, target_name: &str) -> Option<u32> {
    let rest = entry
        .strip_prefix('.')?
        .strip_prefix(target_name)?
        .strip_prefix(".tmp-")?;
    let (pid, n) = rest.split_once('-')?;
    if n.is_empty() || !n.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// Whether the process `pid` may still be running. Where that cannot be known (no `/proc`),
/// every process counts as running, so nothing is removed.
fn maybe_running(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return true;
    }
    proc.join(pid.to_string()).exists()
}

/// Removes the temporaries of `target` (`.NAME.tmp-PID-N` next to it) that processes no longer
/// running left behind (an interrupt that could not clean up: SIGKILL, a power cut). Returns
/// what was removed. Temporaries of running processes are never touched.
pub fn remove_stale(target: &Path) -> Vec<PathBuf> {
    let Some(name) = target.file_name().map(|s| s.to_string_lossy().into_owned()) else {
        return Vec::new();
    };
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let Ok(entries) = std::fs::read_dir(&parent) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for e in entries.flatten() {
        let entry = e.file_name().to_string_lossy().into_owned();
        match temp_pid(&entry, &name) {
            Some(pid) if !maybe_running(pid) => {
                let p = e.path();
                remove_path(&p);
                if !p.exists() {
                    removed.push(p);
                }
            }
            _ => {}
        }
    }
    removed
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn temp_names_carry_the_pid() {
        let p = temp_sibling(Path::new("a/out.txt"));
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(temp_pid(&name, "out.txt"), Some(std::process::id()));
        assert_eq!(temp_pid(".out.txt.tmp-12-3", "out.txt"), Some(12));
        assert_eq!(temp_pid(".out.txt.tmp-12-", "out.txt"), None);
        assert_eq!(temp_pid(".other.tmp-12-3", "out.txt"), None);
        assert_eq!(temp_pid(".out.txt.tmp-x-3", "out.txt"), None);
    }
}
