//! `cargo xtask fuzz`: every parser of the workspace fed arbitrary and mutated bytes, with a
//! seeded random generator (reproducible: a case is its target, the seed and its number,
//! whatever the number of threads), on stable Rust. A case passes when the parser returns,
//! with a value or an error; a panic is caught (`catch_unwind` per case), its input written
//! to `target/fuzz-failures/` with the command that reproduces it, and the run fails.
//!
//! Inputs are, in turn: random bytes, random text from the alphabet of the formats, and
//! mutations (bit flips, interesting bytes and 32-bit values, insertions, deletions,
//! duplications, truncation, numbers replaced by extreme ones, lines deleted, duplicated or
//! swapped, splices of two seeds, PNG chunks whose CRC is made valid again) of seeds: the
//! real files under `tests/fixtures/dso-family/` (their first few KiB) and small generated
//! files (a sequence's times.txt and images.zip, PNG and JPEG frames of every kind, poses,
//! results.csv; the calibration config `data/calib.toml`).
//!
//! What a case exercises beyond the parser: what the command-line tools do next with a
//! parsed value (camera.txt: the output pinhole and the rectification map, on about one case
//! in four, picked by a hash of the input, and at a reduced size, so that a million cases
//! stay minutes; trajectories and ground truths: the evaluation; results.csv: the summaries;
//! PNG: the vignette).
//!
//! A process abort (out of memory, stack overflow) cannot be caught: it ends the run without a
//! report; `--case N` reruns one case (`--save FILE` writes its input) to find it.

mod mutate;
mod runners;
mod seeds;

use std::io::{IsTerminal, Write};
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use rayon::prelude::*;

use self::mutate::input;
use self::seeds::targets;

/// One parser under test: its name, its seeds and the function that feeds it one input.
struct Target {
    /// Short name, for `--target` and file names.
    id: &'static str,
    /// What is parsed.
    what: &'static str,
    seeds: Vec<Vec<u8>>,
    /// Text formats get text mutations (numbers, lines) and text from their alphabet.
    text: bool,
    /// Feeds one input; `true` when the parser accepted it.
    run: fn(&[u8]) -> bool,
}

// ---------------------------------------------------------------------------------------
// running

thread_local! {
    /// Where the last panic on this thread happened, set by the panic hook.
    static PANIC_AT: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

/// A panic found: the target, the case and its input.
struct Finding {
    case: u64,
    message: String,
    input: Vec<u8>,
}

/// The outcome of one target.
struct Outcome {
    cases: u64,
    /// Inputs the parser accepted (the rest were errors).
    accepted: u64,
    seconds: f64,
    /// The slowest case: its duration and number.
    slowest: (Duration, u64),
    findings: Vec<Finding>,
}

fn usage() -> &'static str {
    "usage: cargo xtask fuzz [--cases N] [--quick] [--seed S] [--target NAME[,NAME..]]\n       \
     \x20               [--case N [--save FILE] | --input FILE] [--list]\n\n\
     Feeds every parser arbitrary and mutated bytes (seeded, reproducible, the same inputs with\n\
     any number of threads) and fails on a panic, writing the input and the command that\n\
     reproduces it to target/fuzz-failures/. --cases is per target (default 1000000); --quick\n\
     is 20000; --target runs the named targets (--list shows them); --case N runs case N only\n\
     (--save FILE writes its input); --input FILE runs the targets on the bytes of FILE.\n\
     RAYON_NUM_THREADS sets the number of threads."
}

struct Options {
    cases: u64,
    seed: u64,
    only: Option<Vec<String>>,
    case: Option<u64>,
    input: Option<PathBuf>,
    list: bool,
    /// With `--case`: where to write the case's input.
    save: Option<PathBuf>,
}

fn number(args: &mut dyn Iterator<Item = String>, flag: &str) -> Result<u64> {
    let v = args
        .next()
        .with_context(|| format!("{flag} needs a number"))?;
    v.replace('_', "")
        .parse()
        .with_context(|| format!("{flag} needs a number, not `{v}`"))
}

fn options(mut args: impl Iterator<Item = String>) -> Result<Option<Options>> {
    let mut o = Options {
        cases: 1_000_000,
        seed: 1,
        only: None,
        case: None,
        input: None,
        list: false,
        save: None,
    };
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => o.cases = 20_000,
            "--cases" => o.cases = number(&mut args, "--cases")?,
            "--seed" => o.seed = number(&mut args, "--seed")?,
            "--case" => o.case = Some(number(&mut args, "--case")?),
            "--target" | "--only" => {
                let names = args.next().context("--target needs a name (see --list)")?;
                o.only = Some(names.split(',').map(|s| s.trim().to_string()).collect());
            }
            "--input" => o.input = Some(args.next().context("--input needs a file")?.into()),
            "--list" => o.list = true,
            "--save" => o.save = Some(args.next().context("--save needs a file")?.into()),
            "-h" | "--help" => {
                println!("{}", usage());
                return Ok(None);
            }
            other => bail!("unknown argument `{other}`\n{}", usage()),
        }
    }
    Ok(Some(o))
}

/// A stable number for a target's name: its cases do not change when targets are added.
fn name_hash(id: &str) -> u64 {
    fnv1a(id.as_bytes())
}

/// FNV-1a, 64 bits.
fn fnv1a(b: &[u8]) -> u64 {
    b.iter().fold(0xCBF2_9CE4_8422_2325u64, |h, &c| {
        (h ^ c as u64).wrapping_mul(0x0000_0100_0000_01B3)
    })
}

/// Runs one input through a target: whether the parser accepted it, or the panic's message
/// and location.
fn run_case(t: &Target, bytes: &[u8]) -> std::result::Result<bool, String> {
    let r = std::panic::catch_unwind(AssertUnwindSafe(|| (t.run)(bytes)));
    let at = PANIC_AT.with(|p| p.borrow_mut().take());
    match r {
        Ok(accepted) => Ok(accepted),
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "panic".into());
            Err(format!("{msg}{}", at.unwrap_or_default()))
        }
    }
}

/// Runs `cases` cases of a target in parallel, with a live progress line on a terminal.
fn run_target(t: &Target, seed: u64, cases: u64, first: u64) -> Outcome {
    let started = Instant::now();
    let found: Mutex<Vec<Finding>> = Mutex::new(Vec::new());
    let panics = AtomicUsize::new(0);
    let done = AtomicU64::new(0);
    let accepted = AtomicU64::new(0);
    let finished = AtomicBool::new(false);
    let key = name_hash(t.id);
    let show = std::io::stderr().is_terminal() && cases > 1;
    let slowest = std::thread::scope(|s| {
        if show {
            s.spawn(|| {
                while !finished.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(250));
                    let n = done.load(Ordering::Relaxed);
                    let secs = started.elapsed().as_secs_f64();
                    eprint!(
                        "\r{:<14} {n:>9}/{cases} cases {:>9.0} cases/s  ",
                        t.id,
                        n as f64 / secs.max(1e-9)
                    );
                }
                eprint!("\r{:<72}\r", "");
            });
        }
        let slowest = (first..first + cases)
            .into_par_iter()
            .map(|case| {
                // after 5 panics the rest of the target is skipped
                if panics.load(Ordering::Relaxed) >= 5 {
                    return (Duration::ZERO, case);
                }
                let bytes = input(seed, key, case, t);
                let t0 = Instant::now();
                let r = run_case(t, &bytes);
                let took = t0.elapsed();
                done.fetch_add(1, Ordering::Relaxed);
                if r == Ok(true) {
                    accepted.fetch_add(1, Ordering::Relaxed);
                }
                if let Err(message) = r {
                    panics.fetch_add(1, Ordering::Relaxed);
                    if let Ok(mut f) = found.lock() {
                        f.push(Finding {
                            case,
                            message,
                            input: bytes,
                        });
                    }
                }
                (took, case)
            })
            .reduce(
                || (Duration::ZERO, u64::MAX),
                |a, b| if b.0 > a.0 { b } else { a },
            );
        finished.store(true, Ordering::Relaxed);
        slowest
    });
    let mut findings = found.into_inner().unwrap_or_else(|e| e.into_inner());
    findings.sort_by_key(|f| f.case);
    Outcome {
        cases,
        accepted: accepted.into_inner(),
        seconds: started.elapsed().as_secs_f64(),
        slowest,
        findings,
    }
}

fn safe_name(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Writes a finding's input and a note with the message and the command that reproduces
/// it; returns the input's path.
fn write_finding(dir: &Path, t: &Target, seed: u64, f: &Finding) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
    let stem = format!("{}-seed{seed}-case{}", safe_name(t.id), f.case);
    let file = dir.join(format!("{stem}.bin"));
    std::fs::write(&file, &f.input).with_context(|| file.display().to_string())?;
    let note = dir.join(format!("{stem}.txt"));
    std::fs::write(
        &note,
        format!(
            "target: {} ({})\ncase: {} of seed {seed}\npanic: {}\n\nreproduce:\n  \
             cargo xtask fuzz --target {} --seed {seed} --case {}\n  \
             cargo xtask fuzz --target {} --input {}\n",
            t.id,
            t.what,
            f.case,
            f.message,
            t.id,
            f.case,
            t.id,
            file.display()
        ),
    )
    .with_context(|| note.display().to_string())?;
    Ok(file)
}

/// Runs `cargo xtask fuzz` with its arguments.
pub fn run(args: impl Iterator<Item = String>) -> Result<()> {
    let Some(opts) = options(args)? else {
        return Ok(());
    };
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let all = targets(&root)?;
    if opts.list {
        for t in &all {
            println!("{:<14} {} ({} seeds)", t.id, t.what, t.seeds.len());
        }
        return Ok(());
    }
    let chosen: Vec<&Target> = match &opts.only {
        None => all.iter().collect(),
        Some(names) => {
            for n in names {
                if !all.iter().any(|t| t.id == n) {
                    bail!(
                        "no fuzz target `{n}`; the targets are: {}",
                        all.iter().map(|t| t.id).collect::<Vec<_>>().join(", ")
                    );
                }
            }
            all.iter()
                .filter(|t| names.iter().any(|n| n == t.id))
                .collect()
        }
    };
    // panics are caught and reported by run_case, not printed by the default hook
    std::panic::set_hook(Box::new(|info| {
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        PANIC_AT.with(|p| *p.borrow_mut() = Some(at));
    }));
    if let Some(file) = &opts.input {
        let bytes = std::fs::read(file).with_context(|| file.display().to_string())?;
        let mut failed = 0;
        for t in &chosen {
            match run_case(t, &bytes) {
                Ok(accepted) => println!(
                    "{:<14} ok ({})",
                    t.id,
                    if accepted { "accepted" } else { "an error" }
                ),
                Err(m) => {
                    failed += 1;
                    println!("{:<14} PANIC: {m}", t.id);
                }
            }
        }
        if failed > 0 {
            bail!("{} made {failed} target(s) panic", file.display());
        }
        return Ok(());
    }
    if let Some(file) = &opts.save {
        let (Some(case), [t]) = (opts.case, chosen.as_slice()) else {
            bail!("--save FILE needs --case N and one --target");
        };
        let bytes = input(opts.seed, name_hash(t.id), case, t);
        std::fs::write(file, bytes).with_context(|| file.display().to_string())?;
    }
    let (first, cases) = match opts.case {
        Some(c) => (c, 1),
        None => (0, opts.cases),
    };
    let seed = opts.seed;
    let out_dir = root.join("target/fuzz-failures");
    println!(
        "fuzzing {} targets, {cases} cases each, seed {seed}, {} threads",
        chosen.len(),
        rayon::current_num_threads()
    );
    let started = Instant::now();
    let mut failures = 0;
    for t in &chosen {
        let o = run_target(t, seed, cases, first);
        println!(
            "{:<14} {:>9} cases {:>7.1} s {:>9.0} cases/s {:>5.1}% accepted  slowest {:>6.1} ms (case {})  {}",
            t.id,
            o.cases,
            o.seconds,
            o.cases as f64 / o.seconds.max(1e-9),
            100.0 * o.accepted as f64 / o.cases.max(1) as f64,
            o.slowest.0.as_secs_f64() * 1e3,
            o.slowest.1,
            if o.findings.is_empty() {
                "ok".to_string()
            } else {
                format!("{} PANIC(S)", o.findings.len())
            }
        );
        std::io::stdout().flush().ok();
        for f in &o.findings {
            failures += 1;
            let file = write_finding(&out_dir, t, seed, f)?;
            let shown: String = f
                .input
                .iter()
                .take(200)
                .flat_map(|b| std::ascii::escape_default(*b))
                .map(char::from)
                .collect();
            println!(
                "  PANIC in {} ({}), case {} of seed {seed}: {}\n    input ({} bytes, in {}): {shown}\n    \
                 reproduce: cargo xtask fuzz --target {} --seed {seed} --case {}",
                t.id,
                t.what,
                f.case,
                f.message,
                f.input.len(),
                file.display(),
                t.id,
                f.case
            );
        }
    }
    println!("total {:.1} s", started.elapsed().as_secs_f64());
    if failures > 0 {
        bail!(
            "{failures} input(s) made a parser panic; inputs and notes in {}",
            out_dir.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn root() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
    }

    /// A case's input depends on the seed, the target and the case number only: the same
    /// with 1 and with 2 threads and in any order.
    #[test]
    fn inputs_do_not_depend_on_threads_or_order() {
        let all = targets(&root()).unwrap();
        for t in &all {
            let key = name_hash(t.id);
            let one: Vec<Vec<u8>> = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| {
                    (0..200usize)
                        .into_par_iter()
                        .map(|c| input(7, key, c as u64, t))
                        .collect()
                });
            let two: Vec<Vec<u8>> = rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap()
                .install(|| {
                    (0..200usize)
                        .into_par_iter()
                        .rev()
                        .map(|c| input(7, key, c as u64, t))
                        .collect::<Vec<_>>()
                        .into_iter()
                        .rev()
                        .collect()
                });
            assert!(one == two, "{}", t.id);
            // and the inputs vary
            assert!(one.iter().any(|i| i != &one[0]), "{}", t.id);
        }
    }

    /// Every target runs a short burst without a panic, and a panicking target is caught.
    #[test]
    fn a_short_run_passes_and_panics_are_caught() {
        let all = targets(&root()).unwrap();
        for t in &all {
            let o = run_target(t, 3, 300, 0);
            assert!(o.findings.is_empty(), "{}: {}", t.id, o.findings[0].message);
        }
        fn boom(b: &[u8]) -> bool {
            if b.len() > 3 {
                panic!("boom");
            }
            true
        }
        let t = Target {
            id: "boom",
            what: "a target that panics",
            seeds: vec![b"0123456789".to_vec()],
            text: true,
            run: boom,
        };
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let o = run_target(&t, 1, 50, 0);
        std::panic::set_hook(prev);
        assert!(!o.findings.is_empty() && o.findings.len() <= 50);
        assert!(o.findings[0].message.contains("boom"));
        let d = std::env::temp_dir().join(format!("monovo-fuzz-test-{}", std::process::id()));
        let f = write_finding(&d, &t, 1, &o.findings[0]).unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), o.findings[0].input);
        let note = std::fs::read_to_string(f.with_extension("txt")).unwrap();
        assert!(note.contains("--target boom --seed 1 --case"), "{note}");
        std::fs::remove_dir_all(&d).ok();
    }
}
