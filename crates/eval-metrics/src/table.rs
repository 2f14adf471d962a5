//! The paper's per-sequence table (its Table 2: median, minimum and maximum over the runs)
//! as aligned plain text for a terminal or as a markdown table: one row per sequence and
//! method (and direction, when split), with `e_align`, `e_r` in degrees and
//! `e'_s = max(e_s, 1/e_s)` as a multiplier; failed runs count as infinite.

use crate::batch::{SequenceSummary, Stat};

/// How a summary table is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TableStyle {
    /// Columns aligned with spaces, ASCII only (`inf` for infinity).
    Text,
    /// A markdown (GitHub) table, `∞` for infinity.
    Markdown,
}

/// What the columns mean: the caption printed with every table.
pub const TABLE_CAPTION: &str = "median (min-max) over the runs; failed runs count as infinite.
e_align: alignment error, in the ground truth's units; e_r: rotation drift, in degrees;
e'_s = max(e_s, 1/e_s): scale drift as a multiplier (1: none).";

fn num(v: f64, digits: usize, style: TableStyle) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else if style == TableStyle::Markdown {
        "∞".into()
    } else {
        "inf".into()
    }
}

fn stat(st: &Stat, digits: usize, style: TableStyle) -> String {
    let dash = if style == TableStyle::Markdown {
        "–"
    } else {
        "-"
    };
    format!(
        "{} ({}{dash}{})",
        num(st.median, digits, style),
        num(st.min, digits, style),
        num(st.max, digits, style)
    )
}

/// The header cells of the table.
const HEADER: [&str; 7] = [
    "sequence",
    "method",
    "runs",
    "failed",
    "e_align",
    "e_r (deg)",
    "e'_s (x)",
];

/// The cells of one summary row.
fn cells(s: &SequenceSummary, style: TableStyle) -> [String; 7] {
    let sequence = match s.direction {
        Some(d) => format!("{} ({d})", s.sequence),
        None => s.sequence.clone(),
    };
    [
        sequence,
        s.method.clone(),
        s.runs.to_string(),
        s.failed.to_string(),
        stat(&s.e_align, 3, style),
        stat(&s.e_r, 2, style),
        stat(&s.e_s_prime, 3, style),
    ]
}

/// The per-sequence table of some summaries (see [`crate::summarize`]), rows in the order
/// given, with [`TABLE_CAPTION`] above it.
///
/// ```
/// use eval_metrics::{summary_table, Stat, SequenceSummary, TableStyle};
///
/// let st = |m: f64| Stat { median: m, min: m, max: f64::INFINITY };
/// let s = SequenceSummary {
///     method: "dso".into(),
///     sequence: "sequence_01".into(),
///     direction: None,
///     runs: 10,
///     failed: 1,
///     e_align: st(0.5),
///     e_r: st(1.06),
///     e_s_prime: st(1.04),
/// };
/// let text = summary_table(&[s], TableStyle::Text);
/// assert!(text.contains("sequence_01  dso       10       1  0.500 (0.500-inf)"));
/// assert!(!text.contains("<br>"));
/// ```
pub fn summary_table(summaries: &[SequenceSummary], style: TableStyle) -> String {
    let rows: Vec<[String; 7]> = summaries.iter().map(|s| cells(s, style)).collect();
    let mut out = String::new();
    match style {
        TableStyle::Markdown => {
            out.push_str(&format!("{TABLE_CAPTION}\n\n"));
            out.push_str(&format!("| {} |\n", HEADER.join(" | ")));
            out.push_str("|---|---|--:|--:|---|---|---|\n");
            for r in &rows {
                out.push_str(&format!("| {} |\n", r.join(" | ")));
            }
        }
        TableStyle::Text => {
            let mut width = HEADER.map(|h| h.chars().count());
            for r in &rows {
                for (w, c) in width.iter_mut().zip(r) {
                    *w = (*w).max(c.chars().count());
                }
            }
            let line = |cells: &[&str]| -> String {
                let mut l = String::new();
                for (i, c) in cells.iter().enumerate() {
                    if i > 0 {
                        l.push_str("  ");
                    }
                    let pad = width[i].saturating_sub(c.chars().count());
                    // counts are right-aligned, text left-aligned
                    if i == 2 || i == 3 {
                        l.push_str(&" ".repeat(pad));
                        l.push_str(c);
                    } else {
                        l.push_str(c);
                        if i + 1 < cells.len() {
                            l.push_str(&" ".repeat(pad));
                        }
                    }
                }
                l.push('\n');
                l
            };
            out.push_str(&format!("{TABLE_CAPTION}\n\n"));
            out.push_str(&line(&HEADER));
            for r in &rows {
                let refs: Vec<&str> = r.iter().map(String::as_str).collect();
                out.push_str(&line(&refs));
            }
        }
    }
    out
}

/// The per-sequence table as markdown (see [`summary_table`]).
pub fn markdown_table(summaries: &[SequenceSummary]) -> String {
    summary_table(summaries, TableStyle::Markdown)
}
