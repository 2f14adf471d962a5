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

mod axes;
mod chart;
mod heatmap;
mod legend;
mod output;
mod text;

use std::path::PathBuf;

use plotters::prelude::*;
use thiserror::Error;

pub use self::output::{format_of, render_rgb, render_svg, save, Format};

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

fn color(c: Rgb) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

fn plot_err<E: std::fmt::Debug>(e: E) -> FigureError {
    FigureError::Draw(format!("{e:?}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axes::{clip_polygon, clip_segment, visible_runs, AxisSpace, LogTicks, TickFormat};

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
