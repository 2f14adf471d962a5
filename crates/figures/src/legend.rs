//! Legends: their entries and a place for them that keeps off the data.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::text::{Scale, LEGEND_PX};
use crate::{color, plot_err, Chart, Result, Rgb};

/// A legend entry: label, colour, width, dash pattern (if dashed), band, marker radius.
pub(crate) type LegendEntry = (String, Rgb, f64, Option<[f64; 2]>, bool, Option<f64>);

/// A legend's entries, measured.
pub(crate) struct Legend {
    pub(crate) entries: Vec<LegendEntry>,
    pub(crate) text_w: i32,
    pub(crate) line_h: i32,
}

impl Legend {
    const SAMPLE: f64 = 30.0;
    pub(crate) const PAD: f64 = 8.0;

    pub(crate) fn of<DB: DrawingBackend>(
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
    pub(crate) fn size(&self, k: Scale) -> (i32, i32) {
        (
            self.text_w + k.px(Self::SAMPLE + 3.0 * Self::PAD),
            self.entries.len() as i32 * self.line_h + k.px(Self::PAD),
        )
    }

    pub(crate) fn draw<DB: DrawingBackend>(
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
pub(crate) fn points_inside(
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
