//! Text: the embedded font, its sizes at a figure's scale, titles, and the bitmap backend
//! that places text where SVG places it.

use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingErrorKind};

use crate::{plot_err, FigureError, Result};

// ------------------------------------------------------------------------------- fonts

/// The font family name under which the embedded font is registered; SVG files name it
/// too, with `sans-serif` as the viewer's fallback.
pub(crate) const FAMILY: &str = "DejaVu Sans, sans-serif";

/// DejaVu Sans (Bitstream Vera licence, see assets/fonts/DejaVuSans-LICENSE.txt).
pub(crate) static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

pub(crate) fn register_font() -> Result<()> {
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
pub(crate) const TITLE_PX: f64 = 19.0;

pub(crate) const LABEL_PX: f64 = 17.0;

pub(crate) const TICK_PX: f64 = 15.0;

pub(crate) const LEGEND_PX: f64 = 15.0;

/// Drawing scale: nominal pixels to back-end pixels.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scale(pub(crate) f64);

impl Scale {
    pub(crate) fn px(self, v: f64) -> i32 {
        (v * self.0).round() as i32
    }
    pub(crate) fn upx(self, v: f64) -> u32 {
        (v * self.0).round().max(1.0) as u32
    }
    pub(crate) fn font(self, px: f64) -> TextStyle<'static> {
        (FAMILY, px * self.0).into_font().color(&BLACK)
    }
}

/// Draws `title` centred at the top of `area` and returns the area below it (the whole area
/// for an empty title).
pub(crate) fn titled<DB: DrawingBackend>(
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

/// plotters' ab_glyph renderer puts the baseline half a font size below the top of the
/// text's layout box, so bitmap text sits about a fifth of its size above where the layout
/// (and the SVG back end) puts it: titles lose their tops, tick labels sit above their
/// ticks. This back end draws text as plotters' default does, moved down by that amount
/// (cap height centred in the layout box), and passes everything else to the bitmap.
pub(crate) struct TextAligned<'a>(pub(crate) BitMapBackend<'a>);

/// How far (in font sizes) bitmap text is moved down; DejaVu's cap height is 0.63 of the
/// size ab_glyph scales to, the layout box 1/1.24 of it.
pub(crate) const TEXT_DROP: f64 = 0.5 / 1.24 + 0.63 / 2.0 - 0.5;

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
