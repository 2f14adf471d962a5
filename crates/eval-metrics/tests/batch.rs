//! Batch evaluation, results.csv, tables and cumulative curves.
use crate::common::{gt_of, path, run};
use eval_metrics::{
    cumulative, evaluate_batch, markdown_table, parse_csv, summarize, write_csv, Direction,
    DirectionFilter, Metric, Metrics, RunKey, RunRecord, Stat,
};
use synthetic::trajectory::{Drift, EstimateConfig};

fn records() -> Vec<eval_metrics::RunRecord> {
    let p = path(21, 400);
    let gt = gt_of(&p);
    let mut jobs = Vec::new();
    for method in ["good", "bad"] {
        for dir in [Direction::Forward, Direction::Backward] {
            for r in 0..3u32 {
                jobs.push((method, dir, r));
            }
        }
    }
    let out = evaluate_batch(
        &jobs,
        |(m, d, r)| RunKey {
            method: m.to_string(),
            sequence: "sequence_01".into(),
            direction: *d,
            run: *r,
        },
        |(m, d, r)| -> Result<_, String> {
            let factor = if *m == "good" { 0.95 } else { 0.5 };
            let cfg = EstimateConfig {
                drift: Drift {
                    scale_jumps: vec![(200, factor)],
                    ..Drift::default()
                },
                backwards: *d == Direction::Backward,
                lost_after: (*m == "bad" && *r == 2).then_some(100),
                ..EstimateConfig::default()
            };
            Ok(run(&p, &cfg, *r as u64))
        },
        |_| Some(&gt),
        || {},
    );
    out.into_iter().map(|r| r.unwrap()).collect()
}

#[test]
fn batch_results_are_in_job_order_and_failures_count() {
    let recs = records();
    assert_eq!(recs.len(), 12);
    assert_eq!(recs[0].key.method, "good");
    assert_eq!(recs[11].key.run, 2);
    let failed: Vec<_> = recs.iter().filter(|r| !r.is_ok()).collect();
    assert_eq!(failed.len(), 2);
    assert!(failed
        .iter()
        .all(|r| r.key.method == "bad" && r.key.run == 2));
}

#[test]
fn csv_round_trips() {
    let recs = records();
    let text = write_csv(&recs);
    assert!(text.starts_with(
        "method,sequence,direction,run,status,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end,poses,reason\n"
    ));
    assert!(text.contains(",failed,inf,"));
    // the failure reason is written, not just the status
    assert!(text.contains("end segment has 0 pose(s)"), "{text}");
    let back = parse_csv(&text).unwrap();
    assert_eq!(back, recs);
    let e = parse_csv("method,sequence\nx,y\n").unwrap_err();
    assert!(e.to_string().contains("line 1"), "{e}");
    let bad = text.replacen(",fwd,", ",sideways,", 1);
    let e = parse_csv(&bad).unwrap_err();
    assert!(e.to_string().contains("line 2"), "{e}");
}

/// Names and reasons with commas, quotes and line breaks survive a write and a read; a
/// failed run read from a file without a reason column gets an empty reason, not an
/// invented one; columns may come in any order.
#[test]
fn csv_round_trips_awkward_fields() {
    let key = |method: &str, sequence: &str, run| RunKey {
        method: method.into(),
        sequence: sequence.into(),
        direction: Direction::Backward,
        run,
    };
    let recs = vec![
        RunRecord {
            key: key("DSO, \"fast\" mode", "sequence_01", 0),
            failure: Some(
                "line 3: expected 8 numbers, found `1,2\n3`\nsecond line \"quoted\"".into(),
            ),
            metrics: Metrics::FAILED,
            poses: 0,
            extra: Default::default(),
        },
        RunRecord {
            key: key("ORB\nSLAM", "seq \"x\", y", 4),
            failure: None,
            metrics: Metrics {
                e_align: 0.1,
                e_s: 1.0 / 3.0,
                e_r: 1e-300,
                e_t: 12345.678,
                e_rmse: f64::MIN_POSITIVE,
                rmse_start: 0.0,
                rmse_end: 2.5e-7,
            },
            poses: 17,
            extra: Default::default(),
        },
        RunRecord {
            key: key("", " padded ", 1),
            failure: Some(String::new()),
            metrics: Metrics {
                rmse_start: 0.25,
                ..Metrics::FAILED
            },
            poses: 3,
            extra: Default::default(),
        },
    ];
    let text = write_csv(&recs);
    let back = parse_csv(&text).unwrap();
    assert_eq!(back, recs, "{text}");

    let old = "poses,status,method,sequence,direction,run,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end\n\
               5,failed,m,s,fwd,0,inf,inf,inf,inf,inf,0.5,inf\n\
               6,ok,m,s,bwd,1,1,2,3,4,5,6,7\n";
    let rows = parse_csv(old).unwrap();
    assert_eq!(rows[0].failure.as_deref(), Some(""));
    assert_eq!(rows[0].metrics.rmse_start, 0.5);
    assert_eq!(rows[0].poses, 5);
    assert_eq!(rows[1].failure, None);
    assert_eq!(rows[1].metrics.rmse_end, 7.0);
    let e = parse_csv("method,sequence,direction,run,status,e_align,e_s,e_r,e_t,e_rmse,rmse_start,rmse_end,poses\nm,s,fwd,0,maybe,1,1,1,1,1,1,1,1\n")
        .unwrap_err();
    assert!(
        e.to_string().starts_with("line 2: ") && e.to_string().contains("`maybe`"),
        "{e}"
    );
}

#[test]
fn summaries_and_cumulative_curves() {
    let recs = records();
    let s = summarize(&recs, false);
    assert_eq!(s.len(), 2);
    let good = s.iter().find(|x| x.method == "good").unwrap();
    assert_eq!((good.runs, good.failed), (6, 0));
    let bad = s.iter().find(|x| x.method == "bad").unwrap();
    assert_eq!(bad.failed, 2);
    assert!(bad.e_align.max.is_infinite());
    let split = summarize(&recs, true);
    assert_eq!(split.len(), 4);
    let curves = cumulative(&recs, Metric::ES, DirectionFilter::Both);
    assert_eq!(curves.len(), 2);
    let g = curves.iter().find(|c| c.label == "good").unwrap();
    assert_eq!((g.values.len(), g.runs), (6, 6));
    // e'_s = max(e_s, 1/e_s): forwards 0.95 -> 1/0.95, backwards 1/0.95 -> 1/0.95
    assert!(g.values.iter().all(|v| (v - 1.0 / 0.95).abs() < 1e-6));
    assert_eq!(g.count_at(1.06), 6);
    assert_eq!(g.count_at(1.0), 0);
    let b = curves.iter().find(|c| c.label == "bad").unwrap();
    assert_eq!((b.values.len(), b.runs), (4, 6));
    let split = cumulative(&recs, Metric::EAlign, DirectionFilter::Split);
    assert_eq!(split.len(), 4);
    assert!(split.iter().any(|c| c.label == "good (bwd)"));
    assert_eq!(
        cumulative(&recs, Metric::EAlign, DirectionFilter::Forward)
            .iter()
            .map(|c| c.runs)
            .sum::<usize>(),
        6
    );
    let table = markdown_table(&s);
    assert!(
        table.contains("| sequence | method | runs | failed | e_align | e_r (deg) | e'_s (x) |"),
        "{table}"
    );
    assert!(table.contains("| sequence_01 | bad |") && table.contains("∞"));
    assert!(!table.contains("<br>"));
    let text = eval_metrics::summary_table(&s, eval_metrics::TableStyle::Text);
    assert!(
        !text.contains('|') && !text.contains("<br>") && text.contains("inf"),
        "{text}"
    );
    // e'_s = max(e_s, 1/e_s): a shrinking scale drift summarises as a multiplier above 1
    assert!(s.iter().all(|x| x.e_s_prime.min >= 1.0), "{s:?}");
}

#[test]
fn median_min_max_count_failures_as_infinite() {
    let s = Stat::of(&[3.0, 1.0, f64::INFINITY, 2.0]).unwrap();
    assert_eq!((s.median, s.min), (2.5, 1.0));
    assert!(s.max.is_infinite());
    let s = Stat::of(&[1.0, f64::INFINITY]).unwrap();
    assert!(s.median.is_infinite());
    assert_eq!(Stat::of(&[4.0]).unwrap().median, 4.0);
    assert!(Stat::of(&[]).is_none());
}
