//! Data-dependent edge flips of an image mesh (Dyn, Levin and Rippa,
//! "Data dependent triangulations for piecewise linear interpolation",
//! 1990): the vertices and their values stay, the triangulation changes.
//!
//! # Math
//!
//! The interior edge `pq` of the triangles `pqr₁` and `qpr₂` is a diagonal
//! of the quadrilateral `p r₂ q r₁`. When that quadrilateral is strictly
//! convex the other diagonal `r₁r₂` gives a valid triangulation too, and
//! the piecewise-linear interpolant `f̃` changes only inside it. The edge is
//! flipped when that lowers the squared error over the grid cells of the
//! quadrilateral,
//!
//! ```text
//! E(T) = Σ_{x ∈ quad} (f(x) − f̃_T(x))²,
//! ```
//!
//! by more than a relative `1e-9` and more than `1e-12` of the image's
//! largest magnitude squared (so that rounding cannot make the flips cycle: on a
//! plateau of the image the error is rounding alone). Each flip lowers the total error, so the greedy loop (a queue of
//! edges; a flip queues the quadrilateral's four sides) ends; it stops at a
//! local minimum, where no single flip helps. A diagonal that already is an
//! edge elsewhere is never made (the mesh stays manifold), and the
//! boundary edges never move. Delaunay's angle guarantee is given up where
//! the image asks for long triangles across which it varies little, which
//! is the point: along an edge of the image, triangles that straddle it are
//! replaced by triangles that follow it.

use std::collections::{HashMap, HashSet};

use super::image::{interpolate, orient, MeshingError};
use crate::numerics::control::Control;

/// What [`flip_to_image`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FlipStats {
    /// Edges flipped.
    pub flips: usize,
    /// Quadrilaterals evaluated.
    pub evaluated: usize,
}

/// Squared error of the two triangles over the grid cells they cover.
fn pair_error(shape: [usize; 2], image: &[f64], pair: [&[([f64; 2], f64); 3]; 2]) -> f64 {
    let [n0, n1] = shape;
    let pts = pair.iter().flat_map(|t| t.iter().map(|(p, _)| *p));
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pts {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let r0 = lo[0].ceil().max(0.0) as usize;
    let r1 = (hi[0].floor().max(0.0) as usize).min(n0 - 1);
    let c0 = lo[1].ceil().max(0.0) as usize;
    let c1 = (hi[1].floor().max(0.0) as usize).min(n1 - 1);
    let mut sum = 0.0;
    for r in r0..=r1 {
        for c in c0..=c1 {
            let x = [r as f64, c as f64];
            if let Some(v) = interpolate(pair[0], x).or_else(|| interpolate(pair[1], x)) {
                sum += (image[r * n1 + c] - v).powi(2);
            }
        }
    }
    sum
}

/// Gains below this are rounding noise, not gains: `1e-12` of the image's
/// largest magnitude squared (the interpolant's rounding error grows with
/// the values, not with their range). On a plateau of the image the error
/// is rounding alone (about `1e-30` per cell for values near 1), and flips
/// chasing it cycled until the flip limit.
pub(super) fn rounding_tolerance(image: &[f64]) -> f64 {
    let scale = image.iter().fold(0.0f64, |m, &x| m.max(x.abs()));
    1e-12 * scale * scale
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// Flips the interior edges of `triangles` (counter-clockwise, over
/// `points` in index coordinates, `values` per point) while a flip lowers
/// the squared error of the piecewise-linear interpolation of `image` (C
/// order over `shape`); see the module docs. Polls `control`.
///
/// # Examples
/// ```
/// use geodex::numerics::control::Control;
/// use geodex::numerics::meshing::image_flips::flip_to_image;
/// // f(x, y) = min(x, y) on a 3 × 3 grid: the diagonal along its crease
/// // (x = y) interpolates it exactly; the other errs in the middle.
/// let image: Vec<f64> = (0..9).map(|i| (i / 3).min(i % 3) as f64).collect();
/// let points = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
/// let values = [0.0, 0.0, 2.0, 0.0];
/// let mut triangles = vec![[0, 1, 3], [1, 2, 3]]; // diagonal 1-3
/// let stats = flip_to_image([3, 3], &points, &mut triangles, &values, &image, &Control::new())?;
/// assert_eq!(stats.flips, 1);
/// assert!(triangles.iter().all(|t| t.contains(&0) && t.contains(&2)));
/// # Ok::<(), geodex::numerics::meshing::MeshingError>(())
/// ```
pub fn flip_to_image(
    shape: [usize; 2],
    points: &[[f64; 2]],
    triangles: &mut [[u32; 3]],
    values: &[f64],
    image: &[f64],
    control: &Control<'_>,
) -> Result<FlipStats, MeshingError> {
    let mut edges: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            edges
                .entry(key(tri[k], tri[(k + 1) % 3]))
                .or_default()
                .push(t);
        }
    }
    let mut queue: Vec<(u32, u32)> = edges
        .iter()
        .filter(|(_, ts)| ts.len() == 2)
        .map(|(&e, _)| e)
        .collect();
    queue.sort_unstable();
    let mut queued: HashSet<(u32, u32)> = queue.iter().copied().collect();
    let scale = points
        .iter()
        .fold(0.0f64, |m, p| m.max(p[0].abs()).max(p[1].abs()))
        .max(1.0);
    let corner = |v: u32| (points[v as usize], values[v as usize]);
    let tolerance = rounding_tolerance(image);
    let mut stats = FlipStats::default();
    let limit = 64 * triangles.len() + 64;
    while let Some(e) = queue.pop() {
        queued.remove(&e);
        if stats.evaluated % 256 == 0 && control.is_cancelled() {
            return Err(MeshingError::Cancelled);
        }
        if stats.flips >= limit {
            break;
        }
        let Some(ts) = edges.get(&e).filter(|ts| ts.len() == 2) else {
            continue;
        };
        let (t1, t2) = (ts[0], ts[1]);
        // t1 is (p, q, r1) up to rotation and t2 (q, p, r2): r2 is t2's
        // corner off the edge.
        let tri1 = triangles[t1];
        let Some(k) = (0..3).find(|&k| key(tri1[k], tri1[(k + 1) % 3]) == e) else {
            continue;
        };
        let (p, q, r1) = (tri1[k], tri1[(k + 1) % 3], tri1[(k + 2) % 3]);
        let tri2 = triangles[t2];
        let Some(&r2) = tri2.iter().find(|&&v| v != p && v != q) else {
            continue;
        };
        if r1 == r2 || edges.contains_key(&key(r1, r2)) {
            continue;
        }
        let (pp, pq, pr1, pr2) = (
            points[p as usize],
            points[q as usize],
            points[r1 as usize],
            points[r2 as usize],
        );
        // The new triangles (p, r2, r1) and (r2, q, r1) must both turn
        // counter-clockwise: the quadrilateral is strictly convex.
        let eps = 1e-9 * scale * scale;
        if orient(pp, pr2, pr1) <= eps || orient(pr2, pq, pr1) <= eps {
            continue;
        }
        stats.evaluated += 1;
        let before = pair_error(
            shape,
            image,
            [
                &[corner(p), corner(q), corner(r1)],
                &[corner(q), corner(p), corner(r2)],
            ],
        );
        let after = pair_error(
            shape,
            image,
            [
                &[corner(p), corner(r2), corner(r1)],
                &[corner(r2), corner(q), corner(r1)],
            ],
        );
        if after >= before * (1.0 - 1e-9) - tolerance {
            continue;
        }
        triangles[t1] = [p, r2, r1];
        triangles[t2] = [r2, q, r1];
        edges.remove(&e);
        edges.insert(key(r1, r2), vec![t1, t2]);
        for (side, from, to) in [(key(p, r2), t2, t1), (key(q, r1), t1, t2)] {
            if let Some(ts) = edges.get_mut(&side) {
                for t in ts.iter_mut() {
                    if *t == from {
                        *t = to;
                    }
                }
            }
        }
        stats.flips += 1;
        for side in [key(p, r1), key(q, r1), key(p, r2), key(q, r2)] {
            if queued.insert(side) {
                queue.push(side);
            }
        }
    }
    Ok(stats)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Squared error of a whole triangulation.
    pub(in crate::numerics::meshing) fn total(
        shape: [usize; 2],
        p: &[[f64; 2]],
        t: &[[u32; 3]],
        v: &[f64],
        f: &[f64],
    ) -> f64 {
        let g = crate::numerics::meshing::piecewise_linear(shape, p, t, v);
        f.iter().zip(&g).map(|(a, b)| (a - b).powi(2)).sum()
    }

    /// The `(m + 1)²` points `(i, j) · step` and two right triangles per
    /// square, counter-clockwise, their diagonals all the same way.
    pub(in crate::numerics::meshing) fn lattice(
        m: usize,
        step: f64,
    ) -> (Vec<[f64; 2]>, Vec<[u32; 3]>) {
        let mut points = Vec::new();
        for i in 0..=m {
            for j in 0..=m {
                points.push([i as f64 * step, j as f64 * step]);
            }
        }
        let id = |i: usize, j: usize| (i * (m + 1) + j) as u32;
        let mut tris = Vec::new();
        for i in 0..m {
            for j in 0..m {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        (points, tris)
    }

    /// The area of counter-clockwise triangles (asserted).
    pub(in crate::numerics::meshing) fn ccw_area(points: &[[f64; 2]], tris: &[[u32; 3]]) -> f64 {
        tris.iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| points[v as usize]);
                let o = orient(a, b, c);
                assert!(o > 0.0, "{t:?} turns clockwise");
                o / 2.0
            })
            .sum()
    }

    #[test]
    fn flips_follow_a_step_edge_and_lower_the_error() {
        // A step along a diagonal line, meshed by a grid of right triangles
        // whose diagonals cross it.
        let (n, m) = (33usize, 8usize);
        let f: Vec<f64> = (0..n * n)
            .map(|i| {
                let (x, y) = ((i / n) as f64, (i % n) as f64);
                if x + 0.5 * y > 20.0 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let (points, mut tris) = lattice(m, (n - 1) as f64 / m as f64);
        let values: Vec<f64> = points
            .iter()
            .map(|p| f[p[0] as usize * n + p[1] as usize])
            .collect();
        let before = total([n, n], &points, &tris, &values, &f);
        let s = flip_to_image([n, n], &points, &mut tris, &values, &f, &Control::new()).unwrap();
        let after = total([n, n], &points, &tris, &values, &f);
        assert!(s.flips > 0);
        assert!(after < 0.8 * before, "{after} vs {before}");
        // Still a triangulation of the square: counter-clockwise triangles
        // whose areas add up to the square's.
        let area = ccw_area(&points, &tris);
        assert!((area - ((n - 1) * (n - 1)) as f64).abs() < 1e-9);
        let mut e: Vec<(u32, u32)> = tris
            .iter()
            .flat_map(|t| (0..3).map(move |k| key(t[k], t[(k + 1) % 3])))
            .collect();
        e.sort_unstable();
        let mut counts = HashMap::new();
        for k in e {
            *counts.entry(k).or_insert(0) += 1;
        }
        assert!(counts.values().all(|&c| c <= 2));
    }

    /// On a plateau the interpolant's error is rounding noise (about
    /// 1e-30 per cell): no flip may chase it. Before the tolerance, flips
    /// cycled on such noise until the flip limit.
    #[test]
    fn a_constant_image_makes_no_flips() {
        let (n, m) = (65usize, 8usize);
        let f = vec![0.7; n * n];
        let (mut points, mut tris) = lattice(m, ((n - 1) / m) as f64);
        // Inner points jittered by a cell, so that the quadrilaterals differ.
        for (k, p) in points.iter_mut().enumerate() {
            let (i, j) = (k / (m + 1), k % (m + 1));
            if i > 0 && i < m && j > 0 && j < m && (7 * k).is_multiple_of(3) {
                p[0] += 1.0;
            }
            if i > 0 && i < m && j > 0 && j < m && (5 * k + 1).is_multiple_of(3) {
                p[1] += 1.0;
            }
        }
        let values = vec![0.7; points.len()];
        let s = flip_to_image([n, n], &points, &mut tris, &values, &f, &Control::new()).unwrap();
        assert_eq!(s.flips, 0);
        assert!(s.evaluated > 0);
    }

    #[test]
    fn a_linear_image_keeps_its_triangulation() {
        let n = 9;
        let f: Vec<f64> = (0..n * n)
            .map(|i| (i / n) as f64 + 2.0 * (i % n) as f64)
            .collect();
        let points = [[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0]];
        let values = [0.0, 8.0, 24.0, 16.0];
        let mut t = vec![[0, 1, 2], [0, 2, 3]];
        let s = flip_to_image([n, n], &points, &mut t, &values, &f, &Control::new()).unwrap();
        assert_eq!(s.flips, 0);
        assert_eq!(t, vec![[0, 1, 2], [0, 2, 3]]);
    }
}
