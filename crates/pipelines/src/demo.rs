//! The parts of `monovo demo` that do not generate or calibrate data: its folder check, the
//! evaluation stage (results tree, the paper's plots, metric study, alignment figure,
//! table), frame previews and the list of what it wrote.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use camera_model::{Image, Intrinsics};
use dataset_io::{OutputDir, Sequence};
use eval_metrics::{evaluate, summarize, DirectionFilter, Metric, RunRecord};
use monovo_figures::Figure;

use crate::paper::{
    cumulative_chart, medians_markdown, method_medians, metric_study_figure, MethodMedians,
};
use crate::{evaluate_tree, load_ground_truth, load_trajectory, save_alignment_figure};
use crate::{BatchOptions, Observer, PipelineError, Result};

/// Marks a folder as written by `monovo demo`, so that a later demo may replace it.
pub const MARKER: &str = ".monovo-demo";

/// Checks the demo's folder before any work: it must not exist, or (with `force`) have been
/// written by an earlier demo, or be empty.
pub fn check_demo_target(target: &Path, force: bool) -> Result<()> {
    OutputDir::check(target, force)?;
    if target.exists() {
        let earlier_demo = target.join(MARKER).is_file();
        let empty = std::fs::read_dir(target)
            .map(|mut d| d.next().is_none())
            .unwrap_or(false);
        if !earlier_demo && !empty {
            return Err(PipelineError::Invalid(format!(
                "{}: exists and was not written by `monovo demo`; refusing to replace it even with --force (choose another folder with -o)",
                target.display()
            )));
        }
    }
    Ok(())
}

/// The evaluation stage of the demo.
#[derive(Debug)]
pub struct DemoEvaluation {
    /// The evaluated runs.
    pub records: Vec<RunRecord>,
    /// Seconds spent evaluating.
    pub seconds: f64,
    /// Medians per method.
    pub medians: Vec<MethodMedians>,
}

/// Evaluates `dir/benchmark` into `dir/results.csv`.
pub fn evaluate_benchmark(dir: &Path, observer: &dyn Observer) -> Result<DemoEvaluation> {
    let batch = evaluate_tree(
        &BatchOptions {
            dataset: dir.join("benchmark/dataset"),
            results: dir.join("benchmark/results"),
            output: Some(dir.join("results.csv")),
            force: false,
            keep_going: false,
            extra: Vec::new(),
        },
        observer,
    )?;
    Ok(DemoEvaluation {
        medians: method_medians(&batch.records),
        records: batch.records,
        seconds: batch.seconds,
    })
}

impl DemoEvaluation {
    /// Draws the paper's cumulative plots, the metric study (from `seed`), the alignment
    /// figure of one run and `table.md` into `dir`.
    pub fn draw(&self, dir: &Path, seed: u64) -> Result<()> {
        let records = &self.records;
        for (metric, file, split) in [
            (
                Metric::EAlign,
                "cumulative_e_align.png",
                DirectionFilter::Both,
            ),
            (Metric::ER, "cumulative_e_r.png", DirectionFilter::Both),
            (Metric::ES, "cumulative_e_s.png", DirectionFilter::Split),
        ] {
            let chart = cumulative_chart(records, metric, split);
            monovo_figures::save(&Figure::single(chart, 900, 600), &dir.join(file))?;
        }
        monovo_figures::save(&metric_study_figure(seed)?, &dir.join("metric_study.png"))?;
        let gt = load_ground_truth(&dir.join("benchmark/dataset/sequence_01/groundtruthSync.txt"))?;
        let run = load_trajectory(
            &dir.join("benchmark/results/feature/sequence_01/fwd_0.txt"),
            None,
            None,
        )?;
        let ev = evaluate(&run, &gt);
        if ev.is_ok() {
            save_alignment_figure(&ev, &gt, &dir.join("alignment.png"))?;
        }
        let table = eval_metrics::markdown_table(&summarize(records, false));
        dataset_io::write_atomic(&dir.join("table.md"), table.as_bytes())?;
        Ok(())
    }

    /// The evaluation section of summary.md.
    pub fn markdown(&self) -> String {
        format!(
            "## Evaluation\n\n{} runs (2 methods x 50 sequences x fwd/bwd x 5 runs) evaluated in {:.2} s.\n\n{}\n\
             ![e_align](cumulative_e_align.png)\n![e_r](cumulative_e_r.png)\n![e_s](cumulative_e_s.png)\n\n\
             The paper's metric study on one synthetic sequence: e_align depends much less on where the drift happens than e_t and e_rmse.\n\n\
             ![metric study](metric_study.png)\n\n![alignment](alignment.png)\n\nPer-sequence table: [table.md](table.md).\n",
            self.records.len(),
            self.seconds,
            medians_markdown(&self.medians)
        )
    }
}

/// Writes the middle frame of `dir/sequence` as `frame_raw.png` and of `dir/rectified`
/// (stretched for viewing: square root of the linear values) as `frame_rectified.png`;
/// returns the rectified camera.
pub fn write_frame_previews(dir: &Path) -> Result<Intrinsics> {
    let rect = Sequence::open(&dir.join("rectified"))?;
    let k = rect
        .camera()
        .map(|c| c.input.intrinsics())
        .ok_or_else(|| PipelineError::Invalid("the rectified sequence has no camera.txt".into()))?;
    let mid = rect.len() / 2;
    let raw = Sequence::open(&dir.join("sequence"))?.decode(mid)?;
    let png = |name: &str, img: &Image<u8>| {
        dataset_io::write_png_u8(
            &dir.join(name),
            img.width(),
            img.height(),
            1,
            img.data(),
            dataset_io::PngSpeed::Default,
        )
    };
    png("frame_raw.png", &raw)?;
    let rect_mid = rect.decode(mid)?;
    let max = rect_mid.data().iter().copied().max().unwrap_or(1).max(1) as f32;
    png(
        "frame_rectified.png",
        &rect_mid.map(|v| ((v as f32 / max).sqrt() * 255.0) as u8),
    )?;
    Ok(k)
}

/// What the demo writes, with a description of each.
pub const DEMO_FILES: [(&str, &str); 10] = [
    ("summary.md", "the report, with every figure"),
    ("table.md", "the paper's per-sequence table"),
    ("results.csv", "1000 evaluated runs"),
    ("cumulative_e_align.png", "cumulative plots (also e_r, e_s)"),
    ("metric_study.png", "where drift happens vs. the metrics"),
    ("alignment.png", "start- and end-aligned trajectory"),
    ("response.png", "calibrated response vs. truth"),
    ("vignette.png", "calibrated vignette vs. truth"),
    ("frame_raw.png", "a raw frame (and frame_rectified.png)"),
    (
        "sequence/",
        "the synthetic sequence (rectified/: corrected)",
    ),
];

/// The demo's files in `dir`.
pub fn demo_files(dir: &Path) -> Vec<PathBuf> {
    DEMO_FILES.iter().map(|(f, _)| dir.join(f)).collect()
}

/// The demo's files in `dir` with their descriptions, one per line, indented by two spaces.
pub fn demo_files_text(dir: &Path) -> String {
    let shown: Vec<(String, &str)> = DEMO_FILES
        .iter()
        .map(|(f, what)| (dir.join(f).display().to_string(), *what))
        .collect();
    let w = shown.iter().map(|(f, _)| f.len()).max().unwrap_or(0);
    let mut s = String::new();
    for (f, what) in &shown {
        let _ = writeln!(s, "  {f:<w$}  {what}");
    }
    s
}
