//! A planar mesh drawn over the image it was made from, for people to look
//! at (image meshing: where did the vertices go, how are the triangles
//! stretched).
//!
//! The picture is an RGB `u8` array of shape `(s · rows, s · cols, 3)`, with
//! the magnification `s = clamp(round(1024 / max(rows, cols)), 1, 4)` so
//! that small images are not drawn with one-pixel triangles. The image is
//! in grey (its finite range stretched to black..white; NaN black); edges
//! are drawn in orange, blended at 85 % opacity, by sampling each segment
//! every half pixel; vertices are 3 × 3 (s ≥ 2) or single yellow dots.
//!
//! Vertex `(r, c)` (index coordinates, axis 0 first) is drawn at the centre
//! of pixel `(s·r + (s−1)/2, s·c + (s−1)/2)`, the centre of the block that
//! shows cell `(r, c)`.

use ndarray::ArrayD;

use super::{ArrayData, IoError};

/// Colour of the edges.
pub const EDGE: [u8; 3] = [255, 110, 20];
/// Colour of the vertices.
pub const VERTEX: [u8; 3] = [255, 230, 40];
/// Largest side of a picture that magnification aims for.
const TARGET_SIDE: f64 = 1024.0;
/// Opacity of the edges.
const EDGE_ALPHA: f64 = 0.85;

/// The magnification for an image of `rows × cols` cells.
pub fn magnification(rows: usize, cols: usize) -> usize {
    let side = rows.max(cols).max(1) as f64;
    ((TARGET_SIDE / side).round() as usize).clamp(1, 4)
}

/// Draws `triangles` over `points` (index coordinates of an image of
/// `rows × cols` cells whose values, C order, are `image`); see the
/// [module](self) docs.
///
/// # Errors
///
/// [`IoError::Encode`] if `image` does not have `rows · cols` values or a
/// triangle names a vertex that does not exist. (Only images with a side
/// under 683 cells are magnified, so the picture has at most 4 times as
/// many pixels as the image has cells, or about 1400² pixels.)
///
/// # Examples
///
/// ```
/// use geodex::io::mesh_picture::mesh_picture;
/// let image = vec![0.0, 1.0, 1.0, 2.0];
/// let pic = mesh_picture(&image, 2, 2, &[[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]], &[[0, 2, 1]])?;
/// assert_eq!(pic.shape(), &[8, 8, 3]);
/// # Ok::<(), geodex::io::IoError>(())
/// ```
pub fn mesh_picture(
    image: &[f64],
    rows: usize,
    cols: usize,
    points: &[[f64; 2]],
    triangles: &[[u32; 3]],
) -> Result<ArrayData, IoError> {
    if image.len() != rows * cols || rows == 0 || cols == 0 {
        return Err(IoError::Encode(format!(
            "an image of {rows} x {cols} cells needs {} values, got {}",
            rows * cols,
            image.len()
        )));
    }
    let s = magnification(rows, cols);
    let (h, w) = (rows * s, cols * s);
    if let Some(t) = triangles
        .iter()
        .find(|t| t.iter().any(|&v| v as usize >= points.len()))
    {
        return Err(IoError::Encode(format!(
            "triangle {t:?} names a vertex beyond the {} points",
            points.len()
        )));
    }
    let finite = image.iter().copied().filter(|v| v.is_finite());
    let lo = finite.clone().fold(f64::INFINITY, f64::min);
    let hi = finite.fold(f64::NEG_INFINITY, f64::max);
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut px = vec![[0.0f64; 3]; h * w];
    for r in 0..h {
        for c in 0..w {
            let v = image[(r / s) * cols + c / s];
            let g = if v.is_finite() {
                255.0 * ((v - lo) / span).clamp(0.0, 1.0)
            } else {
                0.0
            };
            px[r * w + c] = [g; 3];
        }
    }
    let centre = |p: [f64; 2]| {
        let half = (s as f64 - 1.0) / 2.0;
        [p[0] * s as f64 + half, p[1] * s as f64 + half]
    };
    // Each edge once: (min, max) pairs.
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let mut blend = |r: isize, c: isize, colour: [u8; 3], alpha: f64| {
        if r >= 0 && c >= 0 && (r as usize) < h && (c as usize) < w {
            let p = &mut px[r as usize * w + c as usize];
            for k in 0..3 {
                p[k] = p[k] * (1.0 - alpha) + f64::from(colour[k]) * alpha;
            }
        }
    };
    let mut last = (isize::MIN, isize::MIN);
    for (a, b) in edges {
        let (pa, pb) = (centre(points[a as usize]), centre(points[b as usize]));
        let len = (pb[0] - pa[0]).hypot(pb[1] - pa[1]);
        let steps = (2.0 * len).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let r = (pa[0] + t * (pb[0] - pa[0])).round() as isize;
            let c = (pa[1] + t * (pb[1] - pa[1])).round() as isize;
            // Half-pixel steps land twice on most pixels: blend once.
            if (r, c) != last {
                blend(r, c, EDGE, EDGE_ALPHA);
                last = (r, c);
            }
        }
    }
    let dot: isize = if s >= 2 { 1 } else { 0 };
    for p in points {
        let q = centre(*p);
        let (r, c) = (q[0].round() as isize, q[1].round() as isize);
        for dr in -dot..=dot {
            for dc in -dot..=dot {
                blend(r + dr, c + dc, VERTEX, 1.0);
            }
        }
    }
    let raw: Vec<u8> = px
        .into_iter()
        .flat_map(|p| p.map(|v| (v + 0.5).clamp(0.0, 255.0) as u8))
        .collect();
    ArrayD::from_shape_vec(vec![h, w, 3], raw)
        .map(ArrayData::U8)
        .map_err(|e| IoError::Encode(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pixel(a: &ArrayData, r: usize, c: usize) -> [u8; 3] {
        let ArrayData::U8(a) = a else { panic!("u8") };
        [a[[r, c, 0]], a[[r, c, 1]], a[[r, c, 2]]]
    }

    #[test]
    fn edges_vertices_and_background_are_where_they_belong() {
        // A 64 x 64 ramp (s = 4 after rounding 1024/64 = 16 down to the cap);
        // one triangle along the top edge, the left edge and the diagonal.
        let (rows, cols) = (64, 64);
        let image: Vec<f64> = (0..rows * cols).map(|i| (i % cols) as f64).collect();
        let pts = [[0.0, 0.0], [0.0, 63.0], [63.0, 0.0]];
        let pic = mesh_picture(&image, rows, cols, &pts, &[[0, 2, 1]]).unwrap();
        assert_eq!(pic.shape(), &[256, 256, 3]);
        // Vertex (0, 63) at pixel (1.5, 253.5) rounded: (2, 254).
        assert_eq!(pixel(&pic, 2, 254), VERTEX);
        // The top edge runs along pixel row 2 (centre 1.5 rounds to 2).
        let on = pixel(&pic, 2, 128);
        assert!(on[0] > 200 && on[2] < 120, "{on:?}");
        // Away from every edge: grey, the ramp's value (cell column 50 of 63).
        let off = pixel(&pic, 200, 200);
        assert_eq!(off[0], off[1]);
        assert_eq!(off[1], off[2]);
        let want = (255.0 * 50.0 / 63.0_f64).round() as u8;
        assert!(off[0].abs_diff(want) <= 1, "{off:?} vs {want}");
        // Inside the triangle, off its edges: also grey.
        let inside = pixel(&pic, 60, 60);
        assert_eq!(inside[0], inside[2]);
    }

    #[test]
    fn large_images_are_not_magnified_and_bad_input_is_refused() {
        assert_eq!(magnification(512, 512), 2);
        assert_eq!(magnification(2048, 100), 1);
        assert_eq!(magnification(10, 10), 4);
        assert!(mesh_picture(&[0.0; 3], 2, 2, &[], &[]).is_err());
        assert!(mesh_picture(&[0.0; 4], 2, 2, &[[0.0, 0.0]], &[[0, 1, 2]]).is_err());
    }
}
