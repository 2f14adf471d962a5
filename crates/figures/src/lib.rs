//! Figures for papers, drawn with plotters and written as PNG or SVG (chosen by the file
//! extension): line charts with linear or logarithmic axes, bands, point markers, legends that
//! move off the data, multi-panel figures and heat maps with a colour bar.
//!
//! Text uses the DejaVu Sans font embedded in the crate (registered with plotters' ab_glyph
//! renderer), so no system font is needed. PNG figures are drawn at three times their size
//! and reduced, which anti-aliases lines and text; SVG figures are vector graphics at twice
//! their size with a view box of the nominal size (half-pixel precision).
//!
//! ```
//! use monovo_figures::{render_svg, Chart, Figure, Series, PALETTE};
//!
//! let mut chart = Chart::new("a line", "time (s)", "distance (m)");
//! chart.series.push(Series::line("walk", vec![[0.0, 0.0], [1.0, 1.4], [2.0, 2.9]], PALETTE[0]));
//! let svg = render_svg(&Figure::single(chart, 600, 400))?;
//! assert!(svg.contains("distance (m)"));
//! // monovo_figures::save(&fig, "walk.png".as_ref()) writes a PNG (or .svg) atomically
//! # Ok::<(), monovo_figures::FigureError>(())
//! ```

#![deny(missing_docs)]

use std::path::Path;
use std::sync::OnceLock;

use std::path::PathBuf;

use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::FontTransform;
use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingErrorKind};
use thiserror::Error;

/// What can go wrong drawing or writing a figure.
#[derive(Debug, Error)]
pub enum FigureError {
    /// The file name ends in an extension that is not a figure format.
    #[error("{}: cannot write a figure as `.{extension}`: use a file name ending in .png or .svg", path.display())]
    Extension {
        /// The file.
        path: PathBuf,
        /// Its extension.
        extension: String,
    },
    /// The file name has no extension.
    #[error("{}: the file name has no extension: use a file name ending in .png or .svg", path.display())]
    NoExtension {
        /// The file.
        path: PathBuf,
    },
    /// The embedded font could not be registered.
    #[error("the embedded font does not load")]
    Font,
    /// plotters failed to draw.
    #[error("drawing the figure: {0}")]
    Draw(String),
    /// Writing the file failed.
    #[error(transparent)]
    Write(#[from] dataset_io::DatasetError),
}

/// `Result` with [`FigureError`].
pub type Result<T, E = FigureError> = std::result::Result<T, E>;

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
    /// Dash and gap lengths of a dashed line, nominal pixels.
    pub dash: [f64; 2],
    /// A band: the area between `points` (lower edge) and these upper points, filled.
    pub band_upper: Option<Vec<[f64; 2]>>,
    /// A filled circle of this radius (pixels) at every point.
    pub marker: Option<f64>,
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
            dash: DASH,
            band_upper: None,
            marker: None,
        }
    }

    /// Points drawn as filled circles of radius 4, without a line.
    pub fn points(label: impl Into<String>, points: Vec<[f64; 2]>, color: Rgb) -> Series {
        Series {
            width: 0.0,
            marker: Some(4.0),
            ..Series::line(label, points, color)
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
            color: color.map(|c| ((c as u16 + 2 * 255) / 3) as u8),
            width: 2.0,
            dashed: false,
            dash: DASH,
            band_upper: Some(upper),
            marker: None,
        }
    }

    /// The same line, dashed.
    pub fn dashed(mut self) -> Series {
        self.dashed = true;
        self
    }

    /// The same line, dotted (short dashes).
    pub fn dotted(mut self) -> Series {
        self.dashed = true;
        self.dash = [2.5, 3.5];
        self
    }

    /// The same line with dashes of `on` and gaps of `off` nominal pixels.
    pub fn dash_pattern(mut self, on: f64, off: f64) -> Series {
        self.dashed = true;
        self.dash = [on.max(0.5), off.max(0.5)];
        self
    }
}

/// Dash and gap lengths of [`Series::dashed`], nominal pixels.
pub const DASH: [f64; 2] = [9.0, 5.0];

impl Series {}

/// Where the legend should go inside the plot area. It is a preference: when the legend
/// would cover data there, another free corner is taken, and when every corner holds data
/// the legend goes below the chart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Corner {
    /// Top left.
    TopLeft,
    /// Top right.
    TopRight,
    /// Bottom right.
    BottomRight,
    /// Bottom left.
    BottomLeft,
}

/// A chart of lines.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Title above the plot area.
    pub title: String,
    /// x axis label (with its unit).
    pub x_label: String,
    /// y axis label (with its unit).
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
    /// Preferred legend position, `None` for no legend.
    pub legend: Option<Corner>,
    /// Only whole numbers on the y axis (counts).
    pub y_integer: bool,
    /// Names of categories at x = 1, 2, ... (box plots): the x axis labels them and no
    /// other value; empty for a numeric axis.
    pub x_categories: Vec<String>,
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
            y_integer: false,
            x_categories: Vec::new(),
        }
    }
}

/// A scalar field over image pixels shown with a colour map; its axes are the pixel
/// coordinates (x to the right, y down).
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
    /// Only the legend of a chart's series, centred in the panel in as many columns as fit
    /// (a legend shared by several panels).
    Legend(Chart),
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

/// A perceptually ordered colour map (viridis), `t` in [0, 1].
pub fn colormap(t: f32) -> Rgb {
    let c = ViridisRGB::get_color(t.clamp(0.0, 1.0));
    [c.0, c.1, c.2]
}

// ------------------------------------------------------------------------------- fonts

/// The font family name under which the embedded font is registered; SVG files name it
/// too, with `sans-serif` as the viewer's fallback.
const FAMILY: &str = "DejaVu Sans, sans-serif";

/// DejaVu Sans (Bitstream Vera licence, see assets/fonts/DejaVuSans-LICENSE.txt).
static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(FigureError::Font)
    }
}

/// Type sizes in nominal pixels (line heights, as plotters counts them).
const TITLE_PX: f64 = 19.0;
const LABEL_PX: f64 = 17.0;
const TICK_PX: f64 = 15.0;
const LEGEND_PX: f64 = 15.0;

/// Drawing scale: nominal pixels to back-end pixels.
#[derive(Clone, Copy, Debug)]
struct Scale(f64);

impl Scale {
    fn px(self, v: f64) -> i32 {
        (v * self.0).round() as i32
    }
    fn upx(self, v: f64) -> u32 {
        (v * self.0).round().max(1.0) as u32
    }
    fn font(self, px: f64) -> TextStyle<'static> {
        (FAMILY, px * self.0).into_font().color(&BLACK)
    }
}

/// Draws `title` centred at the top of `area` and returns the area below it (the whole area
/// for an empty title).
fn titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    k: Scale,
) -> Result<DrawingArea<DB, Shift>> {
    if title.is_empty() {
        return Ok(area.clone());
    }
    let font = k.font(TITLE_PX).pos(Pos::new(HPos::Center, VPos::Top));
    let (w, _) = area.dim_in_pixel();
    let top = k.px(8.0);
    area.draw_text(title, &font, ((w / 2) as i32, top))
        .map_err(plot_err)?;
    let (_, below) = area.split_vertically(top + k.px(TITLE_PX + 4.0));
    Ok(below)
}

fn color(c: Rgb) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

fn plot_err<E: std::fmt::Debug>(e: E) -> FigureError {
    FigureError::Draw(format!("{e:?}"))
}

// ------------------------------------------------------------------------------- saving

/// Nominal-to-back-end scale of PNG figures (drawn large, then reduced: anti-aliasing).
const PNG_SUPERSAMPLE: u32 = 3;
/// Scale of SVG figures (coordinates are integers: half-pixel precision at 2).
const SVG_SCALE: u32 = 2;

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

/// plotters' ab_glyph renderer puts the baseline half a font size below the top of the
/// text's layout box, so bitmap text sits about a fifth of its size above where the layout
/// (and the SVG back end) puts it: titles lose their tops, tick labels sit above their
/// ticks. This back end draws text as plotters' default does, moved down by that amount
/// (cap height centred in the layout box), and passes everything else to the bitmap.
struct TextAligned<'a>(BitMapBackend<'a>);

/// How far (in font sizes) bitmap text is moved down; DejaVu's cap height is 0.63 of the
/// size ab_glyph scales to, the layout box 1/1.24 of it.
const TEXT_DROP: f64 = 0.5 / 1.24 + 0.63 / 2.0 - 0.5;

impl DrawingBackend for TextAligned<'_> {
    type ErrorType = <BitMapBackend<'static> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }
    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.ensure_prepared()
    }
    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.present()
    }
    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_pixel(point, color)
    }
    fn draw_line<S: plotters_backend::BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_line(from, to, style)
    }
    fn draw_rect<S: plotters_backend::BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_rect(upper_left, bottom_right, style, fill)
    }
    fn draw_path<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_path(path, style)
    }
    fn draw_circle<S: plotters_backend::BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_circle(center, radius, style, fill)
    }
    fn fill_polygon<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.fill_polygon(vert, style)
    }
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        (iw, ih): (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.blit_bitmap(pos, (iw, ih), src)
    }
    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        if style.color().alpha == 0.0 {
            return Ok(());
        }
        let ((x0, y0), (x1, y1)) = style
            .layout_box(text)
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let (w, h) = (x1 - x0, y1 - y0);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Center => -w / 2,
            HPos::Right => -w,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -h / 2,
            VPos::Bottom => -h,
        } + (TEXT_DROP * style.size()).round() as i32;
        let transform = style.transform();
        let (bw, bh) = self.0.get_size();
        let inner = &mut self.0;
        style
            .draw(text, (0, 0), |x, y, color| {
                let (x, y) = transform.transform(x + dx - x0, y + dy - y0);
                let (x, y) = (pos.0 + x, pos.1 + y);
                if x >= 0 && y >= 0 && x < bw as i32 && y < bh as i32 {
                    inner.draw_pixel((x, y), color)
                } else {
                    Ok(())
                }
            })
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?
    }
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

fn draw_figure<DB: DrawingBackend>(
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
fn draw_legend_panel<DB: DrawingBackend>(
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

// ------------------------------------------------------------------------------- charts

/// Tick labels of an axis: as many decimals as the spacing of the ticks needs (plotters
/// puts them at 1, 2 or 5 times a power of ten), trailing zeros dropped, scientific
/// notation for very small or large spacings.
#[derive(Clone, Copy, Debug)]
struct TickFormat {
    /// The (smallest possible) spacing of the ticks; 0 on a logarithmic axis, where each
    /// label is written by its own magnitude.
    step: f64,
}

impl TickFormat {
    /// A linear axis over `span` with at most `labels` labels.
    fn linear(span: f64, labels: usize) -> TickFormat {
        TickFormat {
            step: span.abs() / labels.max(1) as f64,
        }
    }

    /// A logarithmic axis (ticks at 1, 2 or 5 times powers of ten).
    const LOG: TickFormat = TickFormat { step: 0.0 };

    fn format(self, v: f64) -> String {
        if v == 0.0 || !v.is_finite() {
            return if v == 0.0 { "0".into() } else { v.to_string() };
        }
        let step = if self.step > 0.0 { self.step } else { v.abs() };
        let mag = step.log10().floor();
        let trim = |t: &str| -> String {
            if t.contains('.') {
                t.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                t.to_string()
            }
        };
        if !(-4.0..6.0).contains(&mag) || v.abs() >= 1e7 {
            let t = format!("{v:.2e}");
            let (mantissa, exp) = t.split_once('e').unwrap_or((&t, "0"));
            return format!("{}e{exp}", trim(mantissa));
        }
        let decimals = (1.0 - mag).max(0.0) as usize;
        let t = trim(&format!("{v:.decimals$}"));
        if t == "-0" {
            "0".into()
        } else {
            t
        }
    }
}

/// The label of a category axis at `v`: the name at a whole number 1..=n, nothing elsewhere;
/// `None` for a numeric axis.
fn category_label(categories: &[String], v: f64) -> Option<String> {
    if categories.is_empty() {
        return None;
    }
    let k = v.round();
    Some(
        if (v - k).abs() < 1e-9 && k >= 1.0 && k <= categories.len() as f64 {
            categories[k as usize - 1].clone()
        } else {
            String::new()
        },
    )
}

fn data_range(series: &[Series], axis: usize, log: bool) -> Option<[f64; 2]> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in series {
        for p in s.points.iter().chain(s.band_upper.iter().flatten()) {
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

/// The axis ranges of a chart: given, or the data's with a small margin.
fn chart_ranges(c: &Chart) -> ([f64; 2], [f64; 2]) {
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
    if xr[1] <= xr[0] {
        xr[1] = xr[0] + 1.0;
    }
    if yr[1] <= yr[0] {
        yr[1] = yr[0] + 1.0;
    }
    (xr, yr)
}

/// Maps data to the chart's axis space (log10 on a logarithmic x axis) and back.
#[derive(Clone, Copy)]
struct AxisSpace {
    x_log: bool,
}

impl AxisSpace {
    fn to_axis(self, p: [f64; 2]) -> [f64; 2] {
        if self.x_log {
            [p[0].log10(), p[1]]
        } else {
            p
        }
    }
    fn to_data(self, p: [f64; 2]) -> [f64; 2] {
        if self.x_log {
            [10f64.powf(p[0]), p[1]]
        } else {
            p
        }
    }
    fn valid(self, p: [f64; 2]) -> bool {
        p[0].is_finite() && p[1].is_finite() && (!self.x_log || p[0] > 0.0)
    }
}

/// Clips a segment to the rectangle `[x0, x1] x [y0, y1]` (Liang-Barsky).
fn clip_segment(a: [f64; 2], b: [f64; 2], r: [f64; 4]) -> Option<([f64; 2], [f64; 2])> {
    let d = [b[0] - a[0], b[1] - a[1]];
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-d[0], a[0] - r[0]),
        (d[0], r[1] - a[0]),
        (-d[1], a[1] - r[2]),
        (d[1], r[3] - a[1]),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    (t0 <= t1).then(|| {
        (
            [a[0] + t0 * d[0], a[1] + t0 * d[1]],
            [a[0] + t1 * d[0], a[1] + t1 * d[1]],
        )
    })
}

/// The visible pieces of a polyline: broken at non-finite points, clipped to `r` (axis
/// space), returned in data coordinates.
fn visible_runs(points: &[[f64; 2]], space: AxisSpace, r: [f64; 4]) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut cur: Vec<[f64; 2]> = Vec::new();
    let mut flush = |cur: &mut Vec<[f64; 2]>| {
        if cur.len() >= 2 {
            runs.push(
                cur.iter()
                    .map(|p| {
                        let d = space.to_data(*p);
                        (d[0], d[1])
                    })
                    .collect(),
            );
        }
        cur.clear();
    };
    let mut prev: Option<[f64; 2]> = None;
    for &p in points {
        if !space.valid(p) {
            flush(&mut cur);
            prev = None;
            continue;
        }
        let q = space.to_axis(p);
        if let Some(a) = prev {
            match clip_segment(a, q, r) {
                Some((s, e)) => {
                    if cur.last() != Some(&s) {
                        flush(&mut cur);
                        cur.push(s);
                    }
                    cur.push(e);
                    if e != q {
                        flush(&mut cur);
                    }
                }
                None => flush(&mut cur),
            }
        }
        prev = Some(q);
    }
    flush(&mut cur);
    runs
}

/// Clips a polygon to the rectangle `r` (Sutherland-Hodgman; the rectangle is convex).
fn clip_polygon(poly: Vec<[f64; 2]>, r: [f64; 4]) -> Vec<[f64; 2]> {
    let edges: [(usize, f64, bool); 4] = [
        (0, r[0], true),
        (0, r[1], false),
        (1, r[2], true),
        (1, r[3], false),
    ];
    let mut out = poly;
    for (axis, bound, keep_above) in edges {
        let inside = |p: &[f64; 2]| {
            if keep_above {
                p[axis] >= bound
            } else {
                p[axis] <= bound
            }
        };
        let input = std::mem::take(&mut out);
        for (i, &cur) in input.iter().enumerate() {
            let prev = input[(i + input.len() - 1) % input.len()];
            let cross = |a: [f64; 2], b: [f64; 2]| {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
            };
            match (inside(&prev), inside(&cur)) {
                (true, true) => out.push(cur),
                (true, false) => out.push(cross(prev, cur)),
                (false, true) => {
                    out.push(cross(prev, cur));
                    out.push(cur);
                }
                (false, false) => {}
            }
        }
        if out.is_empty() {
            break;
        }
    }
    out
}

/// A legend entry: label, colour, width, dash pattern (if dashed), band, marker radius.
type LegendEntry = (String, Rgb, f64, Option<[f64; 2]>, bool, Option<f64>);

/// A legend's entries, measured.
struct Legend {
    entries: Vec<LegendEntry>,
    text_w: i32,
    line_h: i32,
}

impl Legend {
    const SAMPLE: f64 = 30.0;
    const PAD: f64 = 8.0;

    fn of<DB: DrawingBackend>(
        area: &DrawingArea<DB, Shift>,
        c: &Chart,
        k: Scale,
    ) -> Result<Option<Legend>> {
        let entries: Vec<_> = c
            .series
            .iter()
            .filter(|s| !s.label.is_empty())
            .map(|s| {
                (
                    s.label.clone(),
                    s.color,
                    s.width,
                    s.dashed.then_some(s.dash),
                    s.band_upper.is_some(),
                    s.marker,
                )
            })
            .collect();
        if entries.is_empty() || c.legend.is_none() {
            return Ok(None);
        }
        let font = k.font(LEGEND_PX);
        let mut text_w = 0;
        for e in &entries {
            let (w, _) = area.estimate_text_size(&e.0, &font).map_err(plot_err)?;
            text_w = text_w.max(w as i32);
        }
        Ok(Some(Legend {
            entries,
            text_w,
            line_h: k.px(LEGEND_PX * 1.35),
        }))
    }

    /// Size of the box with one entry per row.
    fn size(&self, k: Scale) -> (i32, i32) {
        (
            self.text_w + k.px(Self::SAMPLE + 3.0 * Self::PAD),
            self.entries.len() as i32 * self.line_h + k.px(Self::PAD),
        )
    }

    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        at: (i32, i32),
        k: Scale,
        columns: usize,
    ) -> Result<()> {
        let columns = columns.max(1);
        let rows = self.entries.len().div_ceil(columns) as i32;
        let col_w = self.text_w + k.px(Self::SAMPLE + 3.0 * Self::PAD);
        let (w, h) = (col_w * columns as i32, rows * self.line_h + k.px(Self::PAD));
        let (x0, y0) = at;
        area.draw(&Rectangle::new(
            [(x0, y0), (x0 + w, y0 + h)],
            WHITE.mix(0.92).filled(),
        ))
        .map_err(plot_err)?;
        area.draw(&Rectangle::new(
            [(x0, y0), (x0 + w, y0 + h)],
            RGBColor(160, 160, 160).stroke_width(k.upx(1.0)),
        ))
        .map_err(plot_err)?;
        let font = k.font(LEGEND_PX).pos(Pos::new(HPos::Left, VPos::Center));
        for (i, (label, c, width, dashed, band, marker)) in self.entries.iter().enumerate() {
            let (col, row) = ((i as i32) / rows, (i as i32) % rows);
            let x = x0 + col * col_w + k.px(Self::PAD);
            let y = y0 + k.px(Self::PAD / 2.0) + row * self.line_h + self.line_h / 2;
            let len = k.px(Self::SAMPLE);
            let style = color(*c).stroke_width(k.upx(*width));
            if *band {
                area.draw(&Rectangle::new(
                    [(x, y - self.line_h / 3), (x + len, y + self.line_h / 3)],
                    color(*c).filled(),
                ))
                .map_err(plot_err)?;
            } else if let Some([on, off]) = dashed {
                // the line's own pattern along the sample
                let (on, off) = (k.px(*on).max(1), k.px(*off).max(1));
                let mut at = 0;
                while at < len {
                    area.draw(&PathElement::new(
                        vec![(x + at, y), (x + (at + on).min(len), y)],
                        style,
                    ))
                    .map_err(plot_err)?;
                    at += on + off;
                }
            } else if *width > 0.0 {
                area.draw(&PathElement::new(vec![(x, y), (x + len, y)], style))
                    .map_err(plot_err)?;
            }
            if let Some(r) = marker {
                area.draw(&Circle::new((x + len / 2, y), k.px(*r), color(*c).filled()))
                    .map_err(plot_err)?;
            }
            area.draw(&Text::new(
                label.clone(),
                (x + len + k.px(Self::PAD), y),
                font.clone(),
            ))
            .map_err(plot_err)?;
        }
        Ok(())
    }
}

/// How many series points (sampled along each segment, in pixels) fall inside `rect`.
fn points_inside(
    c: &Chart,
    to_px: &dyn Fn([f64; 2]) -> Option<(f64, f64)>,
    rect: [f64; 4],
) -> usize {
    let inside =
        |p: (f64, f64)| p.0 >= rect[0] && p.0 <= rect[2] && p.1 >= rect[1] && p.1 <= rect[3];
    let mut n = 0;
    for s in &c.series {
        let mut lines = vec![&s.points];
        if let Some(u) = &s.band_upper {
            lines.push(u);
        }
        for pts in lines {
            let px: Vec<Option<(f64, f64)>> = pts.iter().map(|p| to_px(*p)).collect();
            for w in px.windows(2) {
                if let (Some(a), Some(b)) = (w[0], w[1]) {
                    let len = (b.0 - a.0).hypot(b.1 - a.1);
                    let steps = (len / 3.0).ceil().clamp(1.0, 400.0) as usize;
                    for i in 0..=steps {
                        let t = i as f64 / steps as f64;
                        n += usize::from(inside((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))));
                    }
                } else if let Some(a) = w[0] {
                    n += usize::from(inside(a));
                }
            }
        }
    }
    n
}

/// Margins and label areas of a chart, in back-end pixels.
struct ChartLayout {
    top: i32,
    right: i32,
    bottom: i32,
    left: i32,
    x_area: i32,
    y_area: i32,
}

impl ChartLayout {
    fn new(k: Scale) -> ChartLayout {
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
    fn plot_rect(&self, w: i32, h: i32) -> [i32; 4] {
        [
            self.left + self.y_area,
            self.top,
            (w - self.right).max(self.left + self.y_area + 10),
            (h - self.bottom - self.x_area).max(self.top + 10),
        ]
    }
}

fn draw_chart<DB: DrawingBackend>(
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

/// The ticks of a logarithmic axis: 1, 2 and 5 times the powers of ten in the range (or
/// only the powers, or every n-th, when that is too many; 1 to 9 times them when that is too
/// few); on a range shorter than a factor of about 3, evenly spaced ticks as on a linear
/// axis, so that e'_s from 1 to 1.4 still has labelled ticks.
struct LogTicks {
    bold: Vec<f64>,
    light: Vec<f64>,
    format: TickFormat,
}

impl LogTicks {
    fn new(range: [f64; 2], max_labels: usize) -> LogTicks {
        let [lo, hi] = range;
        let max_labels = max_labels.max(2);
        let inside = |v: &f64| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9);
        let multiples = |m: &[f64]| -> Vec<f64> {
            let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
            (k0..=k1)
                .flat_map(|k| m.iter().map(move |m| m * 10f64.powi(k)))
                .filter(inside)
                .collect()
        };
        let all = multiples(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        let mut bold = multiples(&[1.0, 2.0, 5.0]);
        if bold.len() > max_labels {
            let decades = multiples(&[1.0]);
            let every = decades.len().div_ceil(max_labels).max(1);
            bold = decades.into_iter().step_by(every).collect();
        } else if bold.len() < 3 {
            bold = all.clone();
        }
        if bold.len() >= 3 && bold.len() <= max_labels {
            return LogTicks {
                bold,
                light: all,
                format: TickFormat::LOG,
            };
        }
        // a short range: evenly spaced, 1, 2 or 5 times a power of ten apart
        let raw = (hi - lo) / max_labels.min(8) as f64;
        let p = 10f64.powf(raw.log10().floor());
        let step = [1.0, 2.0, 5.0, 10.0]
            .into_iter()
            .map(|m| m * p)
            .find(|s| *s >= raw)
            .unwrap_or(10.0 * p);
        let first = (lo / step).ceil() as i64;
        let last = (hi / step).floor() as i64;
        let bold: Vec<f64> = (first..=last).map(|i| i as f64 * step).collect();
        let light = (first * 5 - 5..=last * 5 + 5)
            .map(|i| i as f64 * step / 5.0)
            .filter(inside)
            .collect();
        LogTicks {
            bold,
            light,
            format: TickFormat { step },
        }
    }
}

#[derive(Clone, Copy)]
struct Ticks {
    x: usize,
    y: usize,
    x_format: TickFormat,
    y_format: TickFormat,
}

fn draw_chart_body<DB, X>(
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

// ------------------------------------------------------------------------------- heat maps

/// Cells on the longest side of a heat map in SVG files (rectangles, not a raster).
const SVG_HEATMAP_CELLS: usize = 120;

fn heat_color(h: &Heatmap, v: f32) -> Rgb {
    let span = (h.range[1] - h.range[0]).max(1e-12);
    if v.is_finite() {
        colormap((v - h.range[0]) / span)
    } else {
        [128, 128, 128]
    }
}

fn draw_heatmap<DB: DrawingBackend>(
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
        chart.draw_series(cells).map_err(plot_err)?;
    } else {
        // one sample per back-end pixel (nearest), blitted as a bitmap
        let (pw, ph) = (iw as usize, ih as usize);
        let mut rgb = Vec::with_capacity(pw * ph * 3);
        for y in 0..ph {
            let sy = (((y as f64 + 0.5) / ph as f64 * fh as f64) as usize).min(fh - 1);
            for x in 0..pw {
                let sx = (((x as f64 + 0.5) / pw as f64 * fw as f64) as usize).min(fw - 1);
                let v = h.values.get(sy * fw + sx).copied().unwrap_or(f32::NAN);
                rgb.extend_from_slice(&heat_color(h, v));
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_compact() {
        let log = TickFormat::LOG;
        assert_eq!(log.format(0.25), "0.25");
        assert_eq!(log.format(1000.0), "1000");
        assert_eq!(log.format(0.0), "0");
        assert_eq!(log.format(2e-5), "2e-5");
        assert_eq!(log.format(0.1), "0.1");
        // the spacing decides the decimals: 0.0015 is not rounded to 0.002
        let fine = TickFormat::linear(0.0016, 8);
        assert_eq!(fine.format(0.0015), "0.0015");
        assert_eq!(fine.format(0.001), "0.001");
        let coarse = TickFormat::linear(500.0, 10);
        assert_eq!(coarse.format(250.0), "250");
        assert_eq!(
            TickFormat::linear(3.0, 10).format(0.30000000000000004),
            "0.3"
        );
        assert_eq!(TickFormat::linear(6.0, 12).format(2.5), "2.5");
        assert_eq!(TickFormat::linear(2e-5, 4).format(1.5e-5), "1.5e-5");
        assert_eq!(TickFormat::linear(2.0, 4).format(-1e-17), "0");
    }

    #[test]
    fn log_axes_have_enough_labelled_ticks() {
        // several decades: 1, 2, 5 times the powers of ten
        let labels =
            |t: &LogTicks| -> Vec<String> { t.bold.iter().map(|v| t.format.format(*v)).collect() };
        let t = LogTicks::new([0.02, 30.0], 12);
        assert_eq!(
            labels(&t),
            ["0.02", "0.05", "0.1", "0.2", "0.5", "1", "2", "5", "10", "20"]
        );
        assert!(t.light.len() > t.bold.len());
        // too many for the space: every other power of ten
        let t = LogTicks::new([1e-3, 1e3], 5);
        assert_eq!(labels(&t), ["0.001", "0.1", "10", "1000"]);
        // e'_s from 1 to 3: 1, 2, 3
        assert_eq!(labels(&LogTicks::new([1.0, 3.2], 10)), ["1", "2", "3"]);
        // a short range: evenly spaced labels with the decimals they need
        let t = LogTicks::new([1.0, 1.4], 10);
        let l = labels(&t);
        assert!(l.len() >= 4 && l[0] == "1", "{l:?}");
        for (text, v) in l.iter().zip(&t.bold) {
            let back: f64 = text.parse().unwrap();
            assert!((back - v).abs() < 1e-9, "{l:?}");
        }
    }

    #[test]
    fn segments_and_polygons_are_clipped_to_the_plot() {
        let r = [0.0, 10.0, 0.0, 10.0];
        let (a, b) = clip_segment([-5.0, 5.0], [15.0, 5.0], r).unwrap();
        assert_eq!((a, b), ([0.0, 5.0], [10.0, 5.0]));
        assert!(clip_segment([-5.0, -5.0], [-1.0, 20.0], r).is_none());
        let runs = visible_runs(
            &[
                [1.0, 1.0],
                [5.0, 20.0],
                [9.0, 1.0],
                [f64::NAN, 0.0],
                [2.0, 2.0],
                [3.0, 3.0],
            ],
            AxisSpace { x_log: false },
            r,
        );
        assert_eq!(runs.len(), 3, "{runs:?}");
        assert!(runs.iter().flatten().all(|p| p.1 <= 10.0 + 1e-12));
        let poly = clip_polygon(vec![[-5.0, -5.0], [5.0, -5.0], [5.0, 5.0], [-5.0, 5.0]], r);
        let area: f64 = (0..poly.len())
            .map(|i| {
                let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
                p[0] * q[1] - q[0] * p[1]
            })
            .sum::<f64>()
            / 2.0;
        assert!((area.abs() - 25.0).abs() < 1e-9, "{poly:?}");
    }

    #[test]
    fn png_has_anti_aliased_lines_and_text_and_svg_is_scaled() {
        let mut c = Chart::new("title", "x (m)", "y (m)");
        c.series
            .push(Series::line("a", vec![[0.0, 0.0], [1.0, 1.0]], PALETTE[0]));
        let fig = Figure::single(c, 300, 200);
        let rgb = render_rgb(&fig).unwrap();
        assert_eq!(rgb.len(), 300 * 200 * 3);
        let blue = rgb.chunks(3).filter(|p| p[2] > 150 && p[0] < 100).count();
        assert!(blue > 50, "{blue}");
        let dark = rgb.chunks(3).filter(|p| p.iter().all(|&v| v < 60)).count();
        assert!(dark > 100, "{dark}");
        // grey levels between black and white: the edges are smoothed
        let mid = rgb
            .chunks(3)
            .filter(|p| p[0] == p[1] && p[1] == p[2] && (80..200).contains(&p[0]))
            .count();
        assert!(mid > 30, "{mid}");
        let svg = render_svg(&fig).unwrap();
        assert!(
            svg.contains(r#"width="300" height="200" viewBox="0 0 600 400""#),
            "{}",
            &svg[..200]
        );
        assert!(svg.contains("DejaVu Sans"));
    }

    #[test]
    fn save_names_a_wrong_extension() {
        let fig = Figure::single(Chart::new("t", "x", "y"), 100, 80);
        let dir = std::env::temp_dir();
        let e = save(&fig, &dir.join("monovo_plot_test.jpeg")).unwrap_err();
        assert!(
            e.to_string().contains("`.jpeg`") && e.to_string().contains(".png or .svg"),
            "{e}"
        );
        let e = save(&fig, &dir.join("monovo_plot_test_xplot")).unwrap_err();
        assert!(e.to_string().contains("no extension"), "{e}");
    }

    #[test]
    fn the_legend_moves_off_the_data() {
        // a line through the top-left corner: the legend must not sit there
        let mut c = Chart::new("t", "x", "y");
        let pts: Vec<[f64; 2]> = (0..=100).map(|i| [i as f64, 100.0 - i as f64]).collect();
        c.series.push(Series::line("falling", pts, PALETTE[1]));
        c.legend = Some(Corner::TopLeft);
        let fig = Figure::single(c, 400, 300);
        let rgb = render_rgb(&fig).unwrap();
        // the legend box is white-ish with a grey frame; the red line passes the top-left
        // of the plot and the legend text must be elsewhere: look for red pixels in the
        // top-left quarter (the line is visible there, not covered)
        let red_top_left = (40..140)
            .flat_map(|y| (70..170).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let p = &rgb[(y * 400 + x) * 3..(y * 400 + x) * 3 + 3];
                p[0] > 150 && p[1] < 90
            })
            .count();
        assert!(red_top_left > 50, "{red_top_left}");
    }
}
