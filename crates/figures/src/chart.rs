//! Line charts: the layout of the plot area, the axes and the series drawn on them.

use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axes::{
    category_label, chart_ranges, clip_polygon, visible_runs, AxisSpace, LogTicks, TickFormat,
    Ticks,
};
use crate::legend::{points_inside, Legend};
use crate::text::{titled, Scale, LABEL_PX, TICK_PX};
use crate::{color, plot_err, Chart, Corner, Result};

/// Margins and label areas of a chart, in back-end pixels.
pub(crate) struct ChartLayout {
    pub(crate) top: i32,
    pub(crate) right: i32,
    pub(crate) bottom: i32,
    pub(crate) left: i32,
    pub(crate) x_area: i32,
    pub(crate) y_area: i32,
}

impl ChartLayout {
    pub(crate) fn new(k: Scale) -> ChartLayout {
        ChartLayout {
            top: k.px(6.0),
            right: k.px(18.0),
            bottom: k.px(4.0),
            left: k.px(6.0),
            x_area: k.px(TICK_PX + LABEL_PX + 16.0),
            y_area: k.px(TICK_PX * 3.2 + LABEL_PX + 10.0),
        }
    }

    /// The plot rectangle `[x0, y0, x1, y1]` inside an area of size `(w, h)`.
    pub(crate) fn plot_rect(&self, w: i32, h: i32) -> [i32; 4] {
        [
            self.left + self.y_area,
            self.top,
            (w - self.right).max(self.left + self.y_area + 10),
            (h - self.bottom - self.x_area).max(self.top + 10),
        ]
    }
}

pub(crate) fn draw_chart<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    c: &Chart,
    k: Scale,
) -> Result<()> {
    let area = titled(area, &c.title, k)?;
    let (w, h) = area.dim_in_pixel();
    let (w, h) = (w as i32, h as i32);
    let mut layout = ChartLayout::new(k);
    let (mut xr, mut yr) = chart_ranges(c);
    let space = AxisSpace { x_log: c.x_log };
    let fit_aspect = |xr: &mut [f64; 2], yr: &mut [f64; 2], pr: [i32; 4]| {
        if c.equal_aspect && !c.x_log {
            equal_aspect(xr, yr, pr);
        }
    };
    let (ax0, ax1) = (
        space.to_axis([xr[0], 0.0])[0],
        space.to_axis([xr[1], 0.0])[0],
    );
    // legend: the preferred corner if it covers no data, else another free corner, else
    // below the chart
    let legend = Legend::of(&area, c, k)?;
    let mut legend_at: Option<((i32, i32), usize)> = None;
    if let Some(lg) = &legend {
        let pr = layout.plot_rect(w, h);
        fit_aspect(&mut xr, &mut yr, pr);
        let (lw, lh) = lg.size(k);
        let m = k.px(8.0);
        let pos = |corner: Corner| match corner {
            Corner::TopLeft => (pr[0] + m, pr[1] + m),
            Corner::TopRight => (pr[2] - m - lw, pr[1] + m),
            Corner::BottomRight => (pr[2] - m - lw, pr[3] - m - lh),
            Corner::BottomLeft => (pr[0] + m, pr[3] - m - lh),
        };
        let to_px = |p: [f64; 2]| -> Option<(f64, f64)> {
            if !space.valid(p) {
                return None;
            }
            let q = space.to_axis(p);
            let x0 = (ax0, ax1);
            let fx = (q[0] - x0.0) / (x0.1 - x0.0);
            let fy = (q[1] - yr[0]) / (yr[1] - yr[0]);
            Some((
                f64::from(pr[0]) + fx * f64::from(pr[2] - pr[0]),
                f64::from(pr[3]) - fy * f64::from(pr[3] - pr[1]),
            ))
        };
        let mut order = vec![c.legend.unwrap_or(Corner::TopLeft)];
        for corner in [
            Corner::TopLeft,
            Corner::TopRight,
            Corner::BottomRight,
            Corner::BottomLeft,
        ] {
            if !order.contains(&corner) {
                order.push(corner);
            }
        }
        let fits = lw < pr[2] - pr[0] - 2 * m && lh < pr[3] - pr[1] - 2 * m;
        let pad = f64::from(k.px(3.0));
        legend_at = order
            .into_iter()
            .map(pos)
            .find(|&(x, y)| {
                fits && points_inside(
                    c,
                    &to_px,
                    [
                        f64::from(x) - pad,
                        f64::from(y) - pad,
                        f64::from(x + lw) + pad,
                        f64::from(y + lh) + pad,
                    ],
                ) == 0
            })
            .map(|p| (p, 1));
        if legend_at.is_none() {
            // below the chart, in as many columns as fit
            let col_w = lw;
            let columns = (((w - layout.left - layout.y_area) / col_w.max(1)) as usize)
                .clamp(1, lg.entries.len());
            let rows = lg.entries.len().div_ceil(columns) as i32;
            let box_h = rows * lg.line_h + k.px(Legend::PAD);
            layout.bottom += box_h + k.px(6.0);
            let pr = layout.plot_rect(w, h);
            let x = pr[0] + ((pr[2] - pr[0]) - col_w * columns as i32).max(0) / 2;
            legend_at = Some(((x, h - layout.bottom + k.px(6.0)), columns));
            // the plot area shrank: refit the aspect from the original ranges
            let (x2, y2) = chart_ranges(c);
            xr = x2;
            yr = y2;
            fit_aspect(&mut xr, &mut yr, pr);
        }
    } else {
        fit_aspect(&mut xr, &mut yr, layout.plot_rect(w, h));
    }
    let mut builder = ChartBuilder::on(&area);
    builder
        .margin_top(layout.top)
        .margin_right(layout.right)
        .margin_bottom(layout.bottom)
        .margin_left(layout.left)
        .x_label_area_size(layout.x_area)
        .y_label_area_size(layout.y_area);
    let pr = layout.plot_rect(w, h);
    let (ticks, log_ticks) = chart_ticks(c, k, pr, xr, yr);
    let clip = [ax0, ax1, yr[0], yr[1]];
    if let Some(t) = log_ticks {
        let x_axis = (xr[0]..xr[1])
            .log_scale()
            .with_key_points(t.bold)
            .with_light_points(t.light);
        let mut chart = builder
            .build_cartesian_2d(x_axis, yr[0]..yr[1])
            .map_err(plot_err)?;
        draw_chart_body(&mut chart, c, k, ticks, space, clip)?;
    } else {
        let mut chart = builder
            .build_cartesian_2d(xr[0]..xr[1], yr[0]..yr[1])
            .map_err(plot_err)?;
        draw_chart_body(&mut chart, c, k, ticks, space, clip)?;
    }
    if let (Some(lg), Some((at, columns))) = (&legend, legend_at) {
        lg.draw(&area, at, k, columns)?;
    }
    Ok(())
}

/// Widens one of the ranges so that a unit is as long on both axes of the plot area `pr`.
fn equal_aspect(xr: &mut [f64; 2], yr: &mut [f64; 2], pr: [i32; 4]) {
    let (pw, ph) = (f64::from(pr[2] - pr[0]), f64::from(pr[3] - pr[1]));
    let sx = pw / (xr[1] - xr[0]);
    let sy = ph / (yr[1] - yr[0]);
    if sx > sy {
        let need = pw / sy;
        let mid = 0.5 * (xr[0] + xr[1]);
        *xr = [mid - need / 2.0, mid + need / 2.0];
    } else {
        let need = ph / sx;
        let mid = 0.5 * (yr[0] + yr[1]);
        *yr = [mid - need / 2.0, mid + need / 2.0];
    }
}

/// The ticks of a chart whose plot area is `pr`: as many labels as fit, whole numbers on an
/// integer y axis, and the logarithmic x axis's ticks.
fn chart_ticks(
    c: &Chart,
    k: Scale,
    pr: [i32; 4],
    xr: [f64; 2],
    yr: [f64; 2],
) -> (Ticks, Option<LogTicks>) {
    let x_labels = ((f64::from(pr[2] - pr[0]) / f64::from(k.px(65.0))) as usize).clamp(2, 12);
    let mut y_labels = ((f64::from(pr[3] - pr[1]) / f64::from(k.px(45.0))) as usize).clamp(2, 12);
    if c.y_integer {
        // fewer labels than whole numbers in the range: plotters' steps are then >= 1
        y_labels = y_labels.min((yr[1] - yr[0]).floor().max(1.0) as usize + 1);
    }
    let log_ticks = c.x_log.then(|| LogTicks::new(xr, x_labels));
    let ticks = Ticks {
        x: x_labels,
        y: y_labels,
        x_format: if let Some(t) = &log_ticks {
            t.format
        } else {
            TickFormat::linear(xr[1] - xr[0], x_labels)
        },
        y_format: if c.y_integer {
            TickFormat { step: 1.0 }
        } else {
            TickFormat::linear(yr[1] - yr[0], y_labels)
        },
    };
    (ticks, log_ticks)
}

pub(crate) fn draw_chart_body<DB, X>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, RangedCoordf64>>,
    c: &Chart,
    k: Scale,
    ticks: Ticks,
    space: AxisSpace,
    clip: [f64; 4],
) -> Result<()>
where
    DB: DrawingBackend,
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_labels(ticks.x)
        .y_labels(ticks.y)
        .x_label_formatter(&|v| {
            category_label(&c.x_categories, *v).unwrap_or_else(|| ticks.x_format.format(*v))
        })
        .y_label_formatter(&|v| ticks.y_format.format(*v))
        .x_desc(c.x_label.as_str())
        .y_desc(c.y_label.as_str())
        .label_style(k.font(TICK_PX))
        .axis_desc_style(k.font(LABEL_PX))
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(k.upx(1.0)))
        .light_line_style(RGBColor(242, 242, 242).stroke_width(k.upx(1.0)))
        .axis_style(BLACK.stroke_width(k.upx(1.0)))
        .set_all_tick_mark_size(k.px(4.0))
        .draw()
        .map_err(plot_err)?;
    for s in &c.series {
        if let Some(upper) = &s.band_upper {
            let poly: Vec<[f64; 2]> = s
                .points
                .iter()
                .chain(upper.iter().rev())
                .filter(|p| space.valid(**p))
                .map(|p| space.to_axis(*p))
                .collect();
            let poly = clip_polygon(poly, clip);
            if poly.len() >= 3 {
                let pts: Vec<(f64, f64)> = poly
                    .iter()
                    .map(|p| {
                        let d = space.to_data(*p);
                        (d[0], d[1])
                    })
                    .collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(pts, color(s.color).filled())))
                    .map_err(plot_err)?;
            }
            continue;
        }
        if let Some(r) = s.marker {
            let dots: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter(|p| space.valid(**p))
                .map(|p| space.to_axis(*p))
                .filter(|p| {
                    p[0] >= clip[0] && p[0] <= clip[1] && p[1] >= clip[2] && p[1] <= clip[3]
                })
                .map(|p| {
                    let d = space.to_data(p);
                    (d[0], d[1])
                })
                .collect();
            chart
                .draw_series(
                    dots.into_iter()
                        .map(|p| Circle::new(p, k.px(r), color(s.color).filled())),
                )
                .map_err(plot_err)?;
        }
        if s.width <= 0.0 {
            continue;
        }
        let style = color(s.color).stroke_width(k.upx(s.width));
        for run in visible_runs(&s.points, space, clip) {
            if s.dashed {
                chart
                    .draw_series(DashedLineSeries::new(
                        run,
                        k.px(s.dash[0]),
                        k.px(s.dash[1]),
                        style,
                    ))
                    .map_err(plot_err)?;
            } else {
                chart
                    .draw_series(LineSeries::new(run, style))
                    .map_err(plot_err)?;
            }
        }
    }
    // frame the plot area
    let (xs, ys) = (chart.x_range(), chart.y_range());
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(xs.start, ys.start), (xs.end, ys.end)],
            BLACK.stroke_width(k.upx(1.0)),
        )))
        .map_err(plot_err)?;
    Ok(())
}
