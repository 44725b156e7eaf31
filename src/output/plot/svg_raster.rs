//! An SVG backend for plotters that writes a bitmap as one embedded PNG
//! image instead of a rectangle per pixel.
//!
//! A map of a million cells is drawn as the raster of its pixels (see
//! `draw_cells` in `grid`): plotters' SVG backend, without the `image`
//! crate, would write each of those pixels as its own `<rect>`, tens of
//! megabytes. [`RasterSvg`] passes every other drawing call to plotters'
//! SVG backend unchanged, and marks each bitmap's place with a rectangle of
//! a colour of its own; [`render`] then puts the image where its mark is.

use std::cell::RefCell;
use std::rc::Rc;

use base64::Engine;
use plotters::prelude::*;
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};

/// A bitmap drawn: its mark in the SVG text and the `<image>` that replaces it.
struct Placed {
    mark: String,
    image: String,
}

/// plotters' SVG backend, writing into a string, with bitmaps kept aside.
pub struct RasterSvg<'a> {
    svg: SVGBackend<'a>,
    placed: Rc<RefCell<Vec<Placed>>>,
}

/// Draws with `draw` into an SVG of `size`, each bitmap embedded as a PNG
/// image, and returns the SVG's text.
pub fn render<E: std::error::Error + Send + Sync>(
    size: (u32, u32),
    draw: impl FnOnce(DrawingArea<RasterSvg<'_>, plotters::coord::Shift>) -> Result<(), E>,
) -> Result<String, E> {
    let mut text = String::new();
    let placed = Rc::new(RefCell::new(Vec::new()));
    {
        let backend = RasterSvg {
            svg: SVGBackend::with_string(&mut text, size),
            placed: placed.clone(),
        };
        draw(backend.into_drawing_area())?;
    }
    for Placed { mark, image } in placed.take() {
        assert!(
            text.contains(&mark),
            "a bitmap's mark is in the SVG plotters wrote"
        );
        text = text.replacen(&mark, &image, 1);
    }
    Ok(text)
}

/// The colour of the `n`th bitmap's mark: near-black shades that the
/// figures' own colours do not use, and that the mark's exact geometry
/// makes unique in any case.
fn mark_colour(n: usize) -> BackendColor {
    let n = n as u32 + 1;
    BackendColor {
        alpha: 1.0,
        rgb: (1, (n >> 8) as u8, n as u8),
    }
}

impl DrawingBackend for RasterSvg<'_> {
    type ErrorType = <SVGBackend<'static> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.svg.get_size()
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.fill_polygon(vert, style)
    }

    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.svg.draw_text(text, style, pos)
    }

    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> Result<(u32, u32), DrawingErrorKind<Self::ErrorType>> {
        self.svg.estimate_text_size(text, style)
    }

    /// Writes `src` (RGB rows of `w` × `h` pixels at `pos`) as one PNG
    /// image: marked by a filled rectangle now, put in place by [`render`].
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        (w, h): (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        let png = super::figure::encode_png(src, (w, h)).map_err(DrawingErrorKind::DrawingError)?;
        let mut placed = self.placed.borrow_mut();
        let colour = mark_colour(placed.len());
        let (w, h) = (w as i32, h as i32);
        self.svg
            .draw_rect(pos, (pos.0 + w, pos.1 + h), &colour, true)?;
        // What plotters' SVG backend writes for that rectangle.
        let (r, g, b) = colour.rgb;
        let mark = format!(
            "<rect x=\"{}\" y=\"{}\" width=\"{w}\" height=\"{h}\" opacity=\"1\" fill=\"#{r:02X}{g:02X}{b:02X}\" stroke=\"none\"/>\n",
            pos.0, pos.1
        );
        // One image pixel a figure pixel: drawn sharp, never smoothed.
        let image = format!(
            "<image x=\"{}\" y=\"{}\" width=\"{w}\" height=\"{h}\" preserveAspectRatio=\"none\" style=\"image-rendering:pixelated\" href=\"data:image/png;base64,{}\"/>\n",
            pos.0,
            pos.1,
            base64::engine::general_purpose::STANDARD.encode(png)
        );
        placed.push(Placed { mark, image });
        Ok(())
    }
}
