//! Vertex moves that lower an image mesh's interpolation error: each
//! vertex, in turn, goes to the grid cell near it where the piecewise-linear
//! interpolant of the image over its star is closest to the image, and the
//! data-dependent flips of [`super::image_flips`] follow each sweep.
//!
//! # Math
//!
//! The interpolant `f̃_T` takes the image's values at the vertices, so
//! moving vertex `v` from `p` to `q` changes it only on `v`'s star (the
//! union of its triangles), and only there is the squared error
//!
//! ```text
//! E_v(q) = Σ_{x ∈ star(v)} (f(x) − f̃(x))²
//! ```
//!
//! compared. The star is the polygon of `v`'s link, which does not depend
//! on `q` as long as every triangle of the star stays counter-clockwise
//! (`q` in the kernel of the polygon), so a move that lowers `E_v` lowers
//! the total error by the same amount. A grid cell on a shared edge of the
//! star counts once (for the first triangle of the star that holds it);
//! cells on the link's edges do not depend on `q` (both ends fixed) and add
//! the same to every candidate.
//!
//! The search is a pattern search on the grid: the eight cells at distance
//! `s` (in the max norm) along the axes and diagonals, the best taken if it
//! lowers `E_v` by more than a relative `1e-9` (and more than `1e-12` of
//! the image's largest magnitude squared: rounding noise). A sweep visits every
//! vertex; `s` halves when a sweep moves fewer than 1 % of the vertices, and
//! the loop stops after the sweep at `s = 1` that does so, or after
//! [`MAX_SWEEPS`]; within a step, a vertex is searched again only once its
//! star has changed (a move in it, a flip of one of its triangles).
//! Border vertices slide along their side of the rectangle;
//! the four corners stay. Every accepted move and every flip lowers the
//! total error, so the loop ends, at a local minimum of these moves.
//!
//! Vertices stay on grid cells (their values are the image's values there),
//! the mesh stays a counter-clockwise triangulation of the rectangle with
//! the same vertex count: the points move, and the triangles follow the
//! image's edges as far as the flips allow.

use super::image::{locate, orient, MeshingError};
use super::image_flips::{flip_to_image, rounding_tolerance};
use crate::numerics::buckets::triangles_by_vertex;
use crate::numerics::control::Control;

/// Sweeps at most (a sweep is one pass over every vertex, then flips).
pub const MAX_SWEEPS: usize = 40;

/// The first step of the pattern search, in grid cells: a quarter of the
/// mean vertex spacing `sqrt(cells / vertices)`, at least 1.
fn first_step(shape: [usize; 2], vertices: usize) -> i64 {
    let spacing = ((shape[0] * shape[1]) as f64 / vertices.max(1) as f64).sqrt();
    ((spacing / 4.0).round() as i64).max(1)
}

/// What [`move_to_image`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MoveStats {
    /// Vertex moves accepted.
    pub moves: usize,
    /// Edges flipped between the sweeps (and before the first).
    pub flips: usize,
    /// Sweeps run.
    pub sweeps: usize,
}

/// Squared error over the star of a vertex: `tris` are its triangles,
/// corners and values; a cell on an edge shared by two of them counts for
/// the first.
fn star_error(shape: [usize; 2], image: &[f64], tris: &[[([f64; 2], f64); 3]]) -> f64 {
    let [n0, n1] = shape;
    let mut sum = 0.0;
    for (i, t) in tris.iter().enumerate() {
        let lo = |k: usize| t[0].0[k].min(t[1].0[k]).min(t[2].0[k]).ceil().max(0.0) as usize;
        let hi = |k: usize, n: usize| {
            (t[0].0[k].max(t[1].0[k]).max(t[2].0[k]).floor().max(0.0) as usize).min(n - 1)
        };
        for r in lo(0)..=hi(0, n0) {
            for c in lo(1)..=hi(1, n1) {
                let x = [r as f64, c as f64];
                let Some((value, on_edge)) = locate(t, x) else {
                    continue;
                };
                if on_edge && tris[..i].iter().any(|s| locate(s, x).is_some()) {
                    continue;
                }
                sum += (image[r * n1 + c] - value).powi(2);
            }
        }
    }
    sum
}

/// Moves the vertices of the mesh (`points` on grid cells of `shape`, in
/// index coordinates; `triangles` counter-clockwise; `values` the image at
/// the points, updated) and flips its edges while that lowers the squared
/// interpolation error of `image` (C order); see the module docs. The
/// triangulation must cover the rectangle `[0, n0−1] × [0, n1−1]` with
/// its border vertices on the border. Polls `control`.
///
/// # Examples
/// ```
/// use geodex::numerics::control::Control;
/// use geodex::numerics::meshing::image_moves::move_to_image;
/// use geodex::numerics::meshing::piecewise_linear;
/// // A ridge f = max(0, 4 − |x − y|) on a 9 × 9 grid and one vertex off it.
/// let f: Vec<f64> = (0..81)
///     .map(|i| (4.0 - ((i / 9) as f64 - (i % 9) as f64).abs()).max(0.0))
///     .collect();
/// let error = |p: &[[f64; 2]], t: &[[u32; 3]], v: &[f64]| -> f64 {
///     let g = piecewise_linear([9, 9], p, t, v);
///     f.iter().zip(&g).map(|(a, b)| (a - b).powi(2)).sum()
/// };
/// let mut points = vec![[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0], [3.0, 6.0]];
/// let mut values: Vec<f64> = points.iter().map(|p| f[p[0] as usize * 9 + p[1] as usize]).collect();
/// let mut triangles = vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
/// let before = error(&points, &triangles, &values);
/// let stats = move_to_image([9, 9], &mut points, &mut triangles, &mut values, &f, &Control::new())?;
/// assert!(stats.moves > 0);
/// assert!(error(&points, &triangles, &values) < before); // 80 against 109
/// assert_eq!(points[4], [2.0, 6.0]); // one cell towards the crest
/// # Ok::<(), geodex::numerics::meshing::MeshingError>(())
/// ```
pub fn move_to_image(
    shape: [usize; 2],
    points: &mut [[f64; 2]],
    triangles: &mut [[u32; 3]],
    values: &mut [f64],
    image: &[f64],
    control: &Control<'_>,
) -> Result<MoveStats, MeshingError> {
    let [n0, n1] = shape;
    let nv = points.len();
    let mut stats = MoveStats {
        flips: flip_to_image(shape, points, triangles, values, image, control)?.flips,
        ..MoveStats::default()
    };
    let (last0, last1) = ((n0 - 1) as f64, (n1 - 1) as f64);
    let mut step = first_step(shape, nv);
    let directions: [[i64; 2]; 8] = [
        [1, 0],
        [-1, 0],
        [0, 1],
        [0, -1],
        [1, 1],
        [1, -1],
        [-1, 1],
        [-1, -1],
    ];
    let mut ring: Vec<[([f64; 2], f64); 3]> = Vec::new();
    let tolerance = rounding_tolerance(image);
    // Vertices whose star changed (a move of theirs or of a neighbour, a
    // flip of one of their triangles) since their last search at this
    // step: the others would find the same nothing.
    let mut dirty = vec![true; nv];
    while stats.sweeps < MAX_SWEEPS {
        stats.sweeps += 1;
        let (offsets, around) = triangles_by_vertex(nv, triangles);
        let mut moved = 0usize;
        for v in 0..nv {
            if v % 64 == 0 && control.is_cancelled() {
                return Err(MeshingError::Cancelled);
            }
            if !std::mem::replace(&mut dirty[v], false) {
                continue;
            }
            let p = points[v];
            let on0 = p[0] == 0.0 || p[0] == last0;
            let on1 = p[1] == 0.0 || p[1] == last1;
            if on0 && on1 {
                continue; // a corner
            }
            let star = &around[offsets[v]..offsets[v + 1]];
            if star.is_empty() {
                continue;
            }
            // The star's triangles with `v` at corner 0 (rotation keeps
            // the orientation), at a candidate position `q`.
            let fill = |ring: &mut Vec<[([f64; 2], f64); 3]>, q: [f64; 2], value: f64| {
                ring.clear();
                for &t in star {
                    let tri = triangles[t as usize];
                    let k = tri.iter().position(|&u| u as usize == v).unwrap_or(0);
                    let (a, b) = (tri[(k + 1) % 3] as usize, tri[(k + 2) % 3] as usize);
                    ring.push([(q, value), (points[a], values[a]), (points[b], values[b])]);
                }
            };
            fill(&mut ring, p, values[v]);
            let mut best = (star_error(shape, image, &ring), None);
            let threshold = |e: f64| e * (1.0 - 1e-9) - tolerance;
            for d in directions {
                // Border vertices slide along their side only.
                if (on0 && d[0] != 0) || (on1 && d[1] != 0) {
                    continue;
                }
                let q = [p[0] + (step * d[0]) as f64, p[1] + (step * d[1]) as f64];
                if !(0.0..=last0).contains(&q[0]) || !(0.0..=last1).contains(&q[1]) {
                    continue;
                }
                let value = image[q[0] as usize * n1 + q[1] as usize];
                fill(&mut ring, q, value);
                if ring.iter().any(|t| orient(t[0].0, t[1].0, t[2].0) <= 1e-9) {
                    continue;
                }
                let e = star_error(shape, image, &ring);
                if e < threshold(best.0) {
                    best = (e, Some((q, value)));
                }
            }
            if let Some((q, value)) = best.1 {
                points[v] = q;
                values[v] = value;
                moved += 1;
                for &t in star {
                    for u in triangles[t as usize] {
                        dirty[u as usize] = true;
                    }
                }
            }
        }
        stats.moves += moved;
        let before = triangles.to_vec();
        stats.flips += flip_to_image(shape, points, triangles, values, image, control)?.flips;
        for (old, new) in before.iter().zip(triangles.iter()) {
            if old != new {
                for u in old.iter().chain(new) {
                    dirty[*u as usize] = true;
                }
            }
        }
        if moved * 100 < nv {
            if step == 1 {
                break;
            }
            step = (step / 2).max(1);
            dirty.fill(true);
        }
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::meshing::image_flips::tests::{ccw_area, lattice, total};

    /// A blurred disc meshed by a regular grid of vertices: the moves lower
    /// the error well below what flips alone reach, the error never rises,
    /// and the result is still a counter-clockwise triangulation of the
    /// square with its border vertices on the border.
    #[test]
    fn moves_lower_the_error_below_flips_alone() {
        let n = 65usize;
        let f: Vec<f64> = (0..n * n)
            .map(|i| {
                let (x, y) = ((i / n) as f64 - 30.0, (i % n) as f64 - 34.0);
                let r = (x * x + y * y).sqrt();
                1.0 / (1.0 + ((r - 18.0) / 1.5).exp())
            })
            .collect();
        let (mut points, mut tris) = lattice(8, 8.0);
        let mut values: Vec<f64> = points
            .iter()
            .map(|p| f[p[0] as usize * n + p[1] as usize])
            .collect();
        let before = total([n, n], &points, &tris, &values, &f);
        let mut flipped = tris.clone();
        flip_to_image([n, n], &points, &mut flipped, &values, &f, &Control::new()).unwrap();
        let flips_only = total([n, n], &points, &flipped, &values, &f);
        let border: Vec<bool> = points
            .iter()
            .map(|p| p[0] == 0.0 || p[1] == 0.0 || p[0] == 64.0 || p[1] == 64.0)
            .collect();
        let s = move_to_image(
            [n, n],
            &mut points,
            &mut tris,
            &mut values,
            &f,
            &Control::new(),
        )
        .unwrap();
        let after = total([n, n], &points, &tris, &values, &f);
        assert!(s.moves > 0 && s.sweeps <= MAX_SWEEPS);
        assert!(flips_only < before);
        assert!(
            after < 0.7 * flips_only,
            "moves {after} against flips only {flips_only} (before {before})"
        );
        // Values are the image at the (grid) points.
        for (p, v) in points.iter().zip(&values) {
            assert_eq!(p[0].fract(), 0.0);
            assert_eq!(p[1].fract(), 0.0);
            assert_eq!(*v, f[p[0] as usize * n + p[1] as usize]);
        }
        // A triangulation of the square, border vertices on the border.
        let area = ccw_area(&points, &tris);
        assert!((area - (64.0 * 64.0)).abs() < 1e-9, "area {area}");
        for (p, b) in points.iter().zip(border) {
            let on = p[0] == 0.0 || p[1] == 0.0 || p[0] == 64.0 || p[1] == 64.0;
            assert_eq!(on, b);
        }
    }

    /// On a linear image every triangulation is exact: nothing moves.
    #[test]
    fn a_linear_image_keeps_its_vertices() {
        let n = 9;
        let f: Vec<f64> = (0..n * n)
            .map(|i| (i / n) as f64 + 2.0 * (i % n) as f64)
            .collect();
        let mut points = vec![[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0], [4.0, 3.0]];
        let mut values: Vec<f64> = points
            .iter()
            .map(|p| f[p[0] as usize * n + p[1] as usize])
            .collect();
        let mut t = vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        let s = move_to_image(
            [n, n],
            &mut points,
            &mut t,
            &mut values,
            &f,
            &Control::new(),
        )
        .unwrap();
        assert_eq!(s.moves, 0);
        assert_eq!(points[4], [4.0, 3.0]);
    }
}
