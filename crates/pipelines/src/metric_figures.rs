//! Figures of the trajectory metrics: the error over time or distance with its statistics,
//! next to the aligned trajectories seen from above; the KITTI errors per segment length.

use eval_metrics::principal_plane;
use monovo_figures::{Chart, Corner, Figure, Panel, Series, PALETTE};
use nalgebra::Vector3;

use crate::traj_metrics::{KittiReport, MetricReport};

/// The x axis of the error chart (evo's `--plot_x_dimension`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlotX {
    /// Seconds from the first compared pose (evo's default).
    #[default]
    Seconds,
    /// Distance travelled along the reference.
    Distances,
    /// Index of the error.
    Index,
}

/// Top-down coordinates: the plane of largest spread of `basis`.
fn projector(basis: &[Vector3<f64>]) -> impl Fn(&Vector3<f64>) -> [f64; 2] {
    let (ax, ay) = principal_plane(basis);
    move |p: &Vector3<f64>| [p.dot(&ax), p.dot(&ay)]
}

/// A horizontal line across `[x0, x1]`.
fn hline(label: String, y: f64, x0: f64, x1: f64, color: [u8; 3]) -> Series {
    Series::line(label, vec![[x0, y], [x1, y]], color).dashed()
}

/// The error chart and the trajectories of an APE or RPE report.
pub fn metric_figure(r: &MetricReport, x: PlotX) -> Figure {
    let p = &r.plot;
    let (xs, x_label): (Vec<f64>, &str) = match x {
        PlotX::Seconds if p.seconds.len() == p.errors.len() => (p.seconds.clone(), "t (s)"),
        PlotX::Distances if p.distances.len() == p.errors.len() => (p.distances.clone(), "d (m)"),
        _ => ((0..p.errors.len()).map(|i| i as f64).collect(), "index"),
    };
    let name = if r.metric == "ape" { "APE" } else { "RPE" };
    let y_label = format!("{name} ({})", r.unit);
    // the title's lines: the metric, for RPE the pairs, then the alignment
    let lines: Vec<&str> = r
        .title
        .lines()
        .map(|l| {
            l.strip_prefix('(')
                .and_then(|x| x.strip_suffix(')'))
                .unwrap_or(l)
        })
        .collect();
    let (head, tail) = if r.metric == "rpe" && lines.len() > 1 {
        (
            format!("{}, {}", lines[0], lines[1].trim_start_matches("for ")),
            &lines[2..],
        )
    } else {
        (
            lines.first().map_or(String::new(), |l| l.to_string()),
            &lines[1.min(lines.len())..],
        )
    };
    let mut err = Chart::new(head, x_label, y_label.clone());
    let pts: Vec<[f64; 2]> = xs.iter().zip(&p.errors).map(|(a, b)| [*a, *b]).collect();
    let (x0, x1) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let st = &r.stats;
    if x0.is_finite() && x1 >= x0 {
        err.series.push(Series::band(
            format!("mean ± std ({:.4})", st.std),
            vec![[x0, st.mean - st.std], [x1, st.mean - st.std]],
            vec![[x0, st.mean + st.std], [x1, st.mean + st.std]],
            PALETTE[7],
        ));
    }
    let mut line = Series::line(name, pts, PALETTE[7]);
    line.width = 1.5;
    err.series.push(line);
    if x0.is_finite() && x1 >= x0 {
        err.series.push(hline(
            format!("rmse {:.4}", st.rmse),
            st.rmse,
            x0,
            x1,
            PALETTE[1],
        ));
        err.series.push(hline(
            format!("mean {:.4}", st.mean),
            st.mean,
            x0,
            x1,
            PALETTE[0],
        ));
        err.series.push(
            hline(
                format!("median {:.4}", st.median),
                st.median,
                x0,
                x1,
                PALETTE[2],
            )
            .dotted(),
        );
    }
    err.legend = Some(Corner::TopRight);
    let proj = projector(&p.reference);
    let mut map = Chart::new(
        if tail.is_empty() {
            "top-down view".to_string()
        } else {
            format!("top-down view, {}", tail.join(", "))
        },
        "top-down x (m)",
        "top-down y (m)",
    );
    map.equal_aspect = true;
    let mut gt = Series::line(
        "reference",
        p.reference.iter().map(&proj).collect(),
        PALETTE[7],
    )
    .dashed();
    gt.width = 2.5;
    map.series.push(gt);
    map.series.push(Series::line(
        "estimate (aligned)",
        p.estimate.iter().map(&proj).collect(),
        PALETTE[0],
    ));
    map.legend = Some(Corner::TopRight);
    Figure {
        width: 1500,
        height: 560,
        panels: vec![
            (Panel::Chart(err), [0.0, 0.0, 0.58, 1.0]),
            (Panel::Chart(map), [0.58, 0.0, 0.42, 1.0]),
        ],
    }
}

/// The KITTI errors per segment length (translation and rotation) and the paths seen from
/// above (x and z, as the devkit draws them).
pub fn kitti_figure(r: &KittiReport) -> Figure {
    let mut t = Chart::new(
        format!("translation error (mean {:.3} %)", r.t_err_percent),
        "path length (m)",
        "translation error (%)",
    );
    t.series.push(marked(Series::line(
        "translation error",
        r.lengths
            .iter()
            .map(|l| [l.length, l.t_err_percent])
            .collect(),
        PALETTE[0],
    )));
    t.legend = None;
    let mut rot = Chart::new(
        format!("rotation error (mean {:.3} deg/100m)", r.r_err_deg_per_100m),
        "path length (m)",
        "rotation error (deg/100m)",
    );
    rot.series.push(marked(Series::line(
        "rotation error",
        r.lengths
            .iter()
            .map(|l| [l.length, l.r_err_deg_per_100m])
            .collect(),
        PALETTE[1],
    )));
    rot.legend = None;
    for c in [&mut t, &mut rot] {
        c.x_range = Some([50.0, 850.0]);
        let ymax = c
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p[1]))
            .fold(0.0f64, f64::max);
        c.y_range = Some([0.0, (ymax * 1.15).max(1e-6)]);
    }
    let mut path = Chart::new("paths (x, z)", "x (m)", "z (m)");
    path.equal_aspect = true;
    for (k, [g, e]) in r.paths.iter().enumerate() {
        let label = |s: &str| if k == 0 { s.to_string() } else { String::new() };
        let mut gs = Series::line(
            label("ground truth"),
            g.iter().map(|p| [p[0], p[2]]).collect(),
            PALETTE[7],
        )
        .dashed();
        gs.width = 2.5;
        path.series.push(gs);
        path.series.push(Series::line(
            label("estimate"),
            e.iter().map(|p| [p[0], p[2]]).collect(),
            PALETTE[0],
        ));
    }
    path.legend = Some(Corner::TopRight);
    Figure {
        width: 1500,
        height: 520,
        panels: vec![
            (Panel::Chart(t), [0.0, 0.0, 0.3, 1.0]),
            (Panel::Chart(rot), [0.3, 0.0, 0.3, 1.0]),
            (Panel::Chart(path), [0.6, 0.0, 0.4, 1.0]),
        ],
    }
}

/// The same line with a filled circle at every point.
fn marked(mut s: Series) -> Series {
    s.marker = Some(4.0);
    s
}
