//! The medial cells of a shape and the skeleton built from them (the method
//! is in the [module docs](super)): pad the shape, take its exact distance
//! and feature transforms, mark one cell of each pair of neighbours whose
//! nearest boundary points are far apart along the boundary, thin the marks
//! (2D) or thin the shape around them (3D), and crop back to the grid.

use super::graph::graph_2d;
use super::thinning_2d::thin_2d;
use super::thinning_3d::thin_3d;
use super::{Skeleton, SkeletonError, SkeletonOptions};
use crate::numerics::contours::{self, ContourError, CrackEdge};
use crate::numerics::edt::{self, EdtError, EdtOptions, NO_FEATURE};
use crate::numerics::{Control, Grid};

/// Computes the medial axis of `mask` (true inside the shape).
pub fn medial_axis(
    grid: &Grid,
    mask: &[bool],
    options: &SkeletonOptions,
    control: &Control<'_>,
) -> Result<Skeleton, SkeletonError> {
    medial_axis_with(grid, mask, options, control, true)
}

/// [`medial_axis`], with the 3D thinning optional (the tests compare the
/// thinned skeleton with the medial cells it starts from).
pub(super) fn medial_axis_with(
    grid: &Grid,
    mask: &[bool],
    options: &SkeletonOptions,
    control: &Control<'_>,
    thin_3d_cells: bool,
) -> Result<Skeleton, SkeletonError> {
    check(grid, mask, options)?;
    let padded = Padded::new(grid, mask)?;
    let outside: Vec<bool> = padded.mask.iter().map(|&m| !m).collect();
    let t = edt::edt(
        &padded.grid,
        &outside,
        &EdtOptions::default().with_features(true),
        control,
    )?;
    let features = t.features.unwrap_or_default();
    let dist = t.distance;
    let rule = PairRule::new(&padded, &dist, options, control)?;
    let mut marks = mark_medial_cells(&padded, &features, &rule, control)?;
    let [p0, p1, p2] = padded.shape;
    if padded.two_d {
        thin_2d(&mut marks, p1, p2);
    } else if thin_3d_cells {
        let h = padded.h;
        let hmin = h[0].min(h[1]).min(h[2]);
        marks = thin_3d(&padded.mask, &marks, &dist, [p0, p1, p2], hmin, control)?;
    }
    Ok(padded.crop(&marks, &dist))
}

/// Refuses a mask of the wrong length and negative or non-finite lengths.
fn check(grid: &Grid, mask: &[bool], options: &SkeletonOptions) -> Result<(), SkeletonError> {
    if mask.len() != grid.len() {
        return Err(SkeletonError::Length {
            got: mask.len(),
            expected: grid.len(),
        });
    }
    for (field, v) in [
        ("min_boundary_length", options.min_boundary_length),
        ("min_boundary_fraction", options.min_boundary_fraction),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(SkeletonError::Option {
                field,
                reason: format!("{v} must be finite and >= 0"),
            });
        }
    }
    Ok(())
}

/// The shape padded by one outside cell on every active axis (not on the
/// storage axis 0 of a 2D grid), so that the outside of the grid counts as
/// outside the shape.
struct Padded {
    /// Whether the grid is 2D.
    two_d: bool,
    /// Shape of the caller's grid (3D storage).
    inner: [usize; 3],
    /// Spacing (3D storage).
    h: [f64; 3],
    /// Shape of the padded grid (3D storage).
    shape: [usize; 3],
    /// Linear strides of the padded grid.
    strides: [usize; 3],
    /// The padded grid.
    grid: Grid,
    /// The shape on the padded grid.
    mask: Vec<bool>,
}

impl Padded {
    fn new(grid: &Grid, mask: &[bool]) -> Result<Self, SkeletonError> {
        let two_d = grid.ndim() == 2;
        let s = grid.shape3();
        let h = grid.spacing3();
        let pad0 = usize::from(!two_d);
        let ps = [s[0] + 2 * pad0, s[1] + 2, s[2] + 2];
        let pgrid = if two_d {
            Grid::new(&[ps[1], ps[2]], &[h[1], h[2]])
        } else {
            Grid::new(&ps, &h)
        }
        .map_err(|e| SkeletonError::Option {
            field: "mask",
            reason: e.to_string(),
        })?;
        let mut padded = Self {
            two_d,
            inner: s,
            h,
            shape: ps,
            strides: [ps[1] * ps[2], ps[2], 1],
            mask: vec![false; pgrid.len()],
            grid: pgrid,
        };
        for i in 0..s[0] {
            for j in 0..s[1] {
                for k in 0..s[2] {
                    let p = padded.linear(i, j, k);
                    padded.mask[p] = mask[(i * s[1] + j) * s[2] + k];
                }
            }
        }
        Ok(padded)
    }

    /// The padded linear index of the caller's cell `(i, j, k)`.
    fn linear(&self, i: usize, j: usize, k: usize) -> usize {
        let pad0 = usize::from(!self.two_d);
        ((i + pad0) * self.shape[1] + j + 1) * self.shape[2] + k + 1
    }

    /// The storage coordinates of the padded cell `c`.
    fn coords(&self, c: usize) -> [usize; 3] {
        [
            c / self.strides[0],
            (c / self.strides[1]) % self.shape[1],
            c % self.shape[2],
        ]
    }

    /// The physical distance `|h ⊙ (a − b)|` between the centres of the
    /// padded cells `a` and `b`.
    fn phys(&self, a: usize, b: usize) -> f64 {
        let (ca, cb) = (self.coords(a), self.coords(b));
        (0..3)
            .map(|k| ((ca[k] as f64 - cb[k] as f64) * self.h[k]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The skeleton on the caller's grid: `marks` as its cells, `dist` as
    /// the radius function on them and as the distance inside the shape.
    fn crop(&self, marks: &[bool], dist: &[f64]) -> Skeleton {
        let s = self.inner;
        let n = s[0] * s[1] * s[2];
        let mut out_mask = vec![false; n];
        let mut radius = vec![0.0; n];
        let mut distance = vec![0.0; n];
        for i in 0..s[0] {
            for j in 0..s[1] {
                for k in 0..s[2] {
                    let c = (i * s[1] + j) * s[2] + k;
                    let p = self.linear(i, j, k);
                    out_mask[c] = marks[p];
                    distance[c] = if self.mask[p] { dist[p] } else { 0.0 };
                    if marks[p] {
                        radius[c] = dist[p];
                    }
                }
            }
        }
        let h = self.h;
        let graph = self
            .two_d
            .then(|| graph_2d(&out_mask, &radius, [s[1], s[2]], [h[1], h[2]]));
        Skeleton {
            mask: out_mask,
            radius,
            distance,
            graph,
        }
    }
}

/// The arclength position of the boundary (outside) cells of a 2D padded
/// shape along their boundary curves.
///
/// Each curve is the polygon through the midpoints of the cell edges that
/// separate the shape from the outside, in the order of
/// [`contours::trace`]; an outside cell takes the arclength of its first
/// edge along its first curve.
struct BoundaryArcs {
    /// Arclength of each cell (NaN off the boundary).
    s: Vec<f64>,
    /// The curve of each cell (`u32::MAX` off the boundary).
    ring: Vec<u32>,
    /// The length `|C|` of each curve (closed).
    ring_len: Vec<f64>,
}

impl BoundaryArcs {
    fn new(padded: &Padded, control: &Control<'_>) -> Result<Self, SkeletonError> {
        let [_, n0, n1] = padded.shape;
        let h = padded.h;
        let labels: Vec<i64> = padded.mask.iter().map(|&m| i64::from(m)).collect();
        let b = contours::trace(&labels, [n0, n1], Some(0), control)
            .map_err(|ContourError::Cancelled| SkeletonError::Edt(EdtError::Cancelled))?;
        let mut arcs = Self {
            s: vec![f64::NAN; padded.grid.len()],
            ring: vec![u32::MAX; padded.grid.len()],
            ring_len: Vec::with_capacity(b.rings.len()),
        };
        // The midpoint of a crack edge in physical coordinates (corner
        // `(ci, cj)` has index `ci * (n1 + 1) + cj`).
        let mid = |e: &CrackEdge| -> [f64; 2] {
            let nc1 = n1 + 1;
            let (f, t) = (e.from as usize, e.to as usize);
            [
                ((f / nc1) as f64 + (t / nc1) as f64) * 0.5 * h[1],
                ((f % nc1) as f64 + (t % nc1) as f64) * 0.5 * h[2],
            ]
        };
        let dist =
            |m: [f64; 2], p: [f64; 2]| ((m[0] - p[0]).powi(2) + (m[1] - p[1]).powi(2)).sqrt();
        for (r, ring) in b.rings.iter().enumerate() {
            let mut acc = 0.0;
            let mut prev: Option<[f64; 2]> = None;
            for e in &ring.edges {
                let m = mid(e);
                if let Some(p) = prev {
                    acc += dist(m, p);
                }
                prev = Some(m);
                if let Some(o) = e.outside {
                    let o = o as usize;
                    if arcs.ring[o] == u32::MAX {
                        arcs.ring[o] = r as u32;
                        arcs.s[o] = acc;
                    }
                }
            }
            if let (Some(p), Some(e0)) = (prev, ring.edges.first()) {
                acc += dist(mid(e0), p);
            }
            arcs.ring_len.push(acc);
        }
        Ok(arcs)
    }
}

/// When the two nearest boundary points `a`, `b` of a pair of neighbouring
/// cells are far enough apart for the pair to be medial.
enum PairRule {
    /// 2D: the shorter arc `ℓ(a, b)` of their common boundary curve `C` is
    /// at least `τ = max(min_boundary_length, min_boundary_fraction · |C|,
    /// floor)`; always when they lie on different curves.
    Arc {
        arcs: BoundaryArcs,
        min_length: f64,
        min_fraction: f64,
        floor: f64,
    },
    /// 3D: the chord `|a − b|` is at least `tau`.
    Chord { tau: f64 },
}

impl PairRule {
    /// The rule of `options` on `padded`, with the floor of three cells
    /// `3 h_max`; in 3D `τ = max(min_boundary_length, min_boundary_fraction
    /// · 2 max D, 3 h_max)` with `D` the distance transform `dist`.
    fn new(
        padded: &Padded,
        dist: &[f64],
        options: &SkeletonOptions,
        control: &Control<'_>,
    ) -> Result<Self, SkeletonError> {
        let h = padded.h;
        let hmax = h[1].max(h[2]).max(if padded.two_d { 0.0 } else { h[0] });
        let floor = 3.0 * hmax;
        if padded.two_d {
            return Ok(PairRule::Arc {
                arcs: BoundaryArcs::new(padded, control)?,
                min_length: options.min_boundary_length,
                min_fraction: options.min_boundary_fraction,
                floor,
            });
        }
        let max_d = dist
            .iter()
            .zip(&padded.mask)
            .filter(|(_, &m)| m)
            .map(|(&d, _)| d)
            .fold(0.0f64, f64::max);
        let tau = options
            .min_boundary_length
            .max(options.min_boundary_fraction * 2.0 * max_d)
            .max(floor);
        Ok(PairRule::Chord { tau })
    }

    /// Whether the boundary cells `a` and `b` (padded indices) are far
    /// enough apart.
    fn keeps(&self, padded: &Padded, a: usize, b: usize) -> bool {
        match self {
            PairRule::Arc {
                arcs,
                min_length,
                min_fraction,
                floor,
            } => {
                let (ra, rb) = (arcs.ring[a], arcs.ring[b]);
                if ra == u32::MAX || rb == u32::MAX {
                    false
                } else if ra != rb {
                    true
                } else {
                    let len = arcs.ring_len[ra as usize];
                    let d = (arcs.s[a] - arcs.s[b]).abs();
                    let arc = d.min(len - d);
                    let tau = min_length.max(min_fraction * len).max(*floor);
                    arc >= tau
                }
            }
            PairRule::Chord { tau } => padded.phys(a, b) >= *tau,
        }
    }
}

/// The medial cells: for each pair of cells `x`, `y = x + e_k` of the shape
/// whose nearest boundary points `a = F(x)`, `b = F(y)` differ and pass
/// `rule`, the one nearer to the bisector of `a` and `b` (smaller
/// `|x − b| − |x − a|`; `x` on a tie).
fn mark_medial_cells(
    padded: &Padded,
    features: &[u32],
    rule: &PairRule,
    control: &Control<'_>,
) -> Result<Vec<bool>, SkeletonError> {
    let n = padded.grid.len();
    let mut marks = vec![false; n];
    let axes: &[usize] = if padded.two_d { &[1, 2] } else { &[0, 1, 2] };
    for x in 0..n {
        if x % 65536 == 0 && control.is_cancelled() {
            return Err(EdtError::Cancelled.into());
        }
        if !padded.mask[x] {
            continue;
        }
        for &ax in axes {
            let y = x + padded.strides[ax];
            if y >= n || !padded.mask[y] {
                continue;
            }
            let (a, b) = (features[x] as usize, features[y] as usize);
            if a == b || features[x] == NO_FEATURE || features[y] == NO_FEATURE {
                continue;
            }
            if rule.keeps(padded, a, b) {
                let ix = padded.phys(x, b) - padded.phys(x, a);
                let iy = padded.phys(y, a) - padded.phys(y, b);
                marks[if ix <= iy { x } else { y }] = true;
            }
        }
    }
    Ok(marks)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        ((p[0] - a[0] - t * dx).powi(2) + (p[1] - a[1] - t * dy).powi(2)).sqrt()
    }

    #[test]
    fn rectangle_skeleton_is_its_medial_axis_within_one_cell() {
        // Cells [10, 40) x [10, 90): boundary (outside cell centres) at 9 / 40 and 9 / 90.
        let (n0, n1) = (50, 100);
        let grid = Grid::unit(&[n0, n1]).unwrap();
        let mask: Vec<bool> = (0..n0 * n1)
            .map(|c| (10..40).contains(&(c / n1)) && (10..90).contains(&(c % n1)))
            .collect();
        let (lo0, hi0, lo1, hi1) = (9.0, 40.0, 9.0, 90.0);
        let half = (hi0 - lo0) / 2.0;
        let mid = (lo0 + hi0) / 2.0;
        let segs = [
            ([mid, lo1 + half], [mid, hi1 - half]),
            ([lo0, lo1], [mid, lo1 + half]),
            ([hi0, lo1], [mid, lo1 + half]),
            ([lo0, hi1], [mid, hi1 - half]),
            ([hi0, hi1], [mid, hi1 - half]),
        ];
        let axis_dist = |p: [f64; 2]| {
            segs.iter()
                .map(|&(a, b)| seg_dist(p, a, b))
                .fold(f64::INFINITY, f64::min)
        };
        for (opts, reach) in [
            (SkeletonOptions::OFF, 3.0),
            (SkeletonOptions::default(), 0.0),
        ] {
            let sk = medial_axis(&grid, &mask, &opts, &Control::new()).unwrap();
            let cells: Vec<[f64; 2]> = (0..n0 * n1)
                .filter(|&c| sk.mask[c])
                .map(|c| [(c / n1) as f64, (c % n1) as f64])
                .collect();
            for p in &cells {
                assert!(
                    axis_dist(*p) <= 1.0,
                    "{p:?} is {} from the axis",
                    axis_dist(*p)
                );
            }
            // The expected (pruned) axis: points whose two boundary feet are at
            // least tau apart along the boundary. On a diagonal at distance t
            // from both sides that arc is 2t; on the middle segment it is >= 2 half.
            let perim = 2.0 * ((hi0 - lo0) + (hi1 - lo1));
            let tau = (opts.min_boundary_fraction * perim).max(3.0) + reach;
            for &(a, b) in &segs {
                for k in 0..=100 {
                    let t = k as f64 / 100.0;
                    let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                    let clearance = (p[0] - lo0).min(hi0 - p[0]).min(p[1] - lo1).min(hi1 - p[1]);
                    if 2.0 * clearance < tau + 2.0 {
                        continue;
                    }
                    let near = cells
                        .iter()
                        .map(|c| ((c[0] - p[0]).powi(2) + (c[1] - p[1]).powi(2)).sqrt())
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        near <= 1.0 + 1e-9,
                        "axis point {p:?} has no skeleton cell within one cell ({near})"
                    );
                }
            }
            let g = sk.graph.unwrap();
            let ends = g.nodes.iter().filter(|n| n.degree == 1).count();
            assert_eq!(ends, 4, "four diagonal branches: {:?}", g.nodes);
        }
    }

    #[test]
    fn bump_grows_a_branch_only_without_pruning() {
        let n = 80;
        let grid = Grid::unit(&[n, n]).unwrap();
        let (c, r, br) = (40.0, 30.0, 3.0);
        let bump = [c, c + r];
        let mask: Vec<bool> = (0..n * n)
            .map(|k| {
                let (i, j) = ((k / n) as f64, (k % n) as f64);
                ((i - c).powi(2) + (j - c).powi(2)).sqrt() <= r
                    || ((i - bump[0]).powi(2) + (j - bump[1]).powi(2)).sqrt() <= br
            })
            .collect();
        // Skeleton cells toward the bump: beyond 8 cells from the centre, within 20 degrees of the bump direction.
        let toward = |sk: &Skeleton| {
            (0..n * n)
                .filter(|&k| sk.mask[k])
                .filter(|&k| {
                    let (di, dj) = ((k / n) as f64 - c, (k % n) as f64 - c);
                    let rr = (di * di + dj * dj).sqrt();
                    rr > 8.0 && dj > 0.0 && (di / rr).abs() < 20f64.to_radians().sin()
                })
                .count()
        };
        let pruned =
            medial_axis(&grid, &mask, &SkeletonOptions::default(), &Control::new()).unwrap();
        assert_eq!(toward(&pruned), 0);
        let centre = (0..n * n)
            .filter(|&k| pruned.mask[k])
            .map(|k| (((k / n) as f64 - c).powi(2) + ((k % n) as f64 - c).powi(2)).sqrt())
            .fold(f64::INFINITY, f64::min);
        assert!(centre <= 1.5, "the disc keeps its centre ({centre})");
        let raw = medial_axis(&grid, &mask, &SkeletonOptions::OFF, &Control::new()).unwrap();
        assert!(
            toward(&raw) >= 10,
            "branch toward the bump: {} cells",
            toward(&raw)
        );
    }
}
