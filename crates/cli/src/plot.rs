//! Plots written as PNG or SVG (chosen by the file extension): line charts with linear or
//! logarithmic axes, legends, multi-panel figures and heat maps with a colour bar.
//!
//! Layout is computed once into drawing primitives in pixel coordinates; two small back ends
//! turn them into an SVG document or an anti-aliased RGB raster.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use embedded_graphics::mono_font::{ascii, MonoFont, MonoTextStyle};
use embedded_graphics::pixelcolor::Rgb888;
use embedded_graphics::prelude::{DrawTarget, OriginDimensions, Point, RgbColor, Size};
use embedded_graphics::text::{Baseline, Text};
use embedded_graphics::{Drawable, Pixel};

/// An RGB colour.
pub type Rgb = [u8; 3];

/// Distinguishable line colours (Tableau 10).
pub const PALETTE: [Rgb; 8] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
];

const BLACK: Rgb = [0, 0, 0];
const GRID: Rgb = [225, 225, 225];

/// One line of a chart.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text (empty: not in the legend).
    pub label: String,
    /// Points in data coordinates; non-finite points break the line.
    pub points: Vec<[f64; 2]>,
    /// Colour.
    pub color: Rgb,
    /// Line width in pixels.
    pub width: f64,
    /// Dashed line.
    pub dashed: bool,
    /// A band: the area between `points` (lower edge) and these upper points, filled.
    pub band_upper: Option<Vec<[f64; 2]>>,
}

impl Series {
    /// A solid line of width 2.
    pub fn line(label: impl Into<String>, points: Vec<[f64; 2]>, color: Rgb) -> Series {
        Series {
            label: label.into(),
            points,
            color,
            width: 2.0,
            dashed: false,
            band_upper: None,
        }
    }

    /// A filled band between `lower` and `upper` (same x values), in a light shade of
    /// `color`.
    pub fn band(
        label: impl Into<String>,
        lower: Vec<[f64; 2]>,
        upper: Vec<[f64; 2]>,
        color: Rgb,
    ) -> Series {
        Series {
            label: label.into(),
            points: lower,
            color: [
                ((color[0] as u16 + 2 * 255) / 3) as u8,
                ((color[1] as u16 + 2 * 255) / 3) as u8,
                ((color[2] as u16 + 2 * 255) / 3) as u8,
            ],
            width: 2.0,
            dashed: false,
            band_upper: Some(upper),
        }
    }

    /// The same line, dashed.
    pub fn dashed(mut self) -> Series {
        self.dashed = true;
        self
    }
}

/// Where the legend goes inside the plot area.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Corner {
    /// Top left.
    TopLeft,
    /// Top right.
    TopRight,
    /// Bottom right.
    BottomRight,
}

/// A chart of lines.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Title above the plot area.
    pub title: String,
    /// x axis label.
    pub x_label: String,
    /// y axis label.
    pub y_label: String,
    /// Logarithmic x axis.
    pub x_log: bool,
    /// The lines.
    pub series: Vec<Series>,
    /// Fixed x range (else from the data).
    pub x_range: Option<[f64; 2]>,
    /// Fixed y range (else from the data).
    pub y_range: Option<[f64; 2]>,
    /// Same scale on both axes (trajectories).
    pub equal_aspect: bool,
    /// Legend position, `None` for no legend.
    pub legend: Option<Corner>,
}

impl Chart {
    /// An empty chart with a title and axis labels.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Chart {
        Chart {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            x_log: false,
            series: Vec::new(),
            x_range: None,
            y_range: None,
            equal_aspect: false,
            legend: Some(Corner::TopLeft),
        }
    }
}

/// A scalar field shown with a colour map.
#[derive(Clone, Debug)]
pub struct Heatmap {
    /// Title above the map.
    pub title: String,
    /// Field width in samples.
    pub width: usize,
    /// Field height in samples.
    pub height: usize,
    /// Row-major samples; non-finite ones are drawn grey.
    pub values: Vec<f32>,
    /// Values mapped to the ends of the colour map.
    pub range: [f32; 2],
    /// Colour bar label.
    pub label: String,
}

/// A panel of a figure.
#[derive(Clone, Debug)]
pub enum Panel {
    /// Lines.
    Chart(Chart),
    /// A colour-mapped field.
    Heatmap(Heatmap),
}

/// A figure: panels placed in fractions `[x, y, w, h]` of the canvas.
#[derive(Clone, Debug)]
pub struct Figure {
    /// Canvas width in pixels.
    pub width: u32,
    /// Canvas height in pixels.
    pub height: u32,
    /// Panels and their placement.
    pub panels: Vec<(Panel, [f64; 4])>,
}

impl Figure {
    /// A figure with one chart filling the canvas.
    pub fn single(chart: Chart, width: u32, height: u32) -> Figure {
        Figure {
            width,
            height,
            panels: vec![(Panel::Chart(chart), [0.0, 0.0, 1.0, 1.0])],
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Anchor {
    Start,
    Middle,
    End,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum FontSize {
    Small,
    Normal,
    Title,
}

impl FontSize {
    fn mono(self) -> &'static MonoFont<'static> {
        match self {
            FontSize::Small => &ascii::FONT_6X10,
            FontSize::Normal => &ascii::FONT_7X13,
            FontSize::Title => &ascii::FONT_9X15_BOLD,
        }
    }
    fn svg_px(self) -> f64 {
        match self {
            FontSize::Small => 10.0,
            FontSize::Normal => 12.0,
            FontSize::Title => 14.0,
        }
    }
    fn char_width(self) -> f64 {
        self.mono().character_size.width as f64
    }
}

#[derive(Clone, Debug)]
enum Prim {
    Polyline {
        pts: Vec<[f64; 2]>,
        color: Rgb,
        width: f64,
        dashed: bool,
        clip: [f64; 4],
    },
    Text {
        x: f64,
        y: f64,
        text: String,
        color: Rgb,
        size: FontSize,
        anchor: Anchor,
        vertical: bool,
    },
    Rect {
        r: [f64; 4],
        fill: Option<Rgb>,
        stroke: Option<Rgb>,
    },
    Image {
        r: [f64; 4],
        w: usize,
        h: usize,
        rgb: Vec<u8>,
    },
}

/// Nice tick positions for a linear axis.
fn linear_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = (hi - lo).abs().max(1e-300);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= target as f64 + 0.5)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() * step;
    let mut out = Vec::new();
    let mut v = first;
    while v <= hi + step * 1e-9 && out.len() < 50 {
        out.push(if v.abs() < step * 1e-9 { 0.0 } else { v });
        v += step;
    }
    out
}

/// Ticks of a logarithmic axis: the decades, plus 2 and 5 times them when few decades show.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let (a, b) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let decades = (hi / lo).log10();
    let mults: &[f64] = if decades <= 1.0 {
        &[1.0, 1.2, 1.5, 2.0, 3.0, 5.0, 7.0]
    } else if decades <= 2.5 {
        &[1.0, 2.0, 5.0]
    } else {
        &[1.0]
    };
    let mut out = Vec::new();
    for e in a..=b {
        for m in mults {
            let v = m * 10f64.powi(e);
            if v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9) {
                out.push(v);
            }
        }
    }
    out
}

/// Compact tick label.
fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.0e}")
    } else if a >= 100.0 || (v.fract() == 0.0) {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn data_range(series: &[Series], axis: usize, log: bool) -> Option<[f64; 2]> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in series {
        for p in &s.points {
            let v = p[axis];
            if v.is_finite() && (!log || v > 0.0) {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !lo.is_finite() {
        return None;
    }
    if hi <= lo {
        let pad = if log {
            lo * 0.5
        } else {
            lo.abs().max(1.0) * 0.05
        };
        return Some([lo - pad, hi + pad]);
    }
    Some([lo, hi])
}

fn layout_chart(c: &Chart, area: [f64; 4], out: &mut Vec<Prim>) {
    let [ax, ay, aw, ah] = area;
    let (ml, mr, mt, mb) = (62.0, 16.0, 28.0, 44.0);
    let pr = [
        ax + ml,
        ay + mt,
        (aw - ml - mr).max(10.0),
        (ah - mt - mb).max(10.0),
    ];
    out.push(Prim::Text {
        x: ax + aw / 2.0,
        y: ay + 6.0,
        text: c.title.clone(),
        color: BLACK,
        size: FontSize::Title,
        anchor: Anchor::Middle,
        vertical: false,
    });
    let mut xr = c
        .x_range
        .or_else(|| data_range(&c.series, 0, c.x_log))
        .unwrap_or(if c.x_log { [0.1, 10.0] } else { [0.0, 1.0] });
    let mut yr = c
        .y_range
        .or_else(|| data_range(&c.series, 1, false))
        .unwrap_or([0.0, 1.0]);
    if c.x_log {
        xr = [xr[0].max(1e-300), xr[1].max(xr[0] * 1.0001)];
    } else if c.x_range.is_none() {
        let pad = (xr[1] - xr[0]) * 0.03;
        xr = [xr[0] - pad, xr[1] + pad];
    }
    if c.y_range.is_none() {
        let pad = (yr[1] - yr[0]) * 0.04;
        yr = [yr[0] - pad, yr[1] + pad];
    }
    if c.equal_aspect {
        // expand the smaller span so one data unit is the same length on both axes
        let sx = pr[2] / (xr[1] - xr[0]);
        let sy = pr[3] / (yr[1] - yr[0]);
        if sx > sy {
            let need = pr[2] / sy;
            let mid = 0.5 * (xr[0] + xr[1]);
            xr = [mid - need / 2.0, mid + need / 2.0];
        } else {
            let need = pr[3] / sx;
            let mid = 0.5 * (yr[0] + yr[1]);
            yr = [mid - need / 2.0, mid + need / 2.0];
        }
    }
    let tx = |x: f64| -> f64 {
        if c.x_log {
            let (a, b) = (xr[0].log10(), xr[1].log10());
            pr[0] + (x.max(1e-300).log10() - a) / (b - a) * pr[2]
        } else {
            pr[0] + (x - xr[0]) / (xr[1] - xr[0]) * pr[2]
        }
    };
    let ty = |y: f64| -> f64 { pr[1] + pr[3] - (y - yr[0]) / (yr[1] - yr[0]) * pr[3] };
    // grid and ticks
    let xt = if c.x_log {
        log_ticks(xr[0], xr[1])
    } else {
        linear_ticks(xr[0], xr[1], (pr[2] / 90.0) as usize + 1)
    };
    let yt = linear_ticks(yr[0], yr[1], (pr[3] / 60.0) as usize + 1);
    for &v in &xt {
        let x = tx(v);
        out.push(Prim::Polyline {
            pts: vec![[x, pr[1]], [x, pr[1] + pr[3]]],
            color: GRID,
            width: 1.0,
            dashed: false,
            clip: pr,
        });
        out.push(Prim::Text {
            x,
            y: pr[1] + pr[3] + 6.0,
            text: fmt_tick(v),
            color: BLACK,
            size: FontSize::Small,
            anchor: Anchor::Middle,
            vertical: false,
        });
    }
    for &v in &yt {
        let y = ty(v);
        out.push(Prim::Polyline {
            pts: vec![[pr[0], y], [pr[0] + pr[2], y]],
            color: GRID,
            width: 1.0,
            dashed: false,
            clip: pr,
        });
        out.push(Prim::Text {
            x: pr[0] - 5.0,
            y: y - 5.0,
            text: fmt_tick(v),
            color: BLACK,
            size: FontSize::Small,
            anchor: Anchor::End,
            vertical: false,
        });
    }
    out.push(Prim::Text {
        x: pr[0] + pr[2] / 2.0,
        y: pr[1] + pr[3] + 22.0,
        text: c.x_label.clone(),
        color: BLACK,
        size: FontSize::Normal,
        anchor: Anchor::Middle,
        vertical: false,
    });
    out.push(Prim::Text {
        x: ax + 4.0,
        y: pr[1] + pr[3] / 2.0,
        text: c.y_label.clone(),
        color: BLACK,
        size: FontSize::Normal,
        anchor: Anchor::Middle,
        vertical: true,
    });
    for s in &c.series {
        if let Some(upper) = &s.band_upper {
            // filled by vertical strokes one data step wide
            let step = s
                .points
                .windows(2)
                .map(|w| (tx(w[1][0]) - tx(w[0][0])).abs())
                .fold(f64::INFINITY, f64::min)
                .clamp(1.0, 6.0);
            for (lo, hi) in s.points.iter().zip(upper) {
                if [lo[0], lo[1], hi[1]].iter().all(|v| v.is_finite()) {
                    let (x, y0, y1) = (tx(lo[0]), ty(lo[1]), ty(hi[1]));
                    out.push(Prim::Polyline {
                        pts: vec![[x, y0], [x, y1.min(y0 - 1.0)]],
                        color: s.color,
                        width: step + 0.5,
                        dashed: false,
                        clip: pr,
                    });
                }
            }
            continue;
        }
        let mut run: Vec<[f64; 2]> = Vec::new();
        let flush = |run: &mut Vec<[f64; 2]>, out: &mut Vec<Prim>| {
            if run.len() >= 2 {
                out.push(Prim::Polyline {
                    pts: std::mem::take(run),
                    color: s.color,
                    width: s.width,
                    dashed: s.dashed,
                    clip: pr,
                });
            } else {
                run.clear();
            }
        };
        for p in &s.points {
            if p[0].is_finite() && p[1].is_finite() && (!c.x_log || p[0] > 0.0) {
                run.push([tx(p[0]), ty(p[1])]);
            } else {
                flush(&mut run, out);
            }
        }
        flush(&mut run, out);
    }
    out.push(Prim::Rect {
        r: pr,
        fill: None,
        stroke: Some(BLACK),
    });
    if let Some(corner) = c.legend {
        let entries: Vec<&Series> = c.series.iter().filter(|s| !s.label.is_empty()).collect();
        if !entries.is_empty() {
            let cw = FontSize::Normal.char_width();
            let lw = entries.iter().map(|s| s.label.len()).max().unwrap_or(0) as f64 * cw + 44.0;
            let lh = entries.len() as f64 * 17.0 + 8.0;
            let (lx, ly) = match corner {
                Corner::TopLeft => (pr[0] + 8.0, pr[1] + 8.0),
                Corner::TopRight => (pr[0] + pr[2] - lw - 8.0, pr[1] + 8.0),
                Corner::BottomRight => (pr[0] + pr[2] - lw - 8.0, pr[1] + pr[3] - lh - 8.0),
            };
            out.push(Prim::Rect {
                r: [lx, ly, lw, lh],
                fill: Some([255, 255, 255]),
                stroke: Some([160, 160, 160]),
            });
            for (i, s) in entries.iter().enumerate() {
                let y = ly + 12.0 + i as f64 * 17.0;
                out.push(Prim::Polyline {
                    pts: vec![[lx + 6.0, y], [lx + 32.0, y]],
                    color: s.color,
                    width: s.width,
                    dashed: s.dashed,
                    clip: [0.0, 0.0, 1e9, 1e9],
                });
                out.push(Prim::Text {
                    x: lx + 38.0,
                    y: y - 6.0,
                    text: s.label.clone(),
                    color: BLACK,
                    size: FontSize::Normal,
                    anchor: Anchor::Start,
                    vertical: false,
                });
            }
        }
    }
}

/// A perceptually ordered colour map (viridis-like), `t` in [0, 1].
pub fn colormap(t: f32) -> Rgb {
    const STOPS: [[f32; 3]; 6] = [
        [68.0, 1.0, 84.0],
        [65.0, 68.0, 135.0],
        [42.0, 120.0, 142.0],
        [34.0, 168.0, 132.0],
        [122.0, 209.0, 81.0],
        [253.0, 231.0, 37.0],
    ];
    let t = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let i = (t.floor() as usize).min(STOPS.len() - 2);
    let f = t - i as f32;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [0, 1, 2].map(|k| (a[k] + f * (b[k] - a[k])).round() as u8)
}

fn layout_heatmap(h: &Heatmap, area: [f64; 4], out: &mut Vec<Prim>) {
    let [ax, ay, aw, ah] = area;
    out.push(Prim::Text {
        x: ax + aw / 2.0,
        y: ay + 6.0,
        text: h.title.clone(),
        color: BLACK,
        size: FontSize::Title,
        anchor: Anchor::Middle,
        vertical: false,
    });
    let avail = [aw - 100.0, ah - 40.0];
    let scale = (avail[0] / h.width as f64)
        .min(avail[1] / h.height as f64)
        .max(1e-6);
    let (iw, ih) = (h.width as f64 * scale, h.height as f64 * scale);
    let r = [ax + 10.0 + (avail[0] - iw) / 2.0, ay + 28.0, iw, ih];
    let span = (h.range[1] - h.range[0]).max(1e-12);
    let mut rgb = Vec::with_capacity(h.values.len() * 3);
    for &v in &h.values {
        let c = if v.is_finite() {
            colormap((v - h.range[0]) / span)
        } else {
            [128, 128, 128]
        };
        rgb.extend_from_slice(&c);
    }
    out.push(Prim::Image {
        r,
        w: h.width,
        h: h.height,
        rgb,
    });
    out.push(Prim::Rect {
        r,
        fill: None,
        stroke: Some(BLACK),
    });
    // colour bar
    let bar = [r[0] + r[2] + 16.0, r[1], 14.0, r[3]];
    let steps = 64;
    let mut rgb = Vec::with_capacity(steps * 3);
    for i in 0..steps {
        rgb.extend_from_slice(&colormap(1.0 - i as f32 / (steps - 1) as f32));
    }
    out.push(Prim::Image {
        r: bar,
        w: 1,
        h: steps,
        rgb,
    });
    out.push(Prim::Rect {
        r: bar,
        fill: None,
        stroke: Some(BLACK),
    });
    for v in linear_ticks(h.range[0] as f64, h.range[1] as f64, 5) {
        let y = bar[1] + bar[3] - (v - h.range[0] as f64) / span as f64 * bar[3];
        out.push(Prim::Text {
            x: bar[0] + bar[2] + 4.0,
            y: y - 5.0,
            text: fmt_tick(v),
            color: BLACK,
            size: FontSize::Small,
            anchor: Anchor::Start,
            vertical: false,
        });
    }
    out.push(Prim::Text {
        x: r[0] + r[2] / 2.0,
        y: r[1] + r[3] + 6.0,
        text: h.label.clone(),
        color: BLACK,
        size: FontSize::Normal,
        anchor: Anchor::Middle,
        vertical: false,
    });
}

fn layout(fig: &Figure) -> Vec<Prim> {
    let mut out = vec![Prim::Rect {
        r: [0.0, 0.0, fig.width as f64, fig.height as f64],
        fill: Some([255, 255, 255]),
        stroke: None,
    }];
    for (panel, f) in &fig.panels {
        let area = [
            f[0] * fig.width as f64,
            f[1] * fig.height as f64,
            f[2] * fig.width as f64,
            f[3] * fig.height as f64,
        ];
        match panel {
            Panel::Chart(c) => layout_chart(c, area, &mut out),
            Panel::Heatmap(h) => layout_heatmap(h, area, &mut out),
        }
    }
    out
}

/// Splits a polyline into dashes of `on` pixels separated by `off`.
fn dash(pts: &[[f64; 2]], on: f64, off: f64) -> Vec<Vec<[f64; 2]>> {
    let mut out = Vec::new();
    let mut cur: Vec<[f64; 2]> = vec![pts[0]];
    let mut drawing = true;
    let mut left = on;
    for w in pts.windows(2) {
        let (mut a, b) = (w[0], w[1]);
        let mut len = (b[0] - a[0]).hypot(b[1] - a[1]);
        while len > 0.0 {
            let step = left.min(len);
            let f = step / len;
            let p = [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f];
            if drawing {
                cur.push(p);
            }
            left -= step;
            len -= step;
            a = p;
            if left <= 1e-9 {
                if drawing && cur.len() >= 2 {
                    out.push(std::mem::take(&mut cur));
                }
                drawing = !drawing;
                left = if drawing { on } else { off };
                cur = if drawing { vec![a] } else { Vec::new() };
            }
        }
    }
    if drawing && cur.len() >= 2 {
        out.push(cur);
    }
    out
}

// ---------------------------------------------------------------- SVG back end

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= c.len() {
                s.push(T[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn to_svg(fig: &Figure, prims: &[Prim]) -> Result<String> {
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="DejaVu Sans, Helvetica, Arial, sans-serif">"#,
        w = fig.width,
        h = fig.height
    );
    let mut clips: Vec<[f64; 4]> = Vec::new();
    for p in prims {
        if let Prim::Polyline { clip, .. } = p {
            if !clips.contains(clip) {
                clips.push(*clip);
            }
        }
    }
    s.push_str("<defs>\n");
    for (i, c) in clips.iter().enumerate() {
        let _ = writeln!(
            s,
            r#"<clipPath id="c{i}"><rect x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}"/></clipPath>"#,
            c[0], c[1], c[2], c[3]
        );
    }
    s.push_str("</defs>\n");
    let col = |c: &Rgb| format!("rgb({},{},{})", c[0], c[1], c[2]);
    for p in prims {
        match p {
            Prim::Polyline {
                pts,
                color,
                width,
                dashed,
                clip,
            } => {
                let ci = clips.iter().position(|c| c == clip).unwrap_or(0);
                let mut pts_s = String::with_capacity(pts.len() * 14);
                for q in pts {
                    let _ = write!(pts_s, "{:.2},{:.2} ", q[0], q[1]);
                }
                let _ = writeln!(
                    s,
                    r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="{}"{} stroke-linejoin="round" clip-path="url(#c{ci})"/>"#,
                    pts_s.trim_end(),
                    col(color),
                    width,
                    if *dashed {
                        r#" stroke-dasharray="8,5""#
                    } else {
                        ""
                    }
                );
            }
            Prim::Text {
                x,
                y,
                text,
                color,
                size,
                anchor,
                vertical,
            } => {
                let a = match anchor {
                    Anchor::Start => "start",
                    Anchor::Middle => "middle",
                    Anchor::End => "end",
                };
                let fs = size.svg_px();
                let weight = if *size == FontSize::Title {
                    r#" font-weight="bold""#
                } else {
                    ""
                };
                if *vertical {
                    let (cx, cy) = (x + fs, *y);
                    let _ = writeln!(
                        s,
                        r#"<text x="{cx:.2}" y="{cy:.2}" font-size="{fs}" text-anchor="{a}" fill="{}"{weight} transform="rotate(-90 {cx:.2} {cy:.2})">{}</text>"#,
                        col(color),
                        xml_escape(text)
                    );
                } else {
                    let _ = writeln!(
                        s,
                        r#"<text x="{x:.2}" y="{:.2}" font-size="{fs}" text-anchor="{a}" fill="{}"{weight}>{}</text>"#,
                        y + fs,
                        col(color),
                        xml_escape(text)
                    );
                }
            }
            Prim::Rect { r, fill, stroke } => {
                let _ = writeln!(
                    s,
                    r#"<rect x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" fill="{}" stroke="{}"/>"#,
                    r[0],
                    r[1],
                    r[2],
                    r[3],
                    fill.map_or("none".into(), |c| col(&c)),
                    stroke.map_or("none".into(), |c| col(&c))
                );
            }
            Prim::Image { r, w, h, rgb } => {
                let png = dataset_io::encode_png_u8(*w, *h, 3, rgb, dataset_io::PngSpeed::Default)
                    .context("encoding an embedded image")?;
                let _ = writeln!(
                    s,
                    r#"<image x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" preserveAspectRatio="none" style="image-rendering:pixelated" href="data:image/png;base64,{}"/>"#,
                    r[0],
                    r[1],
                    r[2],
                    r[3],
                    base64(&png)
                );
            }
        }
    }
    s.push_str("</svg>\n");
    Ok(s)
}

// ---------------------------------------------------------------- raster back end

struct Raster {
    w: usize,
    h: usize,
    px: Vec<[f32; 3]>,
}

impl Raster {
    fn blend(&mut self, x: i64, y: i64, c: Rgb, a: f32) {
        if x < 0 || y < 0 || x >= self.w as i64 || y >= self.h as i64 || a <= 0.0 {
            return;
        }
        let p = &mut self.px[y as usize * self.w + x as usize];
        for k in 0..3 {
            p[k] += (c[k] as f32 - p[k]) * a.min(1.0);
        }
    }

    /// Anti-aliased thick segment by distance coverage, clipped to `clip`.
    fn segment(&mut self, a: [f64; 2], b: [f64; 2], c: Rgb, width: f64, clip: [f64; 4]) {
        let r = width / 2.0;
        let x0 = (a[0].min(b[0]) - r - 1.0).max(clip[0]).floor() as i64;
        let x1 = (a[0].max(b[0]) + r + 1.0).min(clip[0] + clip[2]).ceil() as i64;
        let y0 = (a[1].min(b[1]) - r - 1.0).max(clip[1]).floor() as i64;
        let y1 = (a[1].max(b[1]) + r + 1.0).min(clip[1] + clip[3]).ceil() as i64;
        let d = [b[0] - a[0], b[1] - a[1]];
        let len2 = d[0] * d[0] + d[1] * d[1];
        for y in y0..=y1 {
            for x in x0..=x1 {
                let p = [x as f64 + 0.5, y as f64 + 0.5];
                let t = if len2 > 0.0 {
                    (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let q = [a[0] + t * d[0], a[1] + t * d[1]];
                let dist = (p[0] - q[0]).hypot(p[1] - q[1]);
                let cov = (r + 0.5 - dist).clamp(0.0, 1.0);
                if cov > 0.0 {
                    self.blend(x, y, c, cov as f32);
                }
            }
        }
    }

    fn polyline(&mut self, pts: &[[f64; 2]], c: Rgb, width: f64, clip: [f64; 4]) {
        for w in pts.windows(2) {
            self.segment(w[0], w[1], c, width, clip);
        }
    }

    fn text(&mut self, x: f64, y: f64, text: &str, style: (Rgb, FontSize, Anchor, bool)) {
        let (c, size, anchor, vertical) = style;
        let font = size.mono();
        let tw = text.chars().count() as f64 * size.char_width();
        let th = font.character_size.height as usize;
        // render horizontally into a mask, then blit (rotated for vertical text)
        let mut mask = Mask {
            w: tw.ceil() as usize + 1,
            h: th,
            a: vec![false; (tw.ceil() as usize + 1) * th],
        };
        let style = MonoTextStyle::new(font, Rgb888::BLACK);
        let _ = Text::with_baseline(text, Point::new(0, 0), style, Baseline::Top).draw(&mut mask);
        let off = match anchor {
            Anchor::Start => 0.0,
            Anchor::Middle => tw / 2.0,
            Anchor::End => tw,
        };
        for my in 0..mask.h {
            for mx in 0..mask.w {
                if !mask.a[my * mask.w + mx] {
                    continue;
                }
                let (px, py) = if vertical {
                    // reading bottom to top, centred at (x + h/2, y)
                    (x + my as f64, y + off - mx as f64)
                } else {
                    (x - off + mx as f64, y + my as f64)
                };
                self.blend(px.round() as i64, py.round() as i64, c, 1.0);
            }
        }
    }
}

struct Mask {
    w: usize,
    h: usize,
    a: Vec<bool>,
}

impl OriginDimensions for Mask {
    fn size(&self) -> Size {
        Size::new(self.w as u32, self.h as u32)
    }
}

impl DrawTarget for Mask {
    type Color = Rgb888;
    type Error = std::convert::Infallible;
    fn draw_iter<I: IntoIterator<Item = Pixel<Rgb888>>>(
        &mut self,
        pixels: I,
    ) -> Result<(), Self::Error> {
        for Pixel(p, _) in pixels {
            if p.x >= 0 && p.y >= 0 && (p.x as usize) < self.w && (p.y as usize) < self.h {
                self.a[p.y as usize * self.w + p.x as usize] = true;
            }
        }
        Ok(())
    }
}

fn to_rgb(fig: &Figure, prims: &[Prim]) -> Vec<u8> {
    let (w, h) = (fig.width as usize, fig.height as usize);
    let mut r = Raster {
        w,
        h,
        px: vec![[255.0; 3]; w * h],
    };
    for p in prims {
        match p {
            Prim::Polyline {
                pts,
                color,
                width,
                dashed,
                clip,
            } => {
                if *dashed {
                    for d in dash(pts, 8.0, 5.0) {
                        r.polyline(&d, *color, *width, *clip);
                    }
                } else {
                    r.polyline(pts, *color, *width, *clip);
                }
            }
            Prim::Text {
                x,
                y,
                text,
                color,
                size,
                anchor,
                vertical,
            } => r.text(*x, *y, text, (*color, *size, *anchor, *vertical)),
            Prim::Rect {
                r: rr,
                fill,
                stroke,
            } => {
                if let Some(f) = fill {
                    for y in rr[1].round() as i64..(rr[1] + rr[3]).round() as i64 {
                        for x in rr[0].round() as i64..(rr[0] + rr[2]).round() as i64 {
                            r.blend(x, y, *f, 1.0);
                        }
                    }
                }
                if let Some(s) = stroke {
                    let (x0, y0) = (rr[0].round() + 0.5, rr[1].round() + 0.5);
                    let (x1, y1) = ((rr[0] + rr[2]).round() - 0.5, (rr[1] + rr[3]).round() - 0.5);
                    let all = [0.0, 0.0, w as f64, h as f64];
                    r.polyline(
                        &[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]],
                        *s,
                        1.0,
                        all,
                    );
                }
            }
            Prim::Image {
                r: rr,
                w: iw,
                h: ih,
                rgb,
            } => {
                let (x0, y0) = (rr[0].round() as i64, rr[1].round() as i64);
                let (ow, oh) = (rr[2].round().max(1.0) as i64, rr[3].round().max(1.0) as i64);
                for y in 0..oh {
                    for x in 0..ow {
                        let sx = ((x as f64 + 0.5) / ow as f64 * *iw as f64) as usize;
                        let sy = ((y as f64 + 0.5) / oh as f64 * *ih as f64) as usize;
                        let i = (sy.min(ih - 1) * iw + sx.min(iw - 1)) * 3;
                        r.blend(x0 + x, y0 + y, [rgb[i], rgb[i + 1], rgb[i + 2]], 1.0);
                    }
                }
            }
        }
    }
    r.px.iter()
        .flat_map(|p| p.map(|v| v.round().clamp(0.0, 255.0) as u8))
        .collect()
}

/// Writes the figure as PNG or SVG by the extension of `path` (atomically).
pub fn save(fig: &Figure, path: &Path) -> Result<()> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let prims = layout(fig);
    match ext.as_str() {
        "svg" => {
            let svg = to_svg(fig, &prims)?;
            dataset_io::write_atomic(path, svg.as_bytes())?;
        }
        "png" => {
            let rgb = to_rgb(fig, &prims);
            dataset_io::write_png_u8(
                path,
                fig.width as usize,
                fig.height as usize,
                3,
                &rgb,
                dataset_io::PngSpeed::Default,
            )?;
        }
        _ => bail!(
            "{}: unknown plot format `.{ext}`, use .png or .svg",
            path.display()
        ),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        assert_eq!(
            linear_ticks(0.0, 10.0, 5),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
        assert_eq!(log_ticks(0.5, 3000.0), vec![1.0, 10.0, 100.0, 1000.0]);
        assert_eq!(
            log_ticks(1.0, 100.0),
            vec![1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0]
        );
        assert_eq!(log_ticks(1.0, 2.5), vec![1.0, 1.2, 1.5, 2.0]);
        assert_eq!(fmt_tick(0.25), "0.25");
        assert_eq!(fmt_tick(1000.0), "1000");
    }

    #[test]
    fn base64_matches_rfc4648_vectors() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn dashes_alternate() {
        let d = dash(&[[0.0, 0.0], [30.0, 0.0]], 8.0, 5.0);
        assert_eq!(d.len(), 3);
        assert!((d[0][1][0] - 8.0).abs() < 1e-9);
        assert!((d[1][0][0] - 13.0).abs() < 1e-9);
    }

    #[test]
    fn raster_draws_lines_and_text() {
        let mut c = Chart::new("t", "x", "y");
        c.series
            .push(Series::line("a", vec![[0.0, 0.0], [1.0, 1.0]], PALETTE[0]));
        let fig = Figure::single(c, 200, 150);
        let rgb = to_rgb(&fig, &layout(&fig));
        assert_eq!(rgb.len(), 200 * 150 * 3);
        let blue = rgb.chunks(3).filter(|p| p[2] > 150 && p[0] < 100).count();
        assert!(blue > 50, "{blue}");
        let dark = rgb
            .chunks(3)
            .filter(|p| p[0] < 60 && p[1] < 60 && p[2] < 60)
            .count();
        assert!(dark > 100, "{dark}");
    }
}
