//! An RGB pixel canvas with the few drawing primitives the pictures need
//! (rectangles, discs, thick segments, alpha blending) and text in a 5 × 7
//! bitmap font, for the colour bars, slice captions and tick labels of
//! [`super::render`] and the pictures of `grid.plan` and `grid.skeleton`.
//!
//! The font is written here rather than taken from a crate: it needs only
//! the digits, `. - + e = : / ,`, and lower-case letters (upper case is
//! drawn as lower case), about 45 glyphs of 7 rows of 5 bits each, and the
//! codecs layer stays free of any font or rasteriser dependency. A glyph
//! occupies a cell of 6 × 8 font pixels (one column and one row of space),
//! each font pixel drawn as `scale × scale` picture pixels.

use image::{ImageBuffer, Rgb};
use ndarray::ArrayD;

use super::raster::{side, write_png};
use super::{ArrayData, IoError};

/// Width of a glyph cell in font pixels (5 columns + 1 of space).
pub const CELL_W: usize = 6;
/// Height of a glyph cell in font pixels (7 rows + 1 of space).
pub const CELL_H: usize = 8;

/// The 7 rows of a glyph, bit 4 the leftmost column; `?` for characters the
/// font lacks.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_lowercase() {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        ' ' => [0; 7],
        'a' => [0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F],
        'b' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E],
        'c' => [0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E],
        'd' => [0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F],
        'e' => [0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E],
        'f' => [0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08],
        'g' => [0x00, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E],
        'h' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11],
        'i' => [0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E],
        'j' => [0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C],
        'k' => [0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12],
        'l' => [0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'm' => [0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11],
        'n' => [0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11],
        'o' => [0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E],
        'p' => [0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10],
        'q' => [0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01],
        'r' => [0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10],
        's' => [0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E],
        't' => [0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06],
        'u' => [0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D],
        'v' => [0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'w' => [0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A],
        'x' => [0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11],
        'y' => [0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E],
        'z' => [0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04],
    }
}

/// Width in pixels of `text` drawn at `scale` (no trailing space column).
pub fn text_width(text: &str, scale: usize) -> usize {
    let n = text.chars().count();
    (n * CELL_W).saturating_sub(1) * scale
}

/// Height in pixels of one line of text at `scale` (the 7 glyph rows).
pub fn text_height(scale: usize) -> usize {
    (CELL_H - 1) * scale
}

/// A number as a short label: up to 4 significant digits, trailing zeros
/// dropped, scientific notation (`1.5e-4`, `2.5e6`) outside `[1e-3, 1e5)`.
///
/// # Examples
///
/// ```
/// use geodex::io::canvas::short_number;
/// assert_eq!(short_number(12.5), "12.5");
/// assert_eq!(short_number(0.000_15), "1.5e-4");
/// assert_eq!(short_number(-3.0), "-3");
/// assert_eq!(short_number(141.42136), "141.4");
/// ```
pub fn short_number(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return if v.is_nan() {
            "nan".into()
        } else if v > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        };
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.3e}");
        // "1.500e-4" → mantissa trimmed, "1.5e-4".
        return match s.split_once('e') {
            Some((m, e)) => format!("{}e{e}", trim_zeros(m)),
            None => s,
        };
    }
    let digits = (3 - a.log10().floor() as i32).max(0) as usize;
    trim_zeros(&format!("{v:.digits$}")).to_string()
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// An RGB picture being drawn: `width × height` pixels, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixels, row by row.
    pub pixels: Vec<[u8; 3]>,
}

impl Canvas {
    /// A canvas filled with `colour`.
    pub fn new(width: usize, height: usize, colour: [u8; 3]) -> Self {
        Canvas {
            width,
            height,
            pixels: vec![colour; width * height],
        }
    }

    /// The pixel at column `x`, row `y` (`None` outside).
    pub fn get(&self, x: usize, y: usize) -> Option<[u8; 3]> {
        (x < self.width && y < self.height).then(|| self.pixels[y * self.width + x])
    }

    /// Sets a pixel; outside the canvas, nothing.
    pub fn set(&mut self, x: i64, y: i64, colour: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let i = y as usize * self.width + x as usize;
            self.pixels[i] = colour;
        }
    }

    /// Mixes `colour` into a pixel with opacity `alpha` in `[0, 1]`.
    pub fn blend(&mut self, x: i64, y: i64, colour: [u8; 3], alpha: f64) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let i = y as usize * self.width + x as usize;
            self.pixels[i] = mix(self.pixels[i], colour, alpha);
        }
    }

    /// Fills the rectangle of columns `x..x + w`, rows `y..y + h`.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: usize, h: usize, colour: [u8; 3]) {
        for yy in y..y + h as i64 {
            for xx in x..x + w as i64 {
                self.set(xx, yy, colour);
            }
        }
    }

    /// A filled disc of radius `r` pixels centred at `(x, y)` (pixel
    /// coordinates, column first).
    pub fn disc(&mut self, x: f64, y: f64, r: f64, colour: [u8; 3]) {
        let (x0, x1) = ((x - r).floor() as i64, (x + r).ceil() as i64);
        let (y0, y1) = ((y - r).floor() as i64, (y + r).ceil() as i64);
        for yy in y0..=y1 {
            for xx in x0..=x1 {
                let (dx, dy) = (xx as f64 - x, yy as f64 - y);
                if dx * dx + dy * dy <= r * r {
                    self.set(xx, yy, colour);
                }
            }
        }
    }

    /// A segment of width `2r + 1` pixels from `a` to `b` (pixel coordinates,
    /// column first), drawn as discs every half pixel.
    pub fn segment(&mut self, a: [f64; 2], b: [f64; 2], r: f64, colour: [u8; 3]) {
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let steps = (2.0 * len).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
            if r <= 0.0 {
                self.set(x.round() as i64, y.round() as i64, colour);
            } else {
                self.disc(x, y, r, colour);
            }
        }
    }

    /// Draws `text` with its top-left corner at `(x, y)`, each font pixel a
    /// `scale × scale` block of `colour`.
    pub fn text(&mut self, x: i64, y: i64, scale: usize, text: &str, colour: [u8; 3]) {
        let s = scale as i64;
        for (k, c) in text.chars().enumerate() {
            let gx = x + (k * CELL_W) as i64 * s;
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        self.fill_rect(gx + col * s, y + row as i64 * s, scale, scale, colour);
                    }
                }
            }
        }
    }

    /// `text` on a filled box (one font pixel of margin), readable over any
    /// picture.
    pub fn label(&mut self, x: i64, y: i64, scale: usize, text: &str, fg: [u8; 3], bg: [u8; 3]) {
        let w = text_width(text, scale) + 2 * scale;
        let h = text_height(scale) + 2 * scale;
        self.fill_rect(x, y, w, h, bg);
        self.text(x + scale as i64, y + scale as i64, scale, text, fg);
    }

    /// Copies `other` with its top-left corner at `(x, y)`.
    pub fn paste(&mut self, other: &Canvas, x: usize, y: usize) {
        for yy in 0..other.height {
            for xx in 0..other.width {
                self.set(
                    (x + xx) as i64,
                    (y + yy) as i64,
                    other.pixels[yy * other.width + xx],
                );
            }
        }
    }

    /// The canvas as an 8-bit RGB PNG.
    ///
    /// # Errors
    ///
    /// [`IoError::Encode`] for an empty canvas.
    pub fn to_png(&self) -> Result<Vec<u8>, IoError> {
        let (w, h) = (side(self.width)?, side(self.height)?);
        let raw: Vec<u8> = self.pixels.iter().flatten().copied().collect();
        write_png(ImageBuffer::<Rgb<u8>, _>::from_raw(w, h, raw))
    }

    /// The canvas as a `u8` array of shape `(height, width, 3)`: what
    /// [`super::render_png`] writes as it is.
    ///
    /// # Errors
    ///
    /// [`IoError::Encode`] if the pixel count does not match the size.
    pub fn to_array(&self) -> Result<ArrayData, IoError> {
        let raw: Vec<u8> = self.pixels.iter().flatten().copied().collect();
        ArrayD::from_shape_vec(vec![self.height, self.width, 3], raw)
            .map(ArrayData::U8)
            .map_err(|e| IoError::Encode(e.to_string()))
    }
}

/// `a` mixed with `b` at opacity `alpha` of `b`.
pub fn mix(a: [u8; 3], b: [u8; 3], alpha: f64) -> [u8; 3] {
    let t = alpha.clamp(0.0, 1.0);
    let m = |i: usize| (f64::from(a[i]) * (1.0 - t) + f64::from(b[i]) * t).round() as u8;
    [m(0), m(1), m(2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_drawn_in_cells_of_six_by_eight() {
        let mut c = Canvas::new(30, 10, [255; 3]);
        c.text(0, 0, 1, "1-", [0; 3]);
        // '1': column 2 of its glyph is set on every row.
        assert!((0..7).all(|y| c.get(2, y) == Some([0; 3])));
        // '-': row 3 of the second cell, columns 6..=10.
        assert!((6..11).all(|x| c.get(x, 3) == Some([0; 3])));
        assert_eq!(c.get(6, 2), Some([255; 3]));
        assert_eq!(text_width("1-", 2), 22);
    }

    #[test]
    fn short_numbers() {
        assert_eq!(short_number(0.25), "0.25");
        assert_eq!(short_number(1234.5678), "1235");
        assert_eq!(short_number(250000.0), "2.5e5");
        assert_eq!(short_number(f64::INFINITY), "inf");
    }
}
