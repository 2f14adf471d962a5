//! Heat maps with a colour bar.

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::FontTransform;

use crate::axes::TickFormat;
use crate::chart::ChartLayout;
use crate::text::{titled, Scale, LABEL_PX, TICK_PX};
use crate::{color, colormap, plot_err, Heatmap, Result, Rgb};

// ------------------------------------------------------------------------------- heat maps

/// Cells on the longest side of a heat map in SVG files (rectangles, not a raster).
pub(crate) const SVG_HEATMAP_CELLS: usize = 120;

pub(crate) fn heat_color(h: &Heatmap, v: f32) -> Rgb {
    let span = (h.range[1] - h.range[0]).max(1e-12);
    if v.is_finite() {
        colormap((v - h.range[0]) / span)
    } else {
        [128, 128, 128]
    }
}

pub(crate) fn draw_heatmap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    h: &Heatmap,
    k: Scale,
    vector: bool,
) -> Result<()> {
    let area = titled(area, &h.title, k)?;
    let (aw, ah) = area.dim_in_pixel();
    let (aw, ah) = (aw as i32, ah as i32);
    let (fw, fh) = (h.width.max(1), h.height.max(1));
    let layout = ChartLayout::new(k);
    // the colour bar's ticks and their widest label
    let (r0, r1) = (f64::from(h.range[0]), f64::from(h.range[1]));
    let r1 = if r1 > r0 { r1 } else { r0 + 1e-12 };
    let bar_axis: RangedCoordf64 = (r0..r1).into();
    let bar_labels = ((f64::from(ah) / f64::from(k.px(60.0))) as usize).clamp(2, 8);
    let bar_format = TickFormat::linear(r1 - r0, bar_labels);
    let bar_ticks: Vec<(f64, String)> = bar_axis
        .key_points(bar_labels)
        .into_iter()
        .map(|v| (v, bar_format.format(v)))
        .collect();
    let tick_font = k.font(TICK_PX).pos(Pos::new(HPos::Left, VPos::Center));
    let mut tick_w = 0;
    for (_, t) in &bar_ticks {
        tick_w = tick_w.max(area.estimate_text_size(t, &tick_font).map_err(plot_err)?.0 as i32);
    }
    let (gap, bar_w, tick_len) = (k.px(14.0), k.px(16.0), k.px(4.0));
    let bar_total = gap + bar_w + tick_len + k.px(4.0) + tick_w + k.px(10.0) + k.px(LABEL_PX);
    // the largest map of the field's aspect that fits beside its axes and the colour bar
    let avail_w = aw - layout.left - layout.y_area - layout.right - bar_total;
    let avail_h = ah - layout.top - layout.bottom - layout.x_area;
    let scale = (f64::from(avail_w) / fw as f64)
        .min(f64::from(avail_h) / fh as f64)
        .max(1e-6);
    let (iw, ih) = (
        ((fw as f64 * scale).round() as i32).max(1),
        ((fh as f64 * scale).round() as i32).max(1),
    );
    // centre map and colour bar together
    let x0 = ((aw - (layout.y_area + iw + bar_total)) / 2).max(0);
    let sub = area.clone().shrink(
        (x0, layout.top),
        ((layout.y_area + iw) as u32, (ih + layout.x_area) as u32),
    );
    let mut chart = ChartBuilder::on(&sub)
        .x_label_area_size(layout.x_area)
        .y_label_area_size(layout.y_area)
        // rows grow downwards: the y axis shows -y
        .build_cartesian_2d(0f64..fw as f64, -(fh as f64)..0f64)
        .map_err(plot_err)?;
    let labels = |px: i32| ((f64::from(px) / f64::from(k.px(70.0))) as usize).clamp(2, 10);
    let (x_format, y_format) = (
        TickFormat::linear(fw as f64, labels(iw)),
        TickFormat::linear(fh as f64, labels(ih)),
    );
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(labels(iw))
        .y_labels(labels(ih))
        .x_label_formatter(&|v| x_format.format(*v))
        .y_label_formatter(&|v| y_format.format(-*v))
        .x_desc("x (pixels)")
        .y_desc("y (pixels)")
        .label_style(k.font(TICK_PX))
        .axis_desc_style(k.font(LABEL_PX))
        .axis_style(BLACK.stroke_width(k.upx(1.0)))
        .set_all_tick_mark_size(k.px(4.0))
        .draw()
        .map_err(plot_err)?;
    if vector {
        let cells = block_means(h, fw, fh);
        chart.draw_series(cells).map_err(plot_err)?;
    } else {
        // one sample per back-end pixel (nearest), blitted as a bitmap
        let (pw, ph) = (iw as usize, ih as usize);
        let rgb = nearest_pixels(h, fw, fh, pw, ph);
        if let Some(img) = BitMapElement::with_owned_buffer((0.0, 0.0), (pw as u32, ph as u32), rgb)
        {
            chart.plotting_area().draw(&img).map_err(plot_err)?;
        }
    }
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(0.0, 0.0), (fw as f64, -(fh as f64))],
            BLACK.stroke_width(k.upx(1.0)),
        )))
        .map_err(plot_err)?;
    // colour bar to the right of the map
    let bx = x0 + layout.y_area + iw + gap;
    let (by0, by1) = (layout.top, layout.top + ih);
    let steps = 128;
    for i in 0..steps {
        let t0 = i as f64 / steps as f64;
        let t1 = (i + 1) as f64 / steps as f64;
        let y_top = by1 - ((t1 * f64::from(ih)).round() as i32);
        let y_bot = by1 - ((t0 * f64::from(ih)).round() as i32);
        area.draw(&Rectangle::new(
            [(bx, y_top), (bx + bar_w, y_bot)],
            color(colormap(((t0 + t1) / 2.0) as f32)).filled(),
        ))
        .map_err(plot_err)?;
    }
    area.draw(&Rectangle::new(
        [(bx, by0), (bx + bar_w, by1)],
        BLACK.stroke_width(k.upx(1.0)),
    ))
    .map_err(plot_err)?;
    for (v, text) in bar_ticks {
        let y = by1 - (((v - r0) / (r1 - r0)) * f64::from(ih)).round() as i32;
        area.draw(&PathElement::new(
            vec![(bx + bar_w, y), (bx + bar_w + tick_len, y)],
            BLACK.stroke_width(k.upx(1.0)),
        ))
        .map_err(plot_err)?;
        area.draw(&Text::new(
            text,
            (bx + bar_w + tick_len + k.px(4.0), y),
            tick_font.clone(),
        ))
        .map_err(plot_err)?;
    }
    let label_font = k
        .font(LABEL_PX)
        .transform(FontTransform::Rotate270)
        .pos(Pos::new(HPos::Center, VPos::Top));
    area.draw(&Text::new(
        h.label.clone(),
        (
            bx + bar_w + tick_len + k.px(4.0) + tick_w + k.px(10.0),
            (by0 + by1) / 2,
        ),
        label_font,
    ))
    .map_err(plot_err)?;
    Ok(())
}

/// The map as a coarse grid of rectangles in plot coordinates (rows downwards: y is -row),
/// each the mean of its block of the `fw` x `fh` field, for vector output.
fn block_means(h: &Heatmap, fw: usize, fh: usize) -> Vec<Rectangle<(f64, f64)>> {
    // a coarse grid of rectangles, each the mean of its block
    let block = fw.max(fh).div_ceil(SVG_HEATMAP_CELLS).max(1);
    let mut cells = Vec::new();
    for by in (0..fh).step_by(block) {
        for bx in (0..fw).step_by(block) {
            let (mut sum, mut n) = (0.0f64, 0usize);
            for y in by..(by + block).min(fh) {
                for x in bx..(bx + block).min(fw) {
                    let v = h.values.get(y * fw + x).copied().unwrap_or(f32::NAN);
                    if v.is_finite() {
                        sum += f64::from(v);
                        n += 1;
                    }
                }
            }
            let v = if n > 0 {
                (sum / n as f64) as f32
            } else {
                f32::NAN
            };
            let (xa, xb) = (bx as f64, (bx + block).min(fw) as f64);
            let (ya, yb) = (-(by as f64), -((by + block).min(fh) as f64));
            cells.push(Rectangle::new(
                [(xa, ya), (xb, yb)],
                color(heat_color(h, v)).filled(),
            ));
        }
    }
    cells
}

/// The map sampled at every one of `pw` x `ph` pixels (nearest), as RGB bytes.
fn nearest_pixels(h: &Heatmap, fw: usize, fh: usize, pw: usize, ph: usize) -> Vec<u8> {
    let mut rgb = Vec::with_capacity(pw * ph * 3);
    for y in 0..ph {
        let sy = (((y as f64 + 0.5) / ph as f64 * fh as f64) as usize).min(fh - 1);
        for x in 0..pw {
            let sx = (((x as f64 + 0.5) / pw as f64 * fw as f64) as usize).min(fw - 1);
            let v = h.values.get(sy * fw + sx).copied().unwrap_or(f32::NAN);
            rgb.extend_from_slice(&heat_color(h, v));
        }
    }
    rgb
}
