//! Behaviour at a terminal and under faults: interrupts remove the temporary output and exit
//! with 128 + the signal, stale temporaries of dead processes go away, existing outputs are
//! refused without --force, every output location is checked before any work, and a closed
//! pipe ends a command quietly.
use crate::common::{monovo, repo_file, stderr, stdout, temp_dir};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn spawn(args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_monovo"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start monovo")
}

/// Hidden temporaries (`.NAME.tmp-PID-N`) in `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.contains(".tmp-"))
        .collect()
}

/// Waits until the command has started writing `name` in `dir` (its temporary exists).
fn wait_for_temporary(dir: &Path, name: &str, child: &mut Child) {
    let started = Instant::now();
    let prefix = format!(".{name}.tmp-");
    loop {
        if temporaries(dir).iter().any(|t| t.starts_with(&prefix)) {
            return;
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("monovo ended ({status}) before writing {name}");
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no temporary of {name} appeared"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn kill(child: &Child, signal: &str) {
    let ok = Command::new("kill")
        .args([format!("-{signal}"), child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -{signal}");
}

/// Runs `args`, sends `signal` once `name` is being written in `dir`, and checks the exit
/// code and that no temporary is left.
fn interrupt(args: &[&str], dir: &Path, name: &str, signal: &str, code: i32) -> String {
    let mut child = spawn(args);
    wait_for_temporary(dir, name, &mut child);
    kill(&child, signal);
    let out = child.wait_with_output().unwrap();
    let e = stderr(&out);
    assert_eq!(
        out.status.code(),
        Some(code),
        "exit code after {signal}: {e}"
    );
    assert!(temporaries(dir).is_empty(), "left: {:?}", temporaries(dir));
    e
}

/// A sequence of `n` identical 1280x1024 PNG frames with the dataset's FOV camera: slow
/// enough to rectify that a signal arrives mid-run, quick to make.
fn many_frames(dir: &Path, n: usize) -> PathBuf {
    let seq = dir.join("seq");
    std::fs::create_dir_all(seq.join("images")).unwrap();
    let (w, h) = (1280, 1024);
    let px: Vec<u8> = (0..w * h)
        .map(|i| ((i % w) / 5 + (i / w) / 8) as u8)
        .collect();
    let png = dataset_io::encode_png_u8(w, h, 1, &px, dataset_io::PngSpeed::Fast).unwrap();
    let mut times = String::new();
    for i in 0..n {
        std::fs::write(seq.join(format!("images/{i:05}.png")), &png).unwrap();
        times.push_str(&format!("{i:05} {}.0 10\n", 1000 + i));
    }
    std::fs::write(seq.join("times.txt"), times).unwrap();
    std::fs::copy(repo_file("data/camera_narrow.txt"), seq.join("camera.txt")).unwrap();
    seq
}

#[test]
fn sigint_during_rectify_removes_the_output_and_keeps_the_old_one() {
    let d = temp_dir("terminal_sigint_rectify");
    let seq = many_frames(&d, 150);
    let out = d.join("out");
    let args = [
        "rectify",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    let e = interrupt(&args, &d, "out", "INT", 130);
    assert!(e.contains("interrupted"), "{e}");
    assert!(!out.exists());
    // with --force over an earlier output: the earlier output stays whole
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("earlier.txt"), "kept").unwrap();
    let mut forced = args.to_vec();
    forced.push("--force");
    interrupt(&forced, &d, "out", "INT", 130);
    assert_eq!(
        std::fs::read_to_string(out.join("earlier.txt")).unwrap(),
        "kept"
    );
}

#[test]
fn sigterm_during_synth_and_sigint_during_demo_leave_nothing() {
    let d = temp_dir("terminal_sigterm_synth");
    let out = d.join("seq");
    let e = interrupt(
        &[
            "synth",
            "sequence",
            "-o",
            out.to_str().unwrap(),
            "--frames",
            "300",
        ],
        &d,
        "seq",
        "TERM",
        143,
    );
    assert!(e.contains("terminated"), "{e}");
    assert!(!out.exists());
    let demo = d.join("demo");
    interrupt(
        &["demo", "-o", demo.to_str().unwrap()],
        &d,
        "demo",
        "INT",
        130,
    );
    assert!(!demo.exists());
}

#[test]
fn stale_temporaries_of_dead_processes_are_removed_by_the_next_run() {
    let d = temp_dir("terminal_stale");
    // 4294967294 is above every pid_max: that process is dead
    let dead_dir = d.join(".res.tmp-4294967294-0");
    std::fs::create_dir_all(dead_dir.join("dataset")).unwrap();
    std::fs::write(dead_dir.join("dataset/x.txt"), "half").unwrap();
    let dead_file = d.join(".r.csv.tmp-4294967294-3");
    std::fs::write(&dead_file, "half").unwrap();
    // the temporary of a running process (this test) is not touched
    let alive = d.join(format!(".res.tmp-{}-5", std::process::id()));
    std::fs::create_dir(&alive).unwrap();
    let res = d.join("res");
    let o = monovo(&[
        "synth",
        "results",
        "-o",
        res.to_str().unwrap(),
        "--sequences",
        "2",
        "--runs",
        "1",
        "--frames",
        "200",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!dead_dir.exists() && alive.exists());
    let o = monovo(&[
        "eval-batch",
        "--dataset",
        res.join("dataset").to_str().unwrap(),
        "--results",
        res.join("results").to_str().unwrap(),
        "-o",
        d.join("r.csv").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!dead_file.exists());
    assert_eq!(
        temporaries(&d),
        vec![alive.file_name().unwrap().to_string_lossy().into_owned()]
    );
}

/// A small results tree and its results.csv.
fn results(d: &Path) -> (PathBuf, PathBuf) {
    let res = d.join("res");
    let o = monovo(&[
        "synth",
        "results",
        "-o",
        res.to_str().unwrap(),
        "--sequences",
        "3",
        "--runs",
        "1",
        "--frames",
        "200",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = d.join("results.csv");
    let o = monovo(&[
        "eval-batch",
        "--dataset",
        res.join("dataset").to_str().unwrap(),
        "--results",
        res.join("results").to_str().unwrap(),
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    (res, csv)
}

#[test]
fn every_writer_refuses_an_existing_output_without_force() {
    let d = temp_dir("terminal_overwrite");
    let (res, csv) = results(&d);
    let existing = d.join("existing.png");
    std::fs::write(&existing, "precious").unwrap();
    let md = d.join("existing.md");
    std::fs::write(&md, "precious").unwrap();
    let dataset = res.join("dataset");
    let results = res.join("results");
    let gt = dataset.join("sequence_01/groundtruthSync.txt");
    let run = results.join("direct/sequence_01/fwd_0.txt");
    let commands: Vec<Vec<&str>> = vec![
        vec![
            "eval-batch",
            "--dataset",
            dataset.to_str().unwrap(),
            "--results",
            results.to_str().unwrap(),
            "-o",
            md.to_str().unwrap(),
        ],
        vec![
            "plot",
            "cumulative",
            csv.to_str().unwrap(),
            "-o",
            existing.to_str().unwrap(),
        ],
        vec![
            "plot",
            "table",
            csv.to_str().unwrap(),
            "-o",
            md.to_str().unwrap(),
        ],
        vec![
            "eval",
            run.to_str().unwrap(),
            "--gt",
            gt.to_str().unwrap(),
            "--plot",
            existing.to_str().unwrap(),
        ],
        vec![
            "calib",
            "response",
            dataset.to_str().unwrap(),
            "-o",
            md.to_str().unwrap(),
        ],
        vec![
            "calib",
            "vignette",
            dataset.to_str().unwrap(),
            "-o",
            existing.to_str().unwrap(),
        ],
        vec!["synth", "results", "-o", res.to_str().unwrap()],
        vec![
            "rectify",
            dataset.to_str().unwrap(),
            "-o",
            res.to_str().unwrap(),
        ],
        vec!["demo", "-o", res.to_str().unwrap()],
    ];
    for args in &commands {
        let o = monovo(args);
        let e = stderr(&o);
        assert!(!o.status.success(), "{args:?} replaced an existing output");
        assert!(
            e.contains("already exists") && e.contains("--force"),
            "{args:?}: {e}"
        );
    }
    assert_eq!(std::fs::read_to_string(&existing).unwrap(), "precious");
    assert_eq!(std::fs::read_to_string(&md).unwrap(), "precious");
    // with --force they replace it
    let o = monovo(&[
        "plot",
        "table",
        csv.to_str().unwrap(),
        "-o",
        md.to_str().unwrap(),
        "--force",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read_to_string(&md)
        .unwrap()
        .contains("| sequence |"));
    let o = monovo(&[
        "plot",
        "cumulative",
        csv.to_str().unwrap(),
        "-o",
        existing.to_str().unwrap(),
        "--force",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // the demo replaces only what an earlier demo wrote, even with --force
    let o = monovo(&["demo", "-o", res.to_str().unwrap(), "--force"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("not written by `monovo demo`"),
        "{}",
        stderr(&o)
    );
    assert!(temporaries(&d).is_empty(), "{:?}", temporaries(&d));
}

#[test]
fn output_locations_are_checked_before_any_work() {
    let d = temp_dir("terminal_missing_folder");
    let missing = d.join("missing/dir");
    let out = |name: &str| missing.join(name).to_string_lossy().into_owned();
    // the inputs do not exist either: the output is what must be named
    let nowhere = d.join("no-input").to_string_lossy().into_owned();
    let commands: Vec<Vec<String>> = vec![
        vec![
            "calib".into(),
            "response".into(),
            nowhere.clone(),
            "-o".into(),
            out("p.txt"),
        ],
        vec![
            "calib".into(),
            "vignette".into(),
            nowhere.clone(),
            "-o".into(),
            out("v.png"),
        ],
        vec!["rectify".into(), nowhere.clone(), "-o".into(), out("seq")],
        vec!["synth".into(), "sweep".into(), "-o".into(), out("sweep")],
        vec!["demo".into(), "-o".into(), out("demo")],
        vec![
            "eval-batch".into(),
            "--dataset".into(),
            nowhere.clone(),
            "--results".into(),
            nowhere.clone(),
            "-o".into(),
            out("r.csv"),
        ],
        vec![
            "plot".into(),
            "cumulative".into(),
            nowhere.clone(),
            "-o".into(),
            out("c.png"),
        ],
        vec![
            "plot".into(),
            "table".into(),
            nowhere.clone(),
            "-o".into(),
            out("t.md"),
        ],
        vec![
            "eval".into(),
            nowhere.clone(),
            "--gt".into(),
            nowhere.clone(),
            "--plot".into(),
            out("a.png"),
        ],
    ];
    for args in &commands {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let t = Instant::now();
        let o = monovo(&a);
        let e = stderr(&o);
        assert!(!o.status.success(), "{a:?}");
        assert!(
            e.contains("missing/dir") && e.contains("does not exist") && !e.contains("no-input"),
            "{a:?}: {e}"
        );
        assert!(t.elapsed() < Duration::from_secs(20), "{a:?} worked first");
    }
    // a folder that refuses new files (not for root, whom permissions do not stop)
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = d.join("read-only");
        std::fs::create_dir(&ro).unwrap();
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        if std::fs::write(ro.join("probe"), "x").is_err() {
            let o = monovo(&[
                "calib",
                "response",
                &nowhere,
                "-o",
                ro.join("p.txt").to_str().unwrap(),
            ]);
            let e = stderr(&o);
            assert!(!o.status.success());
            assert!(e.contains("cannot write") && !e.contains("no-input"), "{e}");
            assert_eq!(e.matches("os error").count(), 1, "the OS error once: {e}");
        }
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
}

#[test]
fn a_closed_pipe_ends_the_output_quietly() {
    let d = temp_dir("terminal_pipe");
    // a results.csv whose table is far larger than a pipe's buffer
    let mut csv =
        String::from("method,sequence,direction,run,status,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end,poses\n");
    for s in 0..3000 {
        csv.push_str(&format!(
            "dso,sequence_{s:04},fwd,0,ok,0.5,1.01,0.3,0.2,0.1,0.01,0.01,100\n"
        ));
    }
    let p = d.join("big.csv");
    std::fs::write(&p, csv).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_monovo"))
        .args(["plot", "table", p.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        let mut first = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut first)
            .unwrap();
        assert!(first.contains("median"), "{first}");
    } // the reader goes away, like `| head -1`
    let out = child.wait_with_output().unwrap();
    let e = stderr(&out);
    assert!(out.status.success(), "{e}");
    assert!(!e.contains("panicked") && e.is_empty(), "{e}");
}

#[test]
fn no_progress_output_when_stderr_is_not_a_terminal() {
    let d = temp_dir("terminal_progress");
    let seq = many_frames(&d, 4);
    let o = monovo(&[
        "rectify",
        seq.to_str().unwrap(),
        "-o",
        d.join("out").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stderr(&o), "", "stderr is a pipe: no progress bar");
    assert!(stdout(&o).contains("frames/s"), "{}", stdout(&o));
}
