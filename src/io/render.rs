//! Colour-mapped 8-bit RGB PNG previews of arrays, for people to look at
//! (not for round trips: use NPY, float TIFF or 16-bit PNG for data).
//!
//! * Continuous values (floats, u8, u16, bool) go through a colour map
//!   ([`Colormap`]): `t = (v - lo) / (hi - lo)` clamped to `[0, 1]`, with
//!   `(lo, hi)` from [`RenderOptions::range`] or the finite minimum and
//!   maximum of the planes shown. `+inf` (unreachable cells of a distance
//!   map) is drawn neutral grey [`UNREACHED`], NaN (walls) black, `-inf`
//!   like `lo`.
//! * Iso-value lines ([`IsoLines`]) are drawn on a cell when
//!   `floor((U - lo) / step)`, clamped to the bands inside `[lo, hi]`,
//!   differs from its right or lower neighbour (both finite); the cell
//!   colour is pushed 60% towards black (light colours) or white (dark
//!   colours).
//! * With [`RenderOptions::colorbar`], a continuous picture gets a colour
//!   bar on its right: the colour map from `lo` (bottom) to `hi` (top), a
//!   tick at every iso value, the labels of `lo`, `hi` and of the ticks that
//!   have room, and below it the line `step <s>` (the iso-line spacing) and
//!   a grey `unreached` swatch when some cell is `+inf`. Text is a 5 × 7
//!   bitmap font ([`super::canvas`]).
//! * Labels (i32, i64 by default) get a qualitative palette of
//!   [`QUALITATIVE`] colours assigned by greedy colouring of the label
//!   adjacency graph (two labels are adjacent when 4-neighbouring cells of
//!   a shown plane carry them; labels in decreasing order of degree, each
//!   takes the first palette colour no coloured neighbour has, else the one
//!   farthest in CIELAB from its neighbours' colours). Neighbouring regions
//!   so get colours at least [`MIN_PALETTE_DELTA_E`] apart; a label's
//!   colour depends on the picture, not only on its value. Negative labels
//!   (no source reached the cell) are grey.
//! * An [`Overlay`] lays the map over a source image of the same shape (grey,
//!   its finite range stretched) with opacity `alpha` (negative labels let
//!   the image through), and draws markers (e.g. the seeds of a
//!   segmentation) as white discs ringed in black, numbered from 0.
//! * A `(rows, cols, 3)` float array is a field of 2D symmetric tensors
//!   `[m00, m01, m11]` (axis 0 first, the order of `ops::spec::tensor`) and
//!   is drawn as glyphs ([`RenderStyle::Tensor`]): on a lattice of one glyph
//!   every `g = ceil(max(rows, cols) / 32)` cells, the unit ball
//!   `{d : dᵀ M d ≤ k²}` of the metric at the lattice cell (long along the
//!   cheap direction), with one `k` for the whole field so that the largest
//!   semi-axis is 0.45 of the lattice step; filled with the colour map at
//!   the anisotropy `1 - λmin/λmax` (colour bar from 0 to 1). Non-positive
//!   tensors are a red cross.
//!
//! 2D arrays `(rows, cols)` give `cols × rows` pixels when nothing is drawn
//! around them. A 3D array shows one plane or a montage ([`View`]): by
//! default the middle slice along axis 0 (index `n0 / 2`), and the picture
//! says so in a caption above it (`slice 0:32 (of 64)`) unless the axis has
//! one slice; `View::Slice` picks the axis and index; `View::Montage` a grid
//! of `count` evenly spaced slices (first and last included), each with its
//! index in its top-left corner, on one colour range. The exception is a
//! `u8` array of shape `(rows, cols, 3)`, which is already an RGB picture
//! and is written as it is.
//!
//! A decorated picture (a colour bar, a caption, a montage, markers) is
//! magnified by `s = clamp(round(384 / side), 1, 8)` (side: the largest side
//! of the map in cells), each cell an `s × s` block, so that the text and
//! markers are not larger than the map; text is drawn at scale
//! `clamp(side_px / 320, 1, 3)`.
//!
//! The colour maps are tables of control points with linear interpolation
//! between them. Viridis and turbo (17 points, `t = k/16`) were computed for
//! this project by evaluating published closed-form fits: the degree-6
//! polynomial fit of matplotlib's viridis, and Anton Mikhailov's polynomial
//! approximation of Google's Turbo. Magma and inferno (11 points, `t =
//! k/10`) are matplotlib's maps sampled at `k/10` (Bokeh's `Magma11` and
//! `Inferno11` palettes).

use std::collections::{BTreeMap, BTreeSet};

use super::canvas::{mix, short_number, text_height, text_width, Canvas};
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

/// Magma at `t = k/10`, `k = 0..=10` (Bokeh's `Magma11`).
const MAGMA: [[u8; 3]; 11] = [
    [0, 0, 3],
    [20, 13, 53],
    [59, 15, 111],
    [99, 25, 127],
    [140, 41, 128],
    [182, 54, 121],
    [221, 73, 104],
    [246, 110, 91],
    [253, 159, 108],
    [253, 205, 144],
    [251, 252, 191],
];

/// Inferno at `t = k/10`, `k = 0..=10` (Bokeh's `Inferno11`).
const INFERNO: [[u8; 3]; 11] = [
    [0, 0, 3],
    [22, 11, 57],
    [66, 10, 104],
    [106, 23, 110],
    [147, 38, 103],
    [188, 55, 84],
    [221, 81, 58],
    [243, 120, 25],
    [252, 165, 10],
    [246, 214, 69],
    [252, 255, 164],
];

/// The qualitative palette of label pictures: Tableau 10 without its grey
/// (too close to [`UNREACHED`]), reordered so that the first colours, the
/// ones greedy colouring uses most, are the most distinct, and three darker
/// colours added.
pub const QUALITATIVE: [[u8; 3]; 12] = [
    [78, 121, 167],  // blue
    [242, 142, 43],  // orange
    [89, 161, 79],   // green
    [225, 87, 89],   // red
    [176, 122, 161], // purple
    [237, 201, 72],  // yellow
    [118, 183, 178], // teal
    [156, 117, 95],  // brown
    [255, 157, 167], // pink
    [31, 58, 147],   // navy
    [140, 209, 125], // light green
    [120, 30, 60],   // wine
];

/// The smallest CIE76 ΔE between two colours of [`QUALITATIVE`] (checked
/// by a test): neighbouring labels are at least this far apart whenever the
/// palette suffices for the greedy colouring.
pub const MIN_PALETTE_DELTA_E: f64 = 15.0;

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
    /// Perceptually uniform, black → purple → orange → pale yellow.
    Magma,
    /// Perceptually uniform, black → purple → orange → bright yellow.
    Inferno,
}

impl Colormap {
    /// Every colour map, for parsers and documentation.
    pub const ALL: [Colormap; 5] = [
        Colormap::Viridis,
        Colormap::Turbo,
        Colormap::Grey,
        Colormap::Magma,
        Colormap::Inferno,
    ];

    /// The lower-case name (`viridis`, `turbo`, `grey`, `magma`, `inferno`).
    pub fn name(self) -> &'static str {
        match self {
            Colormap::Viridis => "viridis",
            Colormap::Turbo => "turbo",
            Colormap::Grey => "grey",
            Colormap::Magma => "magma",
            Colormap::Inferno => "inferno",
        }
    }

    /// The colour at `t` (clamped to `[0, 1]`; NaN gives the colour at 0).
    ///
    /// # Examples
    ///
    /// ```
    /// use geodex::io::Colormap;
    /// assert_eq!(Colormap::Grey.at(0.5), [128, 128, 128]);
    /// assert_eq!(Colormap::Viridis.at(1.0), [252, 231, 33]);
    /// assert_eq!(Colormap::Magma.at(0.0), [0, 0, 3]);
    /// ```
    pub fn at(self, t: f64) -> [u8; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let table: &[[u8; 3]] = match self {
            Colormap::Viridis => &VIRIDIS,
            Colormap::Turbo => &TURBO,
            Colormap::Magma => &MAGMA,
            Colormap::Inferno => &INFERNO,
            // Rounded and clamped, so the cast is exact.
            Colormap::Grey => return [round_u8(t * 255.0); 3],
        };
        let x = t * (table.len() - 1) as f64;
        // In 0..=len-1 since t is in [0, 1].
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
    /// Categorical for i32 and i64 arrays (labels), tensor glyphs for float
    /// arrays of shape `(rows, cols, 3)`, continuous otherwise.
    #[default]
    Auto,
    /// Colour map over a value range.
    Continuous,
    /// One colour per integer label (values are truncated to integers).
    Categorical,
    /// A `(rows, cols, 3)` field of 2D tensors `[m00, m01, m11]` as glyphs.
    Tensor,
}

/// The planes of a 3D array that are shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum View {
    /// 2D: the array; 3D: the middle slice along axis 0, named in a caption.
    #[default]
    Auto,
    /// The slice `index` along `axis`.
    Slice {
        /// 0, 1 or 2.
        axis: usize,
        /// `0..n[axis]`.
        index: usize,
    },
    /// `count` slices along `axis`, evenly spaced from the first to the last
    /// (all of them when `count >= n[axis]`), in a grid.
    Montage {
        /// 0, 1 or 2.
        axis: usize,
        /// At least 1.
        count: usize,
    },
}

/// Options of [`render_png`]. `RenderOptions::default()` is an automatic
/// style, viridis, the finite min..max range, no iso lines, no colour bar
/// and the automatic view.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderOptions {
    /// Continuous, categorical or tensor glyphs.
    pub style: RenderStyle,
    /// The colour map of continuous values.
    pub colormap: Colormap,
    /// Values mapped to the two ends of the colour map; default the finite
    /// minimum and maximum. Must be finite with low < high.
    pub range: Option<(f64, f64)>,
    /// Iso-value lines (continuous style only).
    pub iso_lines: Option<IsoLines>,
    /// A colour bar beside a continuous picture (and a tensor picture).
    pub colorbar: bool,
    /// The planes of a 3D array that are shown.
    pub view: View,
}

/// The iso-value lines a map's picture gets unless others are asked for: 10
/// on a float field (a distance map), none on labels or images. The service
/// (`?format=png`) and the command line (`--out U.png`) draw the same picture.
pub fn default_iso_lines(array: &ArrayData) -> Option<IsoLines> {
    matches!(array, ArrayData::F64(_) | ArrayData::F32(_)).then_some(IsoLines::Count(10))
}

/// What is drawn over a map besides its values.
#[derive(Debug, Clone, Copy, Default)]
pub struct Overlay<'a> {
    /// A source image of the array's shape, drawn in grey under the map.
    pub image: Option<&'a ArrayData>,
    /// Opacity of the map over `image`, in `[0, 1]`.
    pub alpha: f64,
    /// Points to mark, index coordinates (axis 0 first), one coordinate per
    /// axis of the array; in 3D drawn on the slices they lie on (rounded).
    pub markers: &'a [Vec<f64>],
}

/// A rendering option that does not fit the array: `option` names it
/// (`range`, `iso_lines`, `view`, `style`, `overlay`, `alpha`, `markers`).
#[derive(Debug, Clone, PartialEq)]
pub struct OptionError {
    /// The option at fault.
    pub option: &'static str,
    /// Why, and what would do.
    pub reason: String,
}

impl std::fmt::Display for OptionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.option, self.reason)
    }
}

fn refuse(option: &'static str, reason: impl Into<String>) -> OptionError {
    OptionError {
        option,
        reason: reason.into(),
    }
}

/// A colour of the golden-ratio palette for label `k` (negative: grey),
/// used where a label's colour must not depend on the picture (mesh
/// vertex colours).
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

/// CIELAB `(L*, a*, b*)` of an sRGB colour (D65 white).
pub fn lab(c: [u8; 3]) -> [f64; 3] {
    let lin = |v: u8| {
        let v = f64::from(v) / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let (r, g, b) = (lin(c[0]), lin(c[1]), lin(c[2]));
    let x = (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.950_47;
    let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    let z = (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.088_83;
    let f = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIE76 colour difference: the Euclidean distance in CIELAB.
pub fn delta_e(a: [u8; 3], b: [u8; 3]) -> f64 {
    let (p, q) = (lab(a), lab(b));
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

/// One plane shown: `rows × cols` values (C order), the axis and index it
/// is the slice of (3D), and its caption in a montage.
struct Plane {
    rows: usize,
    cols: usize,
    values: Vec<f64>,
    slice: Option<(usize, usize)>,
}

/// The slice `index` along `axis` of a `[n0, n1, n2]` array (C order).
fn slice_of(shape: [usize; 3], values: &[f64], axis: usize, index: usize) -> Plane {
    let [n0, n1, n2] = shape;
    let (rows, cols) = match axis {
        0 => (n1, n2),
        1 => (n0, n2),
        _ => (n0, n1),
    };
    let mut out = Vec::with_capacity(rows * cols);
    for u in 0..rows {
        for v in 0..cols {
            let (i, j, k) = match axis {
                0 => (index, u, v),
                1 => (u, index, v),
                _ => (u, v, index),
            };
            out.push(values[(i * n1 + j) * n2 + k]);
        }
    }
    Plane {
        rows,
        cols,
        values: out,
        slice: Some((axis, index)),
    }
}

/// Checks that `view` fits an array of shape `shape`.
fn check_view(shape: &[usize], view: View) -> Result<(), OptionError> {
    match (shape, view) {
        (&[_, _], View::Auto) => Ok(()),
        (&[_, _], _) => Err(refuse(
            "view",
            "a 2D array has one plane; slice and montage need a 3D array",
        )),
        (&[_, _, _], View::Auto) => Ok(()),
        (&[_, _, _], View::Slice { axis, index }) => {
            if axis > 2 {
                return Err(refuse("view", format!("axis {axis} must be 0, 1 or 2")));
            }
            if index >= shape[axis] {
                return Err(refuse(
                    "view",
                    format!("index {index} is outside 0..{} of axis {axis}", shape[axis]),
                ));
            }
            Ok(())
        }
        (&[_, _, _], View::Montage { axis, count }) => {
            if axis > 2 {
                return Err(refuse("view", format!("axis {axis} must be 0, 1 or 2")));
            }
            if count == 0 || count > MAX_MONTAGE {
                return Err(refuse(
                    "view",
                    format!("a montage shows 1 to {MAX_MONTAGE} slices, not {count}"),
                ));
            }
            Ok(())
        }
        _ => Err(refuse(
            "view",
            format!("a rendering needs a non-empty 2D or 3D array, got shape {shape:?}"),
        )),
    }
}

/// The most slices a montage shows.
pub const MAX_MONTAGE: usize = 64;

/// The planes of `view` (checked by [`check_view`]) and the caption above
/// the picture.
fn planes(
    shape: &[usize],
    values: &[f64],
    view: View,
) -> Result<(Vec<Plane>, Option<String>), OptionError> {
    check_view(shape, view)?;
    if let &[rows, cols] = shape {
        let plane = Plane {
            rows,
            cols,
            values: values.to_vec(),
            slice: None,
        };
        return Ok((vec![plane], None));
    }
    let s = [shape[0], shape[1], shape[2]];
    Ok(match view {
        View::Auto => {
            let (n0, mid) = (s[0], s[0] / 2);
            let caption = (n0 > 1).then(|| format!("slice 0:{mid} (of {n0})"));
            (vec![slice_of(s, values, 0, mid)], caption)
        }
        View::Slice { axis, index } => {
            let caption = format!("slice {axis}:{index} (of {})", s[axis]);
            (vec![slice_of(s, values, axis, index)], Some(caption))
        }
        View::Montage { axis, count } => {
            let n = s[axis];
            let count = count.min(n);
            let indices: Vec<usize> = if count == 1 {
                vec![n / 2]
            } else {
                (0..count)
                    .map(|k| ((k * (n - 1)) as f64 / (count - 1) as f64).round() as usize)
                    .collect()
            };
            let caption = format!("axis {axis}: {count} of {n} slices");
            let planes = indices
                .into_iter()
                .map(|i| slice_of(s, values, axis, i))
                .collect();
            (planes, Some(caption))
        }
    })
}

/// Pushes a colour 60% towards black (light colours) or white (dark ones).
fn contrast(c: [u8; 3]) -> [u8; 3] {
    let luma = 0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2]);
    let target = if luma >= 100.0 { 0.0 } else { 255.0 };
    c.map(|v| round_u8(f64::from(v) * 0.4 + target * 0.6))
}

/// The iso-line step of `lines` over a span.
fn iso_step(lines: IsoLines, span: f64) -> Result<f64, OptionError> {
    match lines {
        IsoLines::Count(0) => Err(refuse("iso_lines", "count must be at least 1")),
        IsoLines::Count(n) => Ok(span / (n as f64 + 1.0)),
        IsoLines::Spacing(s) if s.is_finite() && s > 0.0 => Ok(s),
        IsoLines::Spacing(s) => Err(refuse(
            "iso_lines",
            format!("spacing {s} must be finite and > 0"),
        )),
    }
}

/// The finite range of values, or `range` checked.
fn finite_range(values: &[f64], range: Option<(f64, f64)>) -> Result<(f64, f64), OptionError> {
    if let Some((lo, hi)) = range {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(refuse(
                "range",
                format!("({lo}, {hi}) must be finite with low < high"),
            ));
        }
        return Ok((lo, hi));
    }
    Ok(super::raster::finite_min_max(values))
}

/// Colours of a continuous plane, with its iso lines.
fn continuous_pixels(
    plane: &Plane,
    colormap: Colormap,
    (lo, hi): (f64, f64),
    step: Option<f64>,
) -> Vec<[u8; 3]> {
    let span = hi - lo;
    let (rows, cols) = (plane.rows, plane.cols);
    let values = &plane.values;
    let mut pixels: Vec<[u8; 3]> = values
        .iter()
        .map(|&v| {
            if v.is_nan() {
                WALL
            } else if v == f64::INFINITY {
                UNREACHED
            } else if span > 0.0 {
                colormap.at((v - lo) / span)
            } else {
                colormap.at(0.0)
            }
        })
        .collect();
    if let Some(step) = step.filter(|&s| s > 0.0) {
        // Bands are clamped to the range, so that no line is drawn at
        // `hi` itself (nor outside an explicit range).
        let top = ((span / step).ceil() - 1.0).max(0.0);
        // Each cell's band, once (NaN where the value is not finite,
        // which differs from nothing below).
        let bands: Vec<f64> = values
            .iter()
            .map(|&v| {
                if v.is_finite() {
                    // Clamped below at 0, so truncation is the floor.
                    (((v - lo) / step).max(0.0) as u64 as f64).min(top)
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
    pixels
}

/// The colour of every label shown: greedy colouring of the adjacency of
/// the labels (4-neighbours within each plane) with [`QUALITATIVE`], labels
/// taken in decreasing degree (then increasing value).
fn label_palette(planes: &[Plane]) -> BTreeMap<i64, [u8; 3]> {
    let mut adjacent: BTreeMap<i64, BTreeSet<i64>> = BTreeMap::new();
    for p in planes {
        let label = |i: usize| {
            let v = p.values[i];
            (v.is_finite() && v >= 0.0).then_some(v as i64)
        };
        for r in 0..p.rows {
            for c in 0..p.cols {
                let i = r * p.cols + c;
                let Some(a) = label(i) else { continue };
                adjacent.entry(a).or_default();
                let mut link = |j: usize| {
                    if let Some(b) = label(j) {
                        if b != a {
                            adjacent.entry(a).or_default().insert(b);
                            adjacent.entry(b).or_default().insert(a);
                        }
                    }
                };
                if c + 1 < p.cols {
                    link(i + 1);
                }
                if r + 1 < p.rows {
                    link(i + p.cols);
                }
            }
        }
    }
    let mut order: Vec<i64> = adjacent.keys().copied().collect();
    order.sort_by_key(|k| (std::cmp::Reverse(adjacent[k].len()), *k));
    let mut colour: BTreeMap<i64, usize> = BTreeMap::new();
    for k in order {
        let used: Vec<usize> = adjacent[&k]
            .iter()
            .filter_map(|n| colour.get(n).copied())
            .collect();
        let free = (0..QUALITATIVE.len()).find(|c| !used.contains(c));
        let pick = free.unwrap_or_else(|| {
            // Every colour is taken by a neighbour: the one farthest from
            // the neighbours' colours, counted by how many use it.
            (0..QUALITATIVE.len())
                .min_by_key(|c| used.iter().filter(|u| *u == c).count())
                .unwrap_or(0)
        });
        colour.insert(k, pick);
    }
    colour
        .into_iter()
        .map(|(k, c)| (k, QUALITATIVE[c]))
        .collect()
}

/// Grey values of a source image's planes, its finite range stretched.
fn grey_planes(image: &[Plane]) -> Vec<Vec<[u8; 3]>> {
    let all: Vec<f64> = image
        .iter()
        .flat_map(|p| p.values.iter().copied())
        .collect();
    let (lo, hi) = finite_range(&all, None).unwrap_or((0.0, 1.0));
    let span = if hi > lo { hi - lo } else { 1.0 };
    image
        .iter()
        .map(|p| {
            p.values
                .iter()
                .map(|&v| {
                    if v.is_finite() {
                        Colormap::Grey.at((v - lo) / span)
                    } else {
                        WALL
                    }
                })
                .collect()
        })
        .collect()
}

/// The magnification of a decorated picture whose map has `side` cells on
/// its largest side.
fn magnification(side: usize) -> usize {
    ((384.0 / side.max(1) as f64).round() as usize).clamp(1, 8)
}

/// The text scale of a picture whose map has `side` pixels on its largest side.
fn text_scale(side: usize) -> usize {
    (side / 320).clamp(1, 3)
}

/// The colour bar beside a picture.
struct Bar {
    colormap: Colormap,
    lo: f64,
    hi: f64,
    /// Values with a tick (the iso values).
    ticks: Vec<f64>,
    /// Lines of text under the bar.
    footer: Vec<String>,
    /// Whether to show the `unreached` swatch.
    unreached: bool,
}

/// The map with a caption strip above it and a colour bar on its right
/// (either may be absent); white background, black text.
fn compose(map: Canvas, caption: Option<&str>, bar: Option<&Bar>, ts: usize) -> Canvas {
    let th = text_height(ts);
    let line = th + 2 * ts;
    let header_h = if caption.is_some() { line + 2 * ts } else { 0 };
    let Some(bar) = bar else {
        let Some(caption) = caption else { return map };
        let w = map.width.max(text_width(caption, ts) + 4 * ts);
        let mut out = Canvas::new(w, header_h + map.height, [255; 3]);
        out.text(2 * ts as i64, 2 * ts as i64, ts, caption, [0; 3]);
        out.paste(&map, 0, header_h);
        return out;
    };
    let labels: Vec<(f64, String)> = std::iter::once(bar.hi)
        .chain(std::iter::once(bar.lo))
        .chain(bar.ticks.iter().copied())
        .map(|v| (v, short_number(v)))
        .collect();
    let label_w = labels
        .iter()
        .map(|(_, s)| text_width(s, ts))
        .max()
        .unwrap_or(0);
    let mut footer: Vec<String> = bar.footer.clone();
    if bar.unreached {
        footer.push("   unreached".into());
    }
    let footer_w = footer.iter().map(|s| text_width(s, ts)).max().unwrap_or(0);
    let footer_h = footer.len() * (th + 3 * ts);
    let bar_w = 10 * ts;
    let gap = 6 * ts;
    let panel_w = (bar_w + 4 * ts + label_w).max(footer_w) + gap + 4 * ts;
    let body_h = map.height.max(footer_h + 8 * line);
    let width = (map.width + panel_w).max(caption.map_or(0, |c| text_width(c, ts) + 4 * ts));
    let mut out = Canvas::new(width, header_h + body_h, [255; 3]);
    if let Some(c) = caption {
        out.text(2 * ts as i64, 2 * ts as i64, ts, c, [0; 3]);
    }
    out.paste(&map, 0, header_h);
    let x0 = (map.width + gap) as i64;
    let y_top = (header_h + th / 2 + ts) as i64;
    let y_bot = (header_h + body_h - footer_h - th / 2 - 2 * ts) as i64;
    let extent = (y_bot - y_top).max(1) as f64;
    for y in y_top..=y_bot {
        let t = (y_bot - y) as f64 / extent;
        out.fill_rect(x0, y, bar_w, 1, bar.colormap.at(t));
    }
    // Outline.
    let black = [0u8; 3];
    out.fill_rect(x0 - 1, y_top - 1, bar_w + 2, 1, black);
    out.fill_rect(x0 - 1, y_bot + 1, bar_w + 2, 1, black);
    out.fill_rect(x0 - 1, y_top - 1, 1, (y_bot - y_top + 3) as usize, black);
    out.fill_rect(
        x0 + bar_w as i64,
        y_top - 1,
        1,
        (y_bot - y_top + 3) as usize,
        black,
    );
    let span = bar.hi - bar.lo;
    let y_of = |v: f64| {
        let t = if span > 0.0 { (v - bar.lo) / span } else { 0.0 };
        y_bot - (t.clamp(0.0, 1.0) * extent).round() as i64
    };
    let few_ticks = bar.ticks.len() <= 64;
    if few_ticks {
        for &v in &bar.ticks {
            let y = y_of(v);
            let c = out.get(x0 as usize, y as usize).unwrap_or(black);
            out.fill_rect(x0, y, bar_w, 1, contrast(c));
            out.fill_rect(x0 + bar_w as i64, y, 2 * ts, 1, black);
        }
    }
    // Labels: hi and lo always, then the ticks that do not touch a label.
    let tx = x0 + (bar_w + 4 * ts) as i64;
    let mut placed: Vec<i64> = Vec::new();
    for (k, (v, s)) in labels.iter().enumerate() {
        if k >= 2 && !few_ticks {
            break;
        }
        let y = y_of(*v);
        if k >= 2 && placed.iter().any(|&p| (p - y).abs() < (th + 2 * ts) as i64) {
            continue;
        }
        placed.push(y);
        out.text(tx, y - (th / 2) as i64, ts, s, black);
    }
    let mut fy = (header_h + body_h - footer_h + ts) as i64;
    for s in &footer {
        out.text(x0, fy, ts, s, black);
        fy += (th + 3 * ts) as i64;
    }
    if bar.unreached {
        let y = fy - (th + 3 * ts) as i64;
        out.fill_rect(x0, y, 2 * CELL_PX * ts, th, UNREACHED);
    }
    out
}

/// Width in pixels of the swatch before `unreached`, in font pixels per scale.
const CELL_PX: usize = 6;

/// Checks `options` and `overlay` against `array` without drawing anything
/// (what the service does to name the query parameter at fault).
///
/// # Errors
///
/// [`OptionError`] naming the option that does not fit.
pub fn check_options(
    array: &ArrayData,
    options: &RenderOptions,
    overlay: &Overlay<'_>,
) -> Result<(), OptionError> {
    let shape = array.shape();
    let tensor = is_tensor(shape, options.style, Some(array));
    if let Some(r) = options.range {
        finite_range(&[], Some(r))?;
    }
    if let Some(lines) = options.iso_lines {
        iso_step(lines, 1.0)?;
    }
    if !(overlay.alpha.is_finite() && (0.0..=1.0).contains(&overlay.alpha)) {
        return Err(refuse(
            "alpha",
            format!("{} must be in [0, 1]", overlay.alpha),
        ));
    }
    if let Some(image) = overlay.image {
        if image.shape() != shape {
            return Err(refuse(
                "overlay",
                format!(
                    "the image has shape {:?}, the array {shape:?}: they must match",
                    image.shape()
                ),
            ));
        }
    }
    for (k, m) in overlay.markers.iter().enumerate() {
        let nd = if tensor { 2 } else { shape.len() };
        if m.len() != nd {
            return Err(refuse(
                "markers",
                format!(
                    "marker {k} has {} coordinates, the array {nd} axes",
                    m.len()
                ),
            ));
        }
        for (axis, (&x, &n)) in m.iter().zip(shape).enumerate() {
            if !(x.is_finite() && x > -0.5 && x < n as f64 - 0.5) {
                return Err(refuse(
                    "markers",
                    format!("marker {k}: coordinate {x} is outside axis {axis} (0..{n})"),
                ));
            }
        }
    }
    if tensor {
        if options.view != View::Auto {
            return Err(refuse(
                "view",
                "a tensor field is one 2D plane of glyphs: no slice or montage",
            ));
        }
        if shape.len() != 3 || shape[2] != 3 {
            return Err(refuse(
                "style",
                format!("tensor glyphs need a (rows, cols, 3) array, got {shape:?}"),
            ));
        }
    } else {
        check_view(shape, options.view)?;
    }
    Ok(())
}

/// Whether the array is drawn as tensor glyphs.
fn is_tensor(shape: &[usize], style: RenderStyle, array: Option<&ArrayData>) -> bool {
    match style {
        RenderStyle::Tensor => true,
        RenderStyle::Auto => {
            matches!(shape, [_, _, 3])
                && array.is_some_and(|a| matches!(a, ArrayData::F32(_) | ArrayData::F64(_)))
        }
        _ => false,
    }
}

/// Renders an array as an 8-bit RGB PNG (see the [module](self) docs for
/// the colours, iso lines, colour bar and the slices shown of 3D arrays).
///
/// # Errors
///
/// [`IoError::Encode`] for arrays that are not non-empty 2D/3D, an invalid
/// `range`, an iso-line `Count(0)` / non-positive `Spacing`, or a view that
/// does not fit the array.
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
    render(array, options, &Overlay::default())?.to_png()
}

/// [`render_png`] with an [`Overlay`].
///
/// # Errors
///
/// As [`render_png`], and for an overlay that does not fit (see
/// [`check_options`]).
pub fn render_png_over(
    array: &ArrayData,
    options: &RenderOptions,
    overlay: &Overlay<'_>,
) -> Result<Vec<u8>, IoError> {
    render(array, options, overlay)?.to_png()
}

/// The picture of [`render_png_over`] as a canvas.
///
/// # Errors
///
/// As [`render_png_over`].
pub fn render(
    array: &ArrayData,
    options: &RenderOptions,
    overlay: &Overlay<'_>,
) -> Result<Canvas, IoError> {
    let shape = array.shape().to_vec();
    if shape.is_empty() || shape.contains(&0) {
        return Err(IoError::Encode(format!(
            "a rendering needs a non-empty 2D or 3D array, got shape {shape:?}"
        )));
    }
    if let ArrayData::U8(a) = array {
        if let [rows, cols, 3] = shape[..] {
            if options.style == RenderStyle::Auto {
                // Already a picture (e.g. a mesh drawn over its image): as is.
                let pixels = a
                    .as_slice_memory_order()
                    .map(<[u8]>::to_vec)
                    .unwrap_or_else(|| a.iter().copied().collect());
                return Ok(Canvas {
                    width: cols,
                    height: rows,
                    pixels: pixels.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
                });
            }
        }
    }
    let encode = |e: OptionError| IoError::Encode(e.to_string());
    check_options(array, options, overlay).map_err(encode)?;
    let values = to_f64_vec(array);
    if is_tensor(&shape, options.style, Some(array)) {
        return Ok(tensor_glyphs(
            shape[0],
            shape[1],
            &values,
            options,
            overlay.markers,
        ));
    }
    let (planes, caption) = planes(&shape, &values, options.view).map_err(encode)?;
    let under = match overlay.image {
        Some(image) => {
            let (p, _) = planes_of(&shape, image, options.view).map_err(encode)?;
            Some(grey_planes(&p))
        }
        None => None,
    };
    let categorical = match options.style {
        RenderStyle::Auto => matches!(array, ArrayData::I32(_) | ArrayData::I64(_)),
        RenderStyle::Continuous | RenderStyle::Tensor => false,
        RenderStyle::Categorical => true,
    };
    let montage = matches!(options.view, View::Montage { .. });
    let decorated =
        options.colorbar && !categorical || caption.is_some() || !overlay.markers.is_empty();
    let (rows, cols) = (planes[0].rows, planes[0].cols);
    let n = planes.len();
    let grid_cols = (n as f64).sqrt().ceil() as usize;
    let grid_rows = n.div_ceil(grid_cols);
    let gap = usize::from(montage) * 2;
    let s = if decorated {
        magnification((cols * grid_cols).max(rows * grid_rows))
    } else {
        1
    };
    let (tw, th) = (cols * s, rows * s);
    let map_w = grid_cols * tw + (grid_cols - 1) * gap;
    let map_h = grid_rows * th + (grid_rows - 1) * gap;
    let ts = text_scale(map_w.max(map_h));
    let mut map = Canvas::new(map_w, map_h, [40; 3]);
    let all: Vec<f64> = planes
        .iter()
        .flat_map(|p| p.values.iter().copied())
        .collect();
    let mut bar = None;
    let palette = categorical.then(|| label_palette(&planes));
    let (range, step) = if categorical {
        ((0.0, 1.0), None)
    } else {
        let range = finite_range(&all, options.range).map_err(encode)?;
        let step = match options.iso_lines {
            Some(l) => Some(iso_step(l, range.1 - range.0).map_err(encode)?),
            None => None,
        };
        (range, step)
    };
    for (k, plane) in planes.iter().enumerate() {
        let mut pixels = match &palette {
            Some(palette) => plane
                .values
                .iter()
                .map(|&v| {
                    if v.is_nan() {
                        WALL
                    } else if v < 0.0 {
                        UNREACHED
                    } else {
                        palette.get(&(v as i64)).copied().unwrap_or(UNREACHED)
                    }
                })
                .collect(),
            None => continuous_pixels(plane, options.colormap, range, step),
        };
        if let Some(under) = &under {
            for (i, p) in pixels.iter_mut().enumerate() {
                let v = plane.values[i];
                let see_through = categorical && (v < 0.0 || v.is_nan());
                let alpha = if see_through { 0.0 } else { overlay.alpha };
                *p = mix(under[k][i], *p, alpha);
            }
        }
        let (x0, y0) = ((k % grid_cols) * (tw + gap), (k / grid_cols) * (th + gap));
        for r in 0..plane.rows {
            for c in 0..plane.cols {
                map.fill_rect(
                    (x0 + c * s) as i64,
                    (y0 + r * s) as i64,
                    s,
                    s,
                    pixels[r * plane.cols + c],
                );
            }
        }
        draw_markers(&mut map, plane, overlay.markers, (x0, y0), s, ts);
        if montage {
            if let Some((_, index)) = plane.slice {
                map.label(
                    (x0 + ts) as i64,
                    (y0 + ts) as i64,
                    ts,
                    &index.to_string(),
                    [255; 3],
                    [0; 3],
                );
            }
        }
    }
    if options.colorbar && !categorical {
        let (lo, hi) = range;
        // The iso values strictly inside the range (a relative margin, so
        // that `count` lines give `count` ticks whatever the rounding).
        let ticks: Vec<f64> = match step {
            Some(st) if st > 0.0 => (1..=10_000)
                .map(|k| lo + f64::from(k) * st)
                .take_while(|&v| v < hi - 1e-9 * (hi - lo))
                .collect(),
            _ => Vec::new(),
        };
        bar = Some(Bar {
            colormap: options.colormap,
            lo,
            hi,
            footer: step
                .map(|st| vec![format!("step {}", short_number(st))])
                .unwrap_or_default(),
            ticks,
            unreached: all.contains(&f64::INFINITY),
        });
    }
    Ok(compose(map, caption.as_deref(), bar.as_ref(), ts))
}

/// The planes of another array of the same shape under the same view.
fn planes_of(
    shape: &[usize],
    image: &ArrayData,
    view: View,
) -> Result<(Vec<Plane>, Option<String>), OptionError> {
    planes(shape, &to_f64_vec(image), view)
}

/// Draws the markers that lie on `plane` (all of them in 2D) into the tile
/// at `origin`, cells magnified `s` times: a white disc ringed in black and
/// the marker's number.
fn draw_markers(
    map: &mut Canvas,
    plane: &Plane,
    markers: &[Vec<f64>],
    origin: (usize, usize),
    s: usize,
    ts: usize,
) {
    let r = 2.0 + 1.5 * ts as f64;
    for (k, m) in markers.iter().enumerate() {
        let (row, col) = match plane.slice {
            None => (m[0], m[1]),
            Some((axis, index)) => {
                if m[axis].round() as usize != index {
                    continue;
                }
                let rest: Vec<f64> = (0..3).filter(|&a| a != axis).map(|a| m[a]).collect();
                (rest[0], rest[1])
            }
        };
        if row < -0.5 || col < -0.5 || row >= plane.rows as f64 || col >= plane.cols as f64 {
            continue;
        }
        let x = origin.0 as f64 + (col + 0.5) * s as f64 - 0.5;
        let y = origin.1 as f64 + (row + 0.5) * s as f64 - 0.5;
        map.disc(x, y, r + 1.5, [0; 3]);
        map.disc(x, y, r, [255; 3]);
        map.label(
            (x + r + 2.0) as i64,
            (y - r - 2.0 - text_height(ts) as f64) as i64,
            ts,
            &k.to_string(),
            [255; 3],
            [0; 3],
        );
    }
}

/// The eigenvalues `(λmin, λmax)` of `[[a, b], [b, d]]`.
fn eigen2(a: f64, b: f64, d: f64) -> (f64, f64) {
    let mean = 0.5 * (a + d);
    let r = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    (mean - r, mean + r)
}

/// Tensor glyphs (see the [module](self) docs).
fn tensor_glyphs(
    rows: usize,
    cols: usize,
    values: &[f64],
    options: &RenderOptions,
    markers: &[Vec<f64>],
) -> Canvas {
    let g = rows.max(cols).div_ceil(32).max(1);
    let s = 16usize.div_ceil(g).clamp(1, 16);
    let (w, h) = (cols * s, rows * s);
    let mut canvas = Canvas::new(w, h, [236; 3]);
    let tensor = |i: usize, j: usize| {
        let k = 3 * (i * cols + j);
        (values[k], values[k + 1], values[k + 2])
    };
    let centre = |n: usize| {
        (0..n.div_ceil(g))
            .map(move |q| q * g + g / 2)
            .filter(move |&c| c < n)
    };
    // One k for the field: the largest semi-axis 1/sqrt(λmin) is 0.45 g s.
    let mut lmin_all = f64::INFINITY;
    for i in centre(rows) {
        for j in centre(cols) {
            let (a, b, d) = tensor(i, j);
            let (l0, _) = eigen2(a, b, d);
            if l0.is_finite() && l0 > 0.0 && a.is_finite() && b.is_finite() && d.is_finite() {
                lmin_all = lmin_all.min(l0);
            }
        }
    }
    let radius = 0.45 * (g * s) as f64;
    let k = radius * lmin_all.sqrt();
    for i in centre(rows) {
        for j in centre(cols) {
            let (a, b, d) = tensor(i, j);
            let (l0, l1) = eigen2(a, b, d);
            let (cy, cx) = (
                (i as f64 + 0.5) * s as f64 - 0.5,
                (j as f64 + 0.5) * s as f64 - 0.5,
            );
            let ok = [a, b, d, l0].iter().all(|v| v.is_finite()) && l0 > 0.0 && k.is_finite();
            if !ok {
                let r = (0.2 * radius).max(1.0);
                let red = [210, 30, 30];
                canvas.segment([cx - r, cy - r], [cx + r, cy + r], 0.0, red);
                canvas.segment([cx - r, cy + r], [cx + r, cy - r], 0.0, red);
                continue;
            }
            let colour = options.colormap.at(1.0 - l0 / l1);
            let reach = (k / l0.sqrt()).ceil() as i64;
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let (fy, fx) = (dy as f64, dx as f64);
                    // Axis 0 is the row (y), axis 1 the column (x).
                    if a * fy * fy + 2.0 * b * fy * fx + d * fx * fx <= k * k {
                        canvas.set(cx.round() as i64 + dx, cy.round() as i64 + dy, colour);
                    }
                }
            }
            canvas.set(cx.round() as i64, cy.round() as i64, [0; 3]);
        }
    }
    let ts = text_scale(w.max(h));
    let plane = Plane {
        rows,
        cols,
        values: Vec::new(),
        slice: None,
    };
    draw_markers(&mut canvas, &plane, markers, (0, 0), s, ts);
    let caption = format!("unit balls of m, every {g} cells");
    let bar = options.colorbar.then(|| Bar {
        colormap: options.colormap,
        lo: 0.0,
        hi: 1.0,
        ticks: Vec::new(),
        footer: vec!["1-lmin/lmax".into()],
        unreached: false,
    });
    compose(canvas, Some(&caption), bar.as_ref(), ts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::ArrayD;

    fn rgb(png: &[u8]) -> image::RgbImage {
        image::load_from_memory(png).expect("valid PNG").to_rgb8()
    }

    fn luma(c: [u8; 3]) -> f64 {
        0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2])
    }

    /// Writes a picture to `/tmp/pics/<name>.png` when `GEODEX_PICS` is set
    /// (to look at them), else nothing.
    fn keep(name: &str, png: &[u8]) {
        if std::env::var_os("GEODEX_PICS").is_some() {
            let _ = std::fs::create_dir_all("/tmp/pics");
            let _ = std::fs::write(format!("/tmp/pics/{name}.png"), png);
        }
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
        for map in [
            Colormap::Viridis,
            Colormap::Magma,
            Colormap::Inferno,
            Colormap::Grey,
        ] {
            let mut prev = -1.0;
            for k in 0..=255 {
                let y = luma(map.at(f64::from(k) / 255.0));
                assert!(y >= prev - 0.5, "{map:?}: luma drops at {k}: {prev} → {y}");
                prev = y;
            }
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

    /// A distance map from the corner, 64 × 64.
    fn corner_distance() -> ArrayData {
        ArrayData::F64(ArrayD::from_shape_fn(vec![64, 64], |i| {
            (i[0] as f64).hypot(i[1] as f64)
        }))
    }

    #[test]
    fn colour_bar_is_beside_the_map_with_monotone_colours_and_labels() {
        let options = RenderOptions {
            iso_lines: Some(IsoLines::Count(4)),
            colorbar: true,
            ..Default::default()
        };
        let png = render_png(&corner_distance(), &options).expect("renders");
        keep("colorbar_viridis", &png);
        let img = rgb(&png);
        // Magnified 384 / 64 = 6 times; text scale 1; the bar 6 px right of the map.
        let (x0, bar_w) = (390u32, 10u32);
        assert!(img.width() > x0 + bar_w + 20, "width {}", img.width());
        assert_eq!(img.height(), 384);
        let x = x0 + bar_w / 2;
        let column: Vec<[u8; 3]> = (0..img.height()).map(|y| img.get_pixel(x, y).0).collect();
        // The outline: black at the top and the bottom of the bar only.
        let black: Vec<usize> = (0..column.len()).filter(|&y| column[y] == [0; 3]).collect();
        assert_eq!(black.len(), 2, "{black:?}");
        let (top, bottom) = (black[0] + 1, black[1] - 1);
        assert!(bottom - top > 300, "bar from {top} to {bottom}");
        assert_eq!(column[top], Colormap::Viridis.at(1.0));
        assert_eq!(column[bottom], Colormap::Viridis.at(0.0));
        // Luminance falls going down, but at the 4 iso ticks.
        let rises = (top..bottom)
            .filter(|&y| luma(column[y + 1]) > luma(column[y]) + 0.5)
            .count();
        assert_eq!(rises, 4, "one rise per tick");
        // Labels: dark text pixels right of the bar, left of the picture's edge.
        let text = (x0 + bar_w + 4..img.width())
            .flat_map(|x| (0..img.height()).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == [0; 3])
            .count();
        assert!(text > 100, "{text} text pixels");
        // The map is at the top left, magnified: cell (0, 0) is a 6 × 6 block.
        assert_eq!(img.get_pixel(5, 5).0, Colormap::Viridis.at(0.0));
        // Other maps: the bar follows the map asked for.
        let magma = RenderOptions {
            colormap: Colormap::Magma,
            colorbar: true,
            range: Some((0.0, 50.0)),
            iso_lines: Some(IsoLines::Spacing(10.0)),
            ..Default::default()
        };
        let png = render_png(&corner_distance(), &magma).expect("renders");
        keep("colorbar_magma", &png);
        let img = rgb(&png);
        let column: Vec<[u8; 3]> = (0..img.height()).map(|y| img.get_pixel(x, y).0).collect();
        let black: Vec<usize> = (0..column.len()).filter(|&y| column[y] == [0; 3]).collect();
        assert_eq!(column[black[0] + 1], Colormap::Magma.at(1.0));
        assert_eq!(column[black[black.len() - 1] - 1], Colormap::Magma.at(0.0));
    }

    #[test]
    fn unreached_cells_get_a_swatch_under_the_bar() {
        let mut u = ArrayD::from_shape_fn(vec![32, 32], |i| i[0] as f64);
        u[[0, 0]] = f64::INFINITY;
        let options = RenderOptions {
            colorbar: true,
            ..Default::default()
        };
        let png = render_png(&ArrayData::F64(u), &options).expect("renders");
        keep("colorbar_unreached", &png);
        let img = rgb(&png);
        // Magnified 12 times, capped at 8.
        let map_w = 32 * 8;
        let grey = (map_w..img.width())
            .flat_map(|x| (0..img.height()).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == UNREACHED)
            .count();
        assert!(grey >= 40, "{grey} swatch pixels");
    }

    #[test]
    fn the_qualitative_palette_keeps_its_colours_apart() {
        let mut min = f64::INFINITY;
        for (i, &a) in QUALITATIVE.iter().enumerate() {
            for &b in &QUALITATIVE[i + 1..] {
                min = min.min(delta_e(a, b));
            }
            assert!(
                delta_e(a, UNREACHED) >= MIN_PALETTE_DELTA_E,
                "{a:?} vs grey"
            );
        }
        assert!(min >= MIN_PALETTE_DELTA_E, "smallest palette ΔE {min}");
    }

    /// Labels of 6 × 6 blocks of 10 × 10 cells, numbered so that the
    /// golden-ratio colours of some neighbours are close.
    fn blocks() -> ArrayD<i32> {
        ArrayD::from_shape_fn(vec![60, 60], |i| (i[0] / 10 * 6 + i[1] / 10) as i32)
    }

    fn min_neighbour_delta_e(labels: &ArrayD<i32>, img: &image::RgbImage) -> f64 {
        let (rows, cols) = (labels.shape()[0], labels.shape()[1]);
        let mut min = f64::INFINITY;
        for r in 0..rows {
            for c in 0..cols {
                for (rr, cc) in [(r + 1, c), (r, c + 1)] {
                    if rr < rows && cc < cols && labels[[r, c]] != labels[[rr, cc]] {
                        let a = img.get_pixel(c as u32, r as u32).0;
                        let b = img.get_pixel(cc as u32, rr as u32).0;
                        min = min.min(delta_e(a, b));
                    }
                }
            }
        }
        min
    }

    #[test]
    fn neighbouring_labels_get_distinct_colours() {
        let labels = blocks();
        let png = render_png(&ArrayData::I32(labels.clone()), &RenderOptions::default())
            .expect("renders");
        keep("labels_blocks", &png);
        let img = rgb(&png);
        assert_eq!(img.dimensions(), (60, 60));
        let min = min_neighbour_delta_e(&labels, &img);
        assert!(min >= MIN_PALETTE_DELTA_E, "smallest neighbour ΔE {min}");
        // The golden-ratio colours of the same labels come closer than that.
        let mut old = f64::INFINITY;
        for r in 0..6 {
            for c in 0..6 {
                let k = r * 6 + c;
                for n in [k + 1, k + 6] {
                    if (n == k + 1 && c < 5) || (n == k + 6 && r < 5) {
                        old = old.min(delta_e(label_colour(k), label_colour(n)));
                    }
                }
            }
        }
        eprintln!(
            "smallest ΔE between neighbouring blocks: greedy {min:.1}, golden ratio {old:.1}"
        );
        // Negative labels stay grey, walls black.
        let mut l = labels;
        l[[0, 0]] = -1;
        let img = rgb(&render_png(&ArrayData::I32(l), &RenderOptions::default()).expect("renders"));
        assert_eq!(img.get_pixel(0, 0).0, UNREACHED);
    }

    #[test]
    fn labels_over_an_image_with_seed_markers() {
        let labels = ArrayD::from_shape_fn(vec![40, 40], |i| {
            if i[0] < 5 {
                -1
            } else {
                i32::from(i[1] >= 20)
            }
        });
        let image = ArrayData::F64(ArrayD::from_shape_fn(vec![40, 40], |i| i[1] as f64));
        let markers = vec![vec![20.0, 10.0], vec![20.0, 30.0]];
        let overlay = Overlay {
            image: Some(&image),
            alpha: 0.5,
            markers: &markers,
        };
        let png = render_png_over(&ArrayData::I32(labels), &RenderOptions::default(), &overlay)
            .expect("renders");
        keep("labels_over_image", &png);
        let img = rgb(&png);
        // Magnified round(384 / 40) = 10 times, capped at 8.
        assert_eq!(img.dimensions(), (320, 320));
        // Row 0 is unreached: the image alone, grey of column 0 (black).
        assert_eq!(img.get_pixel(5, 5).0, [0; 3]);
        assert_eq!(img.get_pixel(315, 5).0, Colormap::Grey.at(39.0 / 39.0));
        // Cell (35, 2): label 0 (the first palette colour) half over grey 2/39.
        let want = mix(Colormap::Grey.at(2.0 / 39.0), QUALITATIVE[0], 0.5);
        assert_eq!(img.get_pixel(20, 284).0, want);
        // The markers: white at the centres of cells (20, 10) and (20, 30).
        assert_eq!(img.get_pixel(84, 164).0, [255; 3]);
        assert_eq!(img.get_pixel(244, 164).0, [255; 3]);
        // A marker outside the array is refused, naming the option.
        let far = vec![vec![50.0, 1.0]];
        let err = check_options(
            &image,
            &RenderOptions::default(),
            &Overlay {
                markers: &far,
                alpha: 0.5,
                ..Default::default()
            },
        )
        .expect_err("outside");
        assert_eq!(err.option, "markers");
    }

    #[test]
    fn a_3d_array_says_which_slice_it_shows() {
        // Slices 0, 1, 2 hold labels -1, 0, 1: the middle one (label 0) is shown.
        let labels = ArrayD::from_shape_fn(vec![3, 2, 2], |i| i[0] as i32 - 1);
        let png = render_png(&ArrayData::I32(labels), &RenderOptions::default()).expect("renders");
        keep("volume_default_slice", &png);
        let img = rgb(&png);
        // 2 × 2 cells magnified 8 times under a caption strip of 11 px,
        // as wide as the caption "slice 0:1 (of 3)" (16 characters).
        let caption_w = text_width("slice 0:1 (of 3)", 1) + 4;
        assert_eq!(img.dimensions(), (caption_w as u32, 16 + 11));
        assert!((11..27).all(|y| (0..16).all(|x| img.get_pixel(x, y).0 == QUALITATIVE[0])));
        let dark = (0..caption_w as u32)
            .flat_map(|x| (0..11).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == [0; 3])
            .count();
        assert!(dark > 40, "caption text: {dark} pixels");
        assert_eq!(label_colour(-1), UNREACHED);
        // A slice past the end is refused, naming the view.
        let bad = RenderOptions {
            view: View::Slice { axis: 1, index: 2 },
            ..Default::default()
        };
        let err = check_options(
            &ArrayData::F64(ArrayD::zeros(vec![3, 2, 2])),
            &bad,
            &Overlay::default(),
        )
        .expect_err("outside");
        assert_eq!(err.option, "view");
    }

    #[test]
    fn a_montage_is_a_grid_of_the_slices_asked_for() {
        // Slice i0 holds the value i0: tile k shows index round(k · 9 / 3).
        let u = ArrayD::from_shape_fn(vec![10, 8, 6], |i| i[0] as f64);
        let options = RenderOptions {
            view: View::Montage { axis: 0, count: 4 },
            range: Some((0.0, 9.0)),
            ..Default::default()
        };
        let png = render_png(&ArrayData::F64(u.clone()), &options).expect("renders");
        keep("montage", &png);
        let img = rgb(&png);
        // 2 × 2 tiles of 8 × 6 cells magnified 8 times (384 / 16 → 8), 2 px
        // apart, under an 11 px caption as wide as "axis 0: 4 of 10 slices".
        let (tw, th) = (48u32, 64u32);
        let caption_w = (text_width("axis 0: 4 of 10 slices", 1) + 4) as u32;
        assert_eq!(
            img.dimensions(),
            (caption_w.max(2 * tw + 2), 2 * th + 2 + 11)
        );
        for (k, index) in [0usize, 3, 6, 9].into_iter().enumerate() {
            let (x, y) = ((k as u32 % 2) * (tw + 2), 11 + (k as u32 / 2) * (th + 2));
            let want = Colormap::Viridis.at(index as f64 / 9.0);
            assert_eq!(img.get_pixel(x + tw - 4, y + th - 4).0, want, "tile {k}");
            // Its index, white on black, at its top-left corner.
            let white = (0..20)
                .flat_map(|dx| (0..10).map(move |dy| (x + dx, y + dy)))
                .filter(|&(x, y)| img.get_pixel(x, y).0 == [255; 3])
                .count();
            assert!(white > 5, "tile {k} label");
        }
        // Along axis 2: 6 slices of 10 × 8 cells, all of them for count 9.
        let options = RenderOptions {
            view: View::Montage { axis: 2, count: 9 },
            ..Default::default()
        };
        let img = rgb(&render_png(&ArrayData::F64(u), &options).expect("renders"));
        // 3 × 2 tiles of 10 × 8 cells: side max(24, 20) → magnification 16 → 8.
        assert_eq!(img.height(), 2 * 80 + 2 + 11);
        assert!(img.width() >= 3 * 64 + 4);
    }

    /// The extent (columns, rows) of the pixels of `colour`.
    fn extent(img: &image::RgbImage, colour: [u8; 3]) -> (u32, u32) {
        let pts: Vec<(u32, u32)> = img
            .enumerate_pixels()
            .filter(|(_, _, p)| p.0 == colour)
            .map(|(x, y, _)| (x, y))
            .collect();
        assert!(!pts.is_empty(), "no pixel of {colour:?}");
        let w =
            pts.iter().map(|p| p.0).max().unwrap_or(0) - pts.iter().map(|p| p.0).min().unwrap_or(0);
        let h =
            pts.iter().map(|p| p.1).max().unwrap_or(0) - pts.iter().map(|p| p.1).min().unwrap_or(0);
        (w + 1, h + 1)
    }

    fn one_tensor(m: [f64; 3]) -> ArrayData {
        ArrayData::F64(ArrayD::from_shape_vec(vec![1, 1, 3], m.to_vec()).expect("shape"))
    }

    #[test]
    fn tensor_glyphs_are_long_along_the_cheap_axis() {
        // M = diag(4, 1): moving along axis 1 is cheap, the unit ball is
        // twice as long along axis 1 (the picture's x) as along axis 0.
        let options = RenderOptions::default();
        let fill = Colormap::Viridis.at(0.75);
        let png = render_png(&one_tensor([4.0, 0.0, 1.0]), &options).expect("renders");
        keep("tensor_one_axis1", &png);
        let (w, h) = extent(&rgb(&png), fill);
        assert!(w >= 13 && h <= 9 && w as f64 >= 1.7 * h as f64, "{w} × {h}");
        let (w, h) = extent(
            &rgb(&render_png(&one_tensor([1.0, 0.0, 4.0]), &options).expect("renders")),
            fill,
        );
        assert!(h as f64 >= 1.7 * w as f64, "{w} × {h}");
        // [[2.5, 1.5], [1.5, 2.5]]: eigenvalue 1 along (1, -1) (down-left to up-right in
        // the picture: rows grow downwards), 4 along (1, 1).
        let img = rgb(&render_png(&one_tensor([2.5, 1.5, 2.5]), &options).expect("renders"));
        // The glyph's centre is cell (0, 0)'s centre, (7.5, 7.5) → pixel (8, 8),
        // under the 11 px caption.
        let (cx, cy) = (8i64, 8i64 + 11);
        let at = |dx: i64, dy: i64| img.get_pixel((cx + dx) as u32, (cy + dy) as u32).0;
        assert_eq!(at(4, -4), fill, "along (1, -1)");
        assert_eq!(at(-4, 4), fill, "along (-1, 1)");
        assert_ne!(at(4, 4), fill, "across");
    }

    #[test]
    fn a_512_tensor_field_is_a_lattice_of_glyphs() {
        let m = ArrayD::from_shape_fn(vec![512, 512, 3], |i| match i[2] {
            0 => 1.0 + i[0] as f64 / 128.0,
            1 => 0.0,
            _ => 1.0,
        });
        let options = RenderOptions {
            colorbar: true,
            ..Default::default()
        };
        let png = render_png(&ArrayData::F64(m), &options).expect("renders");
        keep("tensor_512", &png);
        let img = rgb(&png);
        assert!(
            img.width() > 512 && img.height() > 512,
            "{:?}",
            img.dimensions()
        );
        // 32 × 32 glyph centres (black dots) every 16 px, from (8, 8).
        let centres = (0..32)
            .flat_map(|i| (0..32).map(move |j| (8 + 16 * j, 11 + 8 + 16 * i)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == [0; 3])
            .count();
        assert_eq!(centres, 32 * 32);
    }
}
