//! Colour-mapped 8-bit RGB PNG previews of arrays, for people to look at
//! (not for round trips: use NPY, float TIFF or 16-bit PNG for data).
//!
//! * Continuous values (floats, u8, u16, bool) go through a perceptual
//!   colour map: `t = (v - lo) / (hi - lo)` clamped to `[0, 1]`, with `(lo,
//!   hi)` from [`RenderOptions::range`] or the finite minimum and maximum.
//!   `+inf` (unreachable cells of a distance map) is drawn neutral grey
//!   [`UNREACHED`], NaN (walls) black, `-inf` like `lo`.
//! * Labels (i32, i64 by default) get a categorical palette: label `k ≥ 0`
//!   has hue `frac(k · φ⁻¹)` (golden-ratio steps, so neighbouring labels
//!   differ strongly); negative labels (no source reached the cell) are
//!   grey.
//! * Iso-value lines ([`IsoLines`]) are drawn on a cell when
//!   `floor((U - lo) / step)`, clamped to the bands inside `[lo, hi]`,
//!   differs from its right or lower neighbour (both finite); the cell colour is pushed 60% towards black (light
//!   colours) or white (dark colours).
//!
//! 2D arrays `(rows, cols)` give `cols × rows` pixels. 3D arrays show the
//! middle slice along axis 0 (index `n0 / 2`), so a `(1, rows, cols)` grid
//! shows its only slice; the exception is a `u8` array of shape `(rows,
//! cols, 3)`, which is already an RGB picture and is written as it is.
//!
//! The colour maps are tables of 17 control points (`t = k/16`) with linear
//! interpolation between them. The control points were computed for this
//! project by evaluating published closed-form fits: the degree-6 polynomial
//! fit of matplotlib's viridis, and Anton Mikhailov's polynomial
//! approximation of Google's Turbo.

use image::{ImageBuffer, Rgb};
use ndarray::{ArrayD, Axis};

use super::raster::{side, value_range, write_png};
use super::{to_f64_vec, ArrayData, IoError};

/// Colour of unreachable (`+inf`) cells and negative labels.
pub const UNREACHED: [u8; 3] = [128, 128, 128];
/// Colour of NaN cells (walls).
pub const WALL: [u8; 3] = [0, 0, 0];

/// Viridis at `t = k/16`, `k = 0..=16`.
const VIRIDIS: [[u8; 3]; 17] = [
    [71, 1, 85],
    [72, 24, 106],
    [71, 45, 123],
    [67, 64, 134],
    [61, 82, 140],
    [52, 99, 142],
    [43, 114, 142],
    [35, 129, 141],
    [31, 144, 139],
    [33, 159, 135],
    [42, 174, 128],
    [61, 188, 116],
    [90, 200, 97],
    [128, 211, 73],
    [172, 220, 48],
    [216, 226, 29],
    [252, 231, 33],
];

/// Turbo at `t = k/16`, `k = 0..=16`.
const TURBO: [[u8; 3]; 17] = [
    [35, 23, 27],
    [73, 62, 175],
    [68, 106, 238],
    [50, 149, 247],
    [38, 189, 225],
    [41, 221, 187],
    [64, 243, 146],
    [102, 253, 109],
    [150, 250, 80],
    [198, 235, 59],
    [238, 208, 45],
    [255, 171, 36],
    [255, 128, 29],
    [238, 84, 21],
    [201, 45, 12],
    [161, 18, 2],
    [144, 13, 0],
];

/// `v` in `[0, 255]` rounded to the nearest integer, halves up: the cast
/// truncates, so `v + 0.5` truncated is the rounding for `v >= 0`, without
/// the libm call that `f64::round` is on baseline x86-64 (a third of the
/// time of a 1024² picture went to `round` and `floor`).
#[inline]
fn round_u8(v: f64) -> u8 {
    (v + 0.5) as u8
}

/// A continuous colour map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum Colormap {
    /// Perceptually uniform, dark blue → green → yellow, luminance increasing.
    #[default]
    Viridis,
    /// Rainbow-like, dark blue → green → red; more contrast, not monotone in luminance.
    Turbo,
    /// Black → white.
    Grey,
}

impl Colormap {
    /// The colour at `t` (clamped to `[0, 1]`; NaN gives the colour at 0).
    ///
    /// # Examples
    ///
    /// ```
    /// use geodex::io::Colormap;
    /// assert_eq!(Colormap::Grey.at(0.5), [128, 128, 128]);
    /// assert_eq!(Colormap::Viridis.at(1.0), [252, 231, 33]);
    /// ```
    pub fn at(self, t: f64) -> [u8; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let table = match self {
            Colormap::Viridis => &VIRIDIS,
            Colormap::Turbo => &TURBO,
            // Rounded and clamped, so the cast is exact.
            Colormap::Grey => return [round_u8(t * 255.0); 3],
        };
        let x = t * (table.len() - 1) as f64;
        // In 0..=16 since t is in [0, 1].
        // `x >= 0`: the cast truncates, which is the floor (and no libm call).
        let k = (x as usize).min(table.len() - 2);
        let f = x - k as f64;
        let (a, b) = (table[k], table[k + 1]);
        let mix = |i: usize| round_u8(f64::from(a[i]) * (1.0 - f) + f64::from(b[i]) * f);
        [mix(0), mix(1), mix(2)]
    }
}

/// Where to draw iso-value lines.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum IsoLines {
    /// This many lines, evenly spaced strictly inside the range:
    /// `step = (hi - lo) / (count + 1)`.
    Count(usize),
    /// One line every `step` value units from `lo`.
    Spacing(f64),
}

/// How values become colours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum RenderStyle {
    /// Categorical for i32 and i64 arrays (labels), continuous otherwise.
    #[default]
    Auto,
    /// Colour map over a value range.
    Continuous,
    /// One colour per integer label (values are truncated to integers).
    Categorical,
}

/// Options of [`render_png`]. `RenderOptions::default()` is an automatic
/// style, viridis, the finite min..max range and no iso lines.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderOptions {
    /// Continuous or categorical.
    pub style: RenderStyle,
    /// The colour map of continuous values.
    pub colormap: Colormap,
    /// Values mapped to the two ends of the colour map; default the finite
    /// minimum and maximum. Must be finite with low < high.
    pub range: Option<(f64, f64)>,
    /// Iso-value lines (continuous style only).
    pub iso_lines: Option<IsoLines>,
}

/// A colour of the categorical palette for label `k` (negative: grey).
///
/// Hue `h = frac(k · 0.618034)`, saturation alternating 0.85 / 0.6, value
/// cycling 0.95 / 0.75 every other pair, converted from HSV to RGB.
pub fn label_colour(k: i64) -> [u8; 3] {
    if k < 0 {
        return UNREACHED;
    }
    let h = (k as f64 * 0.618_033_988_75).fract() * 6.0;
    let s = if k % 2 == 0 { 0.85 } else { 0.6 };
    let v = if (k / 2) % 2 == 0 { 0.95 } else { 0.75 };
    let c = v * s;
    let x = c * (1.0 - (h % 2.0 - 1.0).abs());
    let (r, g, b) = match h as u8 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    let q = |u: f64| ((u + m) * 255.0).round().clamp(0.0, 255.0) as u8;
    [q(r), q(g), q(b)]
}

/// The plane shown: `(rows, cols, values)`.
fn shown_plane(array: &ArrayData) -> Result<(usize, usize, Vec<f64>), IoError> {
    fn middle<T: Clone>(a: &ArrayD<T>) -> ArrayD<T> {
        let mid = a.shape()[0] / 2;
        a.index_axis(Axis(0), mid).to_owned()
    }
    let shape = array.shape().to_vec();
    match shape[..] {
        [rows, cols] => Ok((rows, cols, to_f64_vec(array))),
        [n0, rows, cols] if n0 > 0 => {
            let slice = match array {
                ArrayData::Bool(a) => ArrayData::Bool(middle(a)),
                ArrayData::U8(a) => ArrayData::U8(middle(a)),
                ArrayData::U16(a) => ArrayData::U16(middle(a)),
                ArrayData::I32(a) => ArrayData::I32(middle(a)),
                ArrayData::I64(a) => ArrayData::I64(middle(a)),
                ArrayData::F32(a) => ArrayData::F32(middle(a)),
                ArrayData::F64(a) => ArrayData::F64(middle(a)),
            };
            Ok((rows, cols, to_f64_vec(&slice)))
        }
        _ => Err(IoError::Encode(format!(
            "a rendering needs a non-empty 2D or 3D array, got shape {shape:?}"
        ))),
    }
}

/// Pushes a colour 60% towards black (light colours) or white (dark ones).
fn contrast(c: [u8; 3]) -> [u8; 3] {
    let luma = 0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2]);
    let target = if luma >= 100.0 { 0.0 } else { 255.0 };
    c.map(|v| round_u8(f64::from(v) * 0.4 + target * 0.6))
}

/// Renders an array as an 8-bit RGB PNG (see the [module](self) docs for
/// the colours, iso lines and the slice shown of 3D arrays).
///
/// # Errors
///
/// [`IoError::Encode`] for arrays that are not non-empty 2D/3D, an invalid
/// `range`, or an iso-line `Count(0)` / non-positive `Spacing`.
///
/// # Examples
///
/// ```
/// use geodex::io::{render_png, ArrayData, IsoLines, RenderOptions};
/// let u = ndarray::ArrayD::from_shape_fn(vec![32, 32], |i| (i[0] as f64).hypot(i[1] as f64));
/// let options = RenderOptions { iso_lines: Some(IsoLines::Spacing(5.0)), ..Default::default() };
/// let png = render_png(&ArrayData::F64(u), &options)?;
/// assert!(png.starts_with(b"\x89PNG"));
/// # Ok::<(), geodex::io::IoError>(())
/// ```
pub fn render_png(array: &ArrayData, options: &RenderOptions) -> Result<Vec<u8>, IoError> {
    if let ArrayData::U8(a) = array {
        if let [rows, cols, 3] = a.shape()[..] {
            // Already a picture (e.g. a mesh drawn over its image): as is.
            let (w, h) = (side(cols)?, side(rows)?);
            let raw: Vec<u8> = a.iter().copied().collect();
            return write_png(ImageBuffer::<Rgb<u8>, _>::from_raw(w, h, raw));
        }
    }
    let (rows, cols, values) = shown_plane(array)?;
    let (w, h) = (side(cols)?, side(rows)?);
    let categorical = match options.style {
        RenderStyle::Auto => matches!(array, ArrayData::I32(_) | ArrayData::I64(_)),
        RenderStyle::Continuous => false,
        RenderStyle::Categorical => true,
    };
    let mut pixels: Vec<[u8; 3]> = if categorical {
        values
            .iter()
            .map(|&v| {
                if v.is_nan() {
                    WALL
                } else {
                    label_colour(v as i64)
                }
            })
            .collect()
    } else {
        let (lo, hi) = value_range(&values, options.range)?;
        let span = hi - lo;
        let mut pixels: Vec<[u8; 3]> = values
            .iter()
            .map(|&v| {
                if v.is_nan() {
                    WALL
                } else if v == f64::INFINITY {
                    UNREACHED
                } else if span > 0.0 {
                    options.colormap.at((v - lo) / span)
                } else {
                    options.colormap.at(0.0)
                }
            })
            .collect();
        if let Some(lines) = options.iso_lines {
            let step = match lines {
                IsoLines::Count(0) => {
                    return Err(IoError::Encode("iso_lines count must be at least 1".into()))
                }
                IsoLines::Count(n) => span / (n as f64 + 1.0),
                IsoLines::Spacing(s) if s.is_finite() && s > 0.0 => s,
                IsoLines::Spacing(s) => {
                    return Err(IoError::Encode(format!(
                        "iso_lines spacing {s} must be finite and > 0"
                    )))
                }
            };
            if step > 0.0 {
                // Bands are clamped to the range, so that no line is drawn at
                // `hi` itself (nor outside an explicit range).
                let top = ((span / step).ceil() - 1.0).max(0.0);
                // Each cell's band, once (NaN where the value is not finite,
                // which differs from nothing below).
                let bands: Vec<f64> = values
                    .iter()
                    .map(|&v| {
                        if v.is_finite() {
                            // `v >= lo`: truncation is the floor.
                            (((v - lo) / step) as u64 as f64).min(top)
                        } else {
                            f64::NAN
                        }
                    })
                    .collect();
                let differs = |a: f64, b: f64| !a.is_nan() && !b.is_nan() && a != b;
                for r in 0..rows {
                    for c in 0..cols {
                        let i = r * cols + c;
                        let here = bands[i];
                        let right = c + 1 < cols && differs(here, bands[i + 1]);
                        let down = r + 1 < rows && differs(here, bands[i + cols]);
                        if right || down {
                            pixels[i] = contrast(pixels[i]);
                        }
                    }
                }
            }
        }
        pixels
    };
    let raw: Vec<u8> = pixels.drain(..).flatten().collect();
    write_png(ImageBuffer::<Rgb<u8>, _>::from_raw(w, h, raw))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgb(png: &[u8]) -> image::RgbImage {
        image::load_from_memory(png).expect("valid PNG").to_rgb8()
    }

    #[test]
    fn viridis_endpoints_and_monotone_luminance() {
        // Reference values of matplotlib's viridis at 0, 0.5 and 1.
        for (t, want) in [
            (0.0, [68, 1, 84]),
            (0.5, [33, 145, 140]),
            (1.0, [253, 231, 37]),
        ] {
            let got = Colormap::Viridis.at(t);
            for i in 0..3 {
                assert!(got[i].abs_diff(want[i]) <= 4, "t={t}: {got:?} vs {want:?}");
            }
        }
        let luma = |c: [u8; 3]| {
            0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2])
        };
        let mut prev = -1.0;
        for k in 0..=255 {
            let y = luma(Colormap::Viridis.at(f64::from(k) / 255.0));
            assert!(y >= prev - 0.5, "luma drops at {k}: {prev} → {y}");
            prev = y;
        }
    }

    #[test]
    fn special_values_have_their_colours() {
        let a = ArrayData::F64(
            ArrayD::from_shape_vec(vec![1, 4], vec![0.0, 10.0, f64::INFINITY, f64::NAN])
                .expect("shape"),
        );
        let img = rgb(&render_png(&a, &RenderOptions::default()).expect("renders"));
        assert_eq!(img.dimensions(), (4, 1));
        assert_eq!(img.get_pixel(0, 0).0, Colormap::Viridis.at(0.0));
        assert_eq!(img.get_pixel(1, 0).0, Colormap::Viridis.at(1.0));
        assert_eq!(img.get_pixel(2, 0).0, UNREACHED);
        assert_eq!(img.get_pixel(3, 0).0, WALL);
    }

    #[test]
    fn iso_lines_are_drawn_where_bands_change() {
        // U = column index 0..=99 on 3 rows; 4 lines: step 99/5 = 19.8, bands
        // change between columns 19|20, 39|40, 59|60, 79|80.
        let u = ArrayD::from_shape_fn(vec![3, 100], |i| i[1] as f64);
        let options = RenderOptions {
            iso_lines: Some(IsoLines::Count(4)),
            ..Default::default()
        };
        let img = rgb(&render_png(&ArrayData::F64(u), &options).expect("renders"));
        for row in 0..3 {
            let marked: Vec<u32> = (0..100)
                .filter(|&c| img.get_pixel(c, row).0 != Colormap::Viridis.at(f64::from(c) / 99.0))
                .collect();
            assert_eq!(marked, vec![19, 39, 59, 79], "row {row}");
        }
        let bad = RenderOptions {
            iso_lines: Some(IsoLines::Spacing(0.0)),
            ..Default::default()
        };
        assert!(render_png(&ArrayData::F64(ArrayD::zeros(vec![2, 2])), &bad).is_err());
    }

    #[test]
    fn rgb_pictures_are_written_as_they_are() {
        let a = ArrayD::from_shape_fn(vec![2, 3, 3], |i| (10 * i[0] + 3 * i[1] + i[2]) as u8);
        let img = rgb(&render_png(&ArrayData::U8(a), &RenderOptions::default()).expect("renders"));
        assert_eq!(img.dimensions(), (3, 2));
        assert_eq!(img.get_pixel(2, 1).0, [16, 17, 18]);
    }

    #[test]
    fn labels_are_categorical_and_3d_shows_the_middle_slice() {
        // Slices 0, 1, 2 hold labels -1, 0, 1: the middle one (label 0) is shown.
        let labels = ArrayD::from_shape_fn(vec![3, 2, 2], |i| i[0] as i32 - 1);
        let img =
            rgb(&render_png(&ArrayData::I32(labels), &RenderOptions::default()).expect("renders"));
        assert_eq!(img.dimensions(), (2, 2));
        assert!(img.pixels().all(|p| p.0 == label_colour(0)));
        assert_eq!(label_colour(-1), UNREACHED);
        let distinct: std::collections::HashSet<[u8; 3]> = (0..12).map(label_colour).collect();
        assert_eq!(distinct.len(), 12);
    }
}
