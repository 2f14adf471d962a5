//! Atomic writes and results trees.
use dataset_io::{parse_run_name, scan_ground_truths, scan_results, write_atomic, DatasetError};

fn tmp(name: &str) -> crate::TempDir {
    crate::TempDir::new("it", name)
}

#[test]
fn atomic_write_replaces_and_leaves_no_temporary() {
    let d = tmp("atomic");
    let p = d.join("a.txt");
    write_atomic(&p, b"one").unwrap();
    write_atomic(&p, b"two").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"two");
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
    let e = write_atomic(&d.join("missing/b.txt"), b"x").unwrap_err();
    assert!(matches!(e, DatasetError::Invalid { .. }), "{e}");
    assert!(e.to_string().contains("missing"));
}

#[test]
fn results_tree_lists_runs_and_stray_files() {
    let d = tmp("tree");
    for (rel, content) in [
        ("res/dso/sequence_01/fwd_0.txt", "x"),
        ("res/dso/sequence_01/bwd_12.txt", "x"),
        ("res/dso/sequence_02/fwd_1.txt", "x"),
        ("res/orb/sequence_01/fwd_0.txt", "x"),
        ("res/orb/sequence_01/fwd_0.txt.bak", "x"),
        ("res/orb/sequence_01/side_0.txt", "x"),
        ("res/README", "x"),
        ("res/orb/notes.txt", "x"),
        ("data/sequence_01/groundtruthSync.txt", "x"),
        ("data/sequence_02/groundtruthSync.txt", "x"),
        ("data/sequence_03/times.txt", "x"),
    ] {
        let p = d.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, content).unwrap();
    }
    let t = scan_results(&d.join("res")).unwrap();
    let names: Vec<_> = t
        .runs
        .iter()
        .map(|r| (r.method.as_str(), r.sequence.as_str(), r.backwards, r.run))
        .collect();
    assert_eq!(
        names,
        vec![
            ("dso", "sequence_01", false, 0),
            ("dso", "sequence_01", true, 12),
            ("dso", "sequence_02", false, 1),
            ("orb", "sequence_01", false, 0),
        ]
    );
    assert_eq!(t.stray.len(), 4, "{:?}", t.stray);
    let gts = scan_ground_truths(&d.join("data")).unwrap();
    assert_eq!(
        gts.iter().map(|g| g.0.as_str()).collect::<Vec<_>>(),
        vec!["sequence_01", "sequence_02"]
    );
    assert!(scan_ground_truths(&d.join("res")).is_err());
    assert!(scan_results(&d.join("nope")).is_err());
}

#[test]
fn run_names() {
    assert_eq!(parse_run_name("fwd_0.txt"), Some((false, 0)));
    assert_eq!(parse_run_name("bwd_42.txt"), Some((true, 42)));
    for bad in [
        "fwd_.txt",
        "fwd_1.csv",
        "fwd1.txt",
        "up_1.txt",
        "fwd_-1.txt",
        "fwd_1a.txt",
    ] {
        assert_eq!(parse_run_name(bad), None, "{bad}");
    }
}

#[test]
fn output_dir_appears_whole_or_not_at_all() {
    use dataset_io::OutputDir;
    let d = tmp("outdir");
    let target = d.join("out");
    {
        let o = OutputDir::create(&target, false).unwrap();
        std::fs::write(o.file("a/b.txt").unwrap(), "x").unwrap();
        // dropped without commit: nothing remains
    }
    assert!(!target.exists());
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0);
    let o = OutputDir::create(&target, false).unwrap();
    std::fs::write(o.file("a.txt").unwrap(), "1").unwrap();
    o.commit().unwrap();
    assert_eq!(std::fs::read_to_string(target.join("a.txt")).unwrap(), "1");
    assert!(matches!(
        OutputDir::create(&target, false),
        Err(DatasetError::Exists { .. })
    ));
    let o = OutputDir::create(&target, true).unwrap();
    std::fs::write(o.file("b.txt").unwrap(), "2").unwrap();
    o.commit().unwrap();
    assert!(!target.join("a.txt").exists() && target.join("b.txt").exists());
    assert!(OutputDir::create(&d.join("no/such/out"), false).is_err());
}

#[test]
fn temporaries_are_listed_while_in_flight_and_stale_ones_removed() {
    use dataset_io::OutputDir;
    let d = tmp("temporaries");
    let target = d.join("out");
    let o = OutputDir::create(&target, false).unwrap();
    assert!(dataset_io::temporaries_in_flight().contains(&o.path().to_path_buf()));
    let staging = o.path().to_path_buf();
    o.commit().unwrap();
    assert!(!dataset_io::temporaries_in_flight().contains(&staging));
    // a dead process's temporaries go, a running one's stay
    let dead = d.join(".out.tmp-4294967294-1");
    std::fs::create_dir_all(dead.join("x")).unwrap();
    let alive = d.join(format!(".out.tmp-{}-99", std::process::id()));
    std::fs::write(&alive, "x").unwrap();
    let other = d.join(".other.tmp-4294967294-1");
    std::fs::write(&other, "x").unwrap();
    let removed = dataset_io::remove_stale_temporaries(&target);
    assert_eq!(removed, vec![dead.clone()]);
    assert!(!dead.exists() && alive.exists() && other.exists());
    // checks before any work: existing, missing folder
    assert!(matches!(
        OutputDir::check(&target, false),
        Err(DatasetError::Exists { .. })
    ));
    assert!(OutputDir::check(&target, true).is_ok());
    let e = OutputDir::check(&d.join("no/such/out"), false).unwrap_err();
    assert!(e.to_string().contains("does not exist"), "{e}");
}

/// A scratch file reads back what was written at any offset and leaves nothing in its
/// folder, even while open; a folder that does not exist is an error that names it.
#[test]
fn scratch_file_leaves_nothing_behind() {
    let dir = tmp("scratch");
    let file = dataset_io::scratch_file(&dir).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileExt;
        file.write_all_at(b"samples", 1 << 20).unwrap();
        let mut back = [0u8; 7];
        file.read_exact_at(&mut back, 1 << 20).unwrap();
        assert_eq!(&back, b"samples");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
    }
    drop(file);
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
    let missing = dir.join("missing");
    let e = dataset_io::scratch_file(&missing).unwrap_err();
    assert!(e.to_string().contains("missing"), "{e}");
}
