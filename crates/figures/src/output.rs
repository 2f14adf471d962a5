//! Writing figures: the format from the file name, PNG (drawn at three times the size and
//! reduced) and SVG, written atomically; the figure's panels laid out.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::chart::draw_chart;
use crate::heatmap::draw_heatmap;
use crate::legend::Legend;
use crate::text::{register_font, Scale, TextAligned};
use crate::{plot_err, Chart, Figure, FigureError, Panel, Result};

// ------------------------------------------------------------------------------- saving

/// Nominal-to-back-end scale of PNG figures (drawn large, then reduced: anti-aliasing).
pub(crate) const PNG_SUPERSAMPLE: u32 = 3;

/// Scale of SVG figures (coordinates are integers: half-pixel precision at 2).
pub(crate) const SVG_SCALE: u32 = 2;

/// The file formats a figure can be written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// A bitmap, anti-aliased.
    Png,
    /// Vector graphics.
    Svg,
}

/// The format of a figure file by its extension (`.png` or `.svg`, any case). Any other
/// extension, or none, is an error that names it and the accepted ones: commands call this
/// before their work.
pub fn format_of(path: &Path) -> Result<Format> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("png") => Ok(Format::Png),
        Some("svg") => Ok(Format::Svg),
        Some(other) => Err(FigureError::Extension {
            path: path.to_path_buf(),
            extension: other.to_string(),
        }),
        None => Err(FigureError::NoExtension {
            path: path.to_path_buf(),
        }),
    }
}

/// Writes the figure as PNG or SVG by the extension of `path` (atomically); see
/// [`format_of`].
pub fn save(fig: &Figure, path: &Path) -> Result<()> {
    match format_of(path)? {
        Format::Png => {
            let rgb = render_rgb(fig)?;
            dataset_io::write_png_u8(
                path,
                fig.width as usize,
                fig.height as usize,
                3,
                &rgb,
                dataset_io::PngSpeed::Default,
            )?;
        }
        Format::Svg => {
            let svg = render_svg(fig)?;
            dataset_io::write_atomic(path, svg.as_bytes())?;
        }
    }
    Ok(())
}

/// The figure as RGB pixels (`width * height * 3` bytes), anti-aliased.
pub fn render_rgb(fig: &Figure) -> Result<Vec<u8>> {
    register_font()?;
    let s = PNG_SUPERSAMPLE;
    let (w, h) = (fig.width.max(1), fig.height.max(1));
    let (bw, bh) = (w * s, h * s);
    let mut big = vec![255u8; bw as usize * bh as usize * 3];
    {
        let root = TextAligned(BitMapBackend::with_buffer(&mut big, (bw, bh))).into_drawing_area();
        draw_figure(&root, fig, Scale(f64::from(s)), false)?;
        root.present().map_err(plot_err)?;
    }
    // box filter: each output pixel is the mean of its s x s block
    let (w, h, s, bw) = (w as usize, h as usize, s as usize, bw as usize);
    let mut out = vec![0u8; w * h * 3];
    for (i, px) in out.chunks_exact_mut(3).enumerate() {
        let (x, y) = (i % w, i / w);
        let mut sum = [0u32; 3];
        for dy in 0..s {
            let row = (y * s + dy) * bw + x * s;
            for p in big[row * 3..(row + s) * 3].chunks_exact(3) {
                for (acc, v) in sum.iter_mut().zip(p) {
                    *acc += u32::from(*v);
                }
            }
        }
        let n = (s * s) as u32;
        for (o, acc) in px.iter_mut().zip(sum) {
            *o = ((acc + n / 2) / n) as u8;
        }
    }
    debug_assert_eq!(out.len(), w * h * 3);
    Ok(out)
}

/// The figure as an SVG document of the nominal size.
pub fn render_svg(fig: &Figure) -> Result<String> {
    register_font()?;
    let s = SVG_SCALE;
    let (w, h) = (fig.width.max(1), fig.height.max(1));
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, (w * s, h * s)).into_drawing_area();
        draw_figure(&root, fig, Scale(f64::from(s)), true)?;
        root.present().map_err(plot_err)?;
    }
    // show the drawing at its nominal size; the view box keeps the finer coordinates
    let big = format!(r#"width="{}" height="{}""#, w * s, h * s);
    Ok(text.replacen(&big, &format!(r#"width="{w}" height="{h}""#), 1))
}

pub(crate) fn draw_figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
    k: Scale,
    vector: bool,
) -> Result<()> {
    root.fill(&WHITE).map_err(plot_err)?;
    let (bw, bh) = root.dim_in_pixel();
    for (panel, f) in &fig.panels {
        let x0 = (f[0] * f64::from(bw)).round() as i32;
        let y0 = (f[1] * f64::from(bh)).round() as i32;
        let pw = (f[2] * f64::from(bw)).round().max(1.0) as u32;
        let ph = (f[3] * f64::from(bh)).round().max(1.0) as u32;
        let area = root.clone().shrink((x0, y0), (pw, ph));
        match panel {
            Panel::Chart(c) => draw_chart(&area, c, k)?,
            Panel::Heatmap(h) => draw_heatmap(&area, h, k, vector)?,
            Panel::Legend(c) => draw_legend_panel(&area, c, k)?,
        }
    }
    Ok(())
}

/// A legend alone, centred in `area`, in as many columns as fit its width.
pub(crate) fn draw_legend_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    c: &Chart,
    k: Scale,
) -> Result<()> {
    let Some(lg) = Legend::of(area, c, k)? else {
        return Ok(());
    };
    let (w, h) = area.dim_in_pixel();
    let (w, h) = (w as i32, h as i32);
    let (col_w, _) = lg.size(k);
    let columns = ((w / col_w.max(1)) as usize).clamp(1, lg.entries.len());
    let rows = lg.entries.len().div_ceil(columns) as i32;
    let box_h = rows * lg.line_h + k.px(Legend::PAD);
    let x = ((w - col_w * columns as i32) / 2).max(0);
    let y = ((h - box_h) / 2).max(0);
    lg.draw(area, (x, y), k, columns)
}
