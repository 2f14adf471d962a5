//! The layout of a benchmark evaluation: `DATASET/sequence_XX/groundtruthSync.txt` and
//! `RESULTS/METHOD/sequence_XX/DIR_RUN.txt` with `DIR` in {`fwd`, `bwd`} and `RUN` a number.

use std::path::{Path, PathBuf};

use crate::DatasetError;

/// One run file of a results tree.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub struct RunFile {
    /// Method (first folder level).
    pub method: String,
    /// Sequence (second folder level).
    pub sequence: String,
    /// `true` for `bwd_*` runs.
    pub backwards: bool,
    /// Run number.
    pub run: u32,
    /// The file.
    pub path: PathBuf,
}

/// A scanned results tree: the run files, sorted, and everything that does not fit the
/// layout (listed so that nothing is silently mixed in or dropped).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ResultsTree {
    /// Run files, sorted by method, sequence, direction and run.
    pub runs: Vec<RunFile>,
    /// Files and folders that do not fit the layout, with the reason.
    pub stray: Vec<(PathBuf, &'static str)>,
}

fn sorted_entries(dir: &Path) -> Result<Vec<std::fs::DirEntry>, DatasetError> {
    let rd = std::fs::read_dir(dir).map_err(|e| DatasetError::io(dir, e))?;
    let mut v = Vec::new();
    for e in rd {
        v.push(e.map_err(|e| DatasetError::io(dir, e))?);
    }
    v.sort_by_key(|e| e.file_name());
    Ok(v)
}

/// Parses a run file name `fwd_3.txt` / `bwd_12.txt`.
pub fn parse_run_name(name: &str) -> Option<(bool, u32)> {
    let stem = name.strip_suffix(".txt")?;
    let (dir, run) = stem.split_once('_')?;
    let backwards = match dir {
        "fwd" => false,
        "bwd" => true,
        _ => return None,
    };
    if run.is_empty() || !run.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((backwards, run.parse().ok()?))
}

/// Scans `RESULTS/METHOD/SEQUENCE/DIR_RUN.txt`.
pub fn scan_results(root: &Path) -> Result<ResultsTree, DatasetError> {
    if !root.is_dir() {
        return Err(DatasetError::invalid(root, "not a folder"));
    }
    let mut tree = ResultsTree::default();
    for m in sorted_entries(root)? {
        let mp = m.path();
        if !mp.is_dir() {
            tree.stray
                .push((mp, "a file where METHOD folders are expected"));
            continue;
        }
        let method = m.file_name().to_string_lossy().into_owned();
        for s in sorted_entries(&mp)? {
            let sp = s.path();
            if !sp.is_dir() {
                tree.stray
                    .push((sp, "a file where SEQUENCE folders are expected"));
                continue;
            }
            let sequence = s.file_name().to_string_lossy().into_owned();
            for f in sorted_entries(&sp)? {
                let fp = f.path();
                let name = f.file_name().to_string_lossy().into_owned();
                match parse_run_name(&name) {
                    Some((backwards, run)) if fp.is_file() => tree.runs.push(RunFile {
                        method: method.clone(),
                        sequence: sequence.clone(),
                        backwards,
                        run,
                        path: fp,
                    }),
                    _ => tree
                        .stray
                        .push((fp, "not a run file named fwd_N.txt or bwd_N.txt")),
                }
            }
        }
    }
    tree.runs.sort();
    Ok(tree)
}

/// The ground-truth files of a dataset folder: `(sequence, DATASET/sequence/groundtruthSync.txt)`
/// for every sequence folder that has one, sorted.
pub fn scan_ground_truths(dataset: &Path) -> Result<Vec<(String, PathBuf)>, DatasetError> {
    if !dataset.is_dir() {
        return Err(DatasetError::invalid(dataset, "not a folder"));
    }
    let mut out = Vec::new();
    for e in sorted_entries(dataset)? {
        let gt = e.path().join("groundtruthSync.txt");
        if gt.is_file() {
            out.push((e.file_name().to_string_lossy().into_owned(), gt));
        }
    }
    if out.is_empty() {
        return Err(DatasetError::invalid(
            dataset,
            "no SEQUENCE/groundtruthSync.txt below this folder",
        ));
    }
    Ok(out)
}
