//! Medial axis (skeleton) of a binary shape in 2D and 3D, with pruning by a
//! length that has a geometric meaning, and in 2D the skeleton as a graph of
//! polylines.
//!
//! # Method
//! Let `D` be the distance from a cell of the shape to the nearest cell
//! outside it and `F` the nearest-boundary-point map (the exact transform and
//! feature transform of [`crate::numerics::edt`]; the grid is padded by one
//! empty cell so that the outside of the grid counts as outside the shape).
//! The medial axis is where `D` is not differentiable: where two neighbouring
//! cells `x`, `y` have nearest boundary points `a = F(x)`, `b = F(y)` far
//! apart (seed §1.4.2, §2.6.2). The pair is kept when the two points are far
//! apart *along the boundary*:
//! * 2D: `ℓ(a, b)`, the length of the shorter arc of the boundary curve from
//!   `a` to `b` (measured on the polygon through the midpoints of the cell
//!   edges that separate the shape from the outside; infinite when `a` and `b`
//!   lie on different boundary curves, e.g. around a hole), must be at least
//!   `τ = max(min_boundary_length, min_boundary_fraction · |C|, 3 h_max)`,
//!   where `|C|` is the length of that boundary curve. A bump of the boundary
//!   whose perimeter is below `τ` grows no branch; the branch toward a corner
//!   of angle `θ` starts where the distance to the corner's sides exceeds `τ/2`.
//! * 3D: the chord `|a - b|` must be at least
//!   `τ = max(min_boundary_length, min_boundary_fraction · 2 max D, 3 h_max)`
//!   (the λ-medial axis of Chazal–Lieutier).
//!
//! Of the two cells of a kept pair, the one nearer to the bisector of `a` and
//! `b` (smaller `|x - b| - |x - a|`) is marked. In 2D the marks are thinned to
//! one cell (Zhang–Suen, which keeps end points and connectivity). The radius
//! function is `D` on the skeleton (distance between cell centres; the
//! inscribed disc reaches the boundary edges at `D - h/2`).
//!
//! Cost: one EDT plus `O(N)`.

use super::contours::{self, CrackEdge};
use super::edt::{self, EdtError, EdtOptions, NO_FEATURE};
use super::{Control, Grid};

/// Options of [`medial_axis`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkeletonOptions {
    /// Smallest boundary length (2D: arc, 3D: chord) between the two nearest
    /// boundary points of a kept pair, in physical units. Default: 0.
    pub min_boundary_length: f64,
    /// Smallest length as a fraction of the boundary curve's length (2D) or of
    /// the largest inscribed diameter (3D). Default: 0.08. Setting both to 0
    /// turns pruning off (the floor of 3 cells that filters pixel noise stays).
    pub min_boundary_fraction: f64,
}

impl Default for SkeletonOptions {
    fn default() -> Self {
        Self {
            min_boundary_length: 0.0,
            min_boundary_fraction: 0.08,
        }
    }
}

impl SkeletonOptions {
    /// No pruning beyond the 3-cell floor.
    pub const OFF: Self = Self {
        min_boundary_length: 0.0,
        min_boundary_fraction: 0.0,
    };
}

/// Why a skeleton was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkeletonError {
    /// The distance transform failed.
    #[error(transparent)]
    Edt(#[from] EdtError),
    /// The mask does not have one value per cell.
    #[error("the mask has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells.
        expected: usize,
    },
    /// An option is out of range.
    #[error("{field}: {reason}")]
    Option {
        /// The option.
        field: &'static str,
        /// Why.
        reason: String,
    },
}

/// A node of the skeleton graph: an end point, a junction (a cluster of
/// adjacent junction cells counts once), or one cell of a closed loop.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SkeletonNode {
    /// Node id (its index).
    pub id: usize,
    /// Position in index coordinates (mean of the cluster's cells).
    pub point: [f64; 2],
    /// Radius function (distance to the boundary) there.
    pub radius: f64,
    /// Number of branches that meet there.
    pub degree: usize,
}

/// A branch: a polyline of skeleton cells between two nodes.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SkeletonEdge {
    /// Node at the start.
    pub source: usize,
    /// Node at the end.
    pub target: usize,
    /// Cell centres from source to target, in index coordinates.
    pub points: Vec<[f64; 2]>,
    /// Radius function at each point.
    pub radius: Vec<f64>,
    /// Physical length of the polyline.
    pub length: f64,
}

/// The skeleton of a 2D shape as a graph.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize)]
pub struct SkeletonGraph {
    /// Nodes.
    pub nodes: Vec<SkeletonNode>,
    /// Branches.
    pub edges: Vec<SkeletonEdge>,
}

/// The medial axis of a shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    /// Skeleton cells (C order).
    pub mask: Vec<bool>,
    /// Distance to the nearest cell outside the shape on skeleton cells, 0 elsewhere.
    pub radius: Vec<f64>,
    /// The distance to the nearest outside cell on the whole grid (0 outside the shape).
    pub distance: Vec<f64>,
    /// 2D only: the skeleton as a graph.
    pub graph: Option<SkeletonGraph>,
}

/// Computes the medial axis of `mask` (true inside the shape).
pub fn medial_axis(
    grid: &Grid,
    mask: &[bool],
    options: &SkeletonOptions,
    control: &Control<'_>,
) -> Result<Skeleton, SkeletonError> {
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
    let two_d = grid.ndim() == 2;
    let s = grid.shape3();
    let h = grid.spacing3();
    // Pad by one outside cell on every active axis.
    let pad = |a: usize| usize::from(!(two_d && a == 0));
    let ps = [s[0] + 2 * pad(0), s[1] + 2, s[2] + 2];
    let pgrid = if two_d {
        Grid::new(&[ps[1], ps[2]], &[h[1], h[2]])
    } else {
        Grid::new(&ps, &h)
    }
    .map_err(|e| SkeletonError::Option {
        field: "mask",
        reason: e.to_string(),
    })?;
    let plin = |i: usize, j: usize, k: usize| ((i + pad(0)) * ps[1] + j + 1) * ps[2] + k + 1;
    let mut pmask = vec![false; pgrid.len()];
    for i in 0..s[0] {
        for j in 0..s[1] {
            for k in 0..s[2] {
                pmask[plin(i, j, k)] = mask[(i * s[1] + j) * s[2] + k];
            }
        }
    }
    let outside: Vec<bool> = pmask.iter().map(|&m| !m).collect();
    let t = edt::edt(
        &pgrid,
        &outside,
        &EdtOptions::default().with_features(true),
        control,
    )?;
    let feats = t.features.unwrap_or_default();
    let dist = t.distance;
    let hmax = h[1].max(h[2]).max(if two_d { 0.0 } else { h[0] });
    let floor = 3.0 * hmax;
    let pstr = [ps[1] * ps[2], ps[2], 1];
    let coords = |c: usize| [c / pstr[0], (c / pstr[1]) % ps[1], c % ps[2]];
    let phys = |a: usize, b: usize| -> f64 {
        let (ca, cb) = (coords(a), coords(b));
        (0..3)
            .map(|k| ((ca[k] as f64 - cb[k] as f64) * h[k]).powi(2))
            .sum::<f64>()
            .sqrt()
    };

    // 2D: arclength parameter of each boundary (outside) cell.
    let mut arc_s = Vec::new();
    let mut arc_ring = Vec::new();
    let mut ring_len = Vec::new();
    if two_d {
        let labels: Vec<i64> = pmask.iter().map(|&m| i64::from(m)).collect();
        let b = contours::trace(&labels, [ps[1], ps[2]], Some(0));
        arc_s = vec![f64::NAN; pgrid.len()];
        arc_ring = vec![u32::MAX; pgrid.len()];
        let mid = |e: &CrackEdge| -> [f64; 2] {
            let nc1 = ps[2] + 1;
            let (f, t) = (e.from as usize, e.to as usize);
            [
                ((f / nc1) as f64 + (t / nc1) as f64) * 0.5 * h[1],
                ((f % nc1) as f64 + (t % nc1) as f64) * 0.5 * h[2],
            ]
        };
        for (r, ring) in b.rings.iter().enumerate() {
            let mut acc = 0.0;
            let mut prev: Option<[f64; 2]> = None;
            for e in &ring.edges {
                let m = mid(e);
                if let Some(p) = prev {
                    acc += ((m[0] - p[0]).powi(2) + (m[1] - p[1]).powi(2)).sqrt();
                }
                prev = Some(m);
                if let Some(o) = e.outside {
                    let o = o as usize;
                    if arc_ring[o] == u32::MAX {
                        arc_ring[o] = r as u32;
                        arc_s[o] = acc;
                    }
                }
            }
            if let (Some(p), Some(e0)) = (prev, ring.edges.first()) {
                let m = mid(e0);
                acc += ((m[0] - p[0]).powi(2) + (m[1] - p[1]).powi(2)).sqrt();
            }
            ring_len.push(acc);
        }
    }
    let max_d = dist
        .iter()
        .zip(&pmask)
        .filter(|(_, &m)| m)
        .map(|(&d, _)| d)
        .fold(0.0f64, f64::max);
    let tau3 = options
        .min_boundary_length
        .max(options.min_boundary_fraction * 2.0 * max_d)
        .max(floor);

    let mut marks = vec![false; pgrid.len()];
    let axes: &[usize] = if two_d { &[1, 2] } else { &[0, 1, 2] };
    for x in 0..pgrid.len() {
        if x % 65536 == 0 && control.is_cancelled() {
            return Err(EdtError::Cancelled.into());
        }
        if !pmask[x] {
            continue;
        }
        for &ax in axes {
            let y = x + pstr[ax];
            if y >= pgrid.len() || !pmask[y] {
                continue;
            }
            let (a, b) = (feats[x] as usize, feats[y] as usize);
            if a == b || feats[x] == NO_FEATURE || feats[y] == NO_FEATURE {
                continue;
            }
            let keep = if two_d {
                let (ra, rb) = (arc_ring[a], arc_ring[b]);
                if ra == u32::MAX || rb == u32::MAX {
                    false
                } else if ra != rb {
                    true
                } else {
                    let len = ring_len[ra as usize];
                    let d = (arc_s[a] - arc_s[b]).abs();
                    let arc = d.min(len - d);
                    let tau = options
                        .min_boundary_length
                        .max(options.min_boundary_fraction * len)
                        .max(floor);
                    arc >= tau
                }
            } else {
                phys(a, b) >= tau3
            };
            if keep {
                let ix = phys(x, b) - phys(x, a);
                let iy = phys(y, a) - phys(y, b);
                marks[if ix <= iy { x } else { y }] = true;
            }
        }
    }
    if two_d {
        thin_2d(&mut marks, ps[1], ps[2]);
    }
    let mut out_mask = vec![false; grid.len()];
    let mut radius = vec![0.0; grid.len()];
    let mut distance = vec![0.0; grid.len()];
    for i in 0..s[0] {
        for j in 0..s[1] {
            for k in 0..s[2] {
                let c = (i * s[1] + j) * s[2] + k;
                let p = plin(i, j, k);
                out_mask[c] = marks[p];
                distance[c] = if pmask[p] { dist[p] } else { 0.0 };
                if marks[p] {
                    radius[c] = dist[p];
                }
            }
        }
    }
    let graph = two_d.then(|| graph_2d(&out_mask, &radius, [s[1], s[2]], [h[1], h[2]]));
    Ok(Skeleton {
        mask: out_mask,
        radius,
        distance,
        graph,
    })
}

/// Zhang–Suen thinning on an `(n0, n1)` image whose border is empty.
fn thin_2d(m: &mut [bool], n0: usize, n1: usize) {
    let mut changed = true;
    let mut del = Vec::new();
    while changed {
        changed = false;
        for pass in 0..2 {
            del.clear();
            for i in 1..n0.saturating_sub(1) {
                for j in 1..n1 - 1 {
                    let c = i * n1 + j;
                    if !m[c] {
                        continue;
                    }
                    // P2..P9 clockwise from north.
                    let p = [
                        m[c - n1],
                        m[c - n1 + 1],
                        m[c + 1],
                        m[c + n1 + 1],
                        m[c + n1],
                        m[c + n1 - 1],
                        m[c - 1],
                        m[c - n1 - 1],
                    ];
                    let b = p.iter().filter(|&&v| v).count();
                    if !(2..=6).contains(&b) {
                        continue;
                    }
                    let a = (0..8).filter(|&k| !p[k] && p[(k + 1) % 8]).count();
                    if a != 1 {
                        continue;
                    }
                    let (p2, p4, p6, p8) = (p[0], p[2], p[4], p[6]);
                    let ok = if pass == 0 {
                        !(p4 && p6 && (p2 || p8))
                    } else {
                        !(p2 && p8 && (p4 || p6))
                    };
                    if ok {
                        del.push(c);
                    }
                }
            }
            for &c in &del {
                m[c] = false;
            }
            changed |= !del.is_empty();
        }
    }
}

/// The graph of a one-cell-thin 2D skeleton (8-connectivity).
pub fn graph_2d(mask: &[bool], radius: &[f64], shape: [usize; 2], h: [f64; 2]) -> SkeletonGraph {
    let [n0, n1] = shape;
    let nbrs = |c: usize| -> Vec<usize> {
        let (i, j) = ((c / n1) as i64, (c % n1) as i64);
        let mut v = Vec::with_capacity(8);
        for di in -1..=1i64 {
            for dj in -1..=1i64 {
                if di == 0 && dj == 0 {
                    continue;
                }
                let (a, b) = (i + di, j + dj);
                if a >= 0 && b >= 0 && (a as usize) < n0 && (b as usize) < n1 {
                    let k = a as usize * n1 + b as usize;
                    if mask[k] {
                        v.push(k);
                    }
                }
            }
        }
        v
    };
    let pt = |c: usize| [(c / n1) as f64, (c % n1) as f64];
    let step = |a: usize, b: usize| {
        let (p, q) = (pt(a), pt(b));
        (((p[0] - q[0]) * h[0]).powi(2) + ((p[1] - q[1]) * h[1]).powi(2)).sqrt()
    };
    // Node cells: degree != 2; clusters of adjacent node cells are one node.
    let mut node_of = vec![usize::MAX; mask.len()];
    let mut graph = SkeletonGraph::default();
    let cells: Vec<usize> = (0..mask.len()).filter(|&c| mask[c]).collect();
    let is_node_cell = |c: usize| nbrs(c).len() != 2;
    for &c in &cells {
        if node_of[c] != usize::MAX || !is_node_cell(c) {
            continue;
        }
        let id = graph.nodes.len();
        let mut stack = vec![c];
        node_of[c] = id;
        let mut members = Vec::new();
        while let Some(x) = stack.pop() {
            members.push(x);
            for y in nbrs(x) {
                if node_of[y] == usize::MAX
                    && is_node_cell(y)
                    && nbrs(y).len() > 2
                    && nbrs(x).len() > 2
                {
                    node_of[y] = id;
                    stack.push(y);
                }
            }
        }
        let k = members.len() as f64;
        let point = members.iter().fold([0.0, 0.0], |acc, &m| {
            let p = pt(m);
            [acc[0] + p[0] / k, acc[1] + p[1] / k]
        });
        let r = members.iter().map(|&m| radius[m]).fold(0.0, f64::max);
        graph.nodes.push(SkeletonNode {
            id,
            point,
            radius: r,
            degree: 0,
        });
    }
    let mut visited = vec![false; mask.len()];
    let walk = |start_node: usize,
                from: usize,
                first: usize,
                visited: &mut Vec<bool>,
                node_of: &Vec<usize>,
                graph: &mut SkeletonGraph| {
        let mut points = vec![pt(from), pt(first)];
        let mut radii = vec![radius[from], radius[first]];
        let mut length = step(from, first);
        let (mut prev, mut cur) = (from, first);
        loop {
            if node_of[cur] != usize::MAX {
                break;
            }
            visited[cur] = true;
            let next = nbrs(cur)
                .into_iter()
                .find(|&n| n != prev && (node_of[n] != usize::MAX || !visited[n]));
            match next {
                Some(n) => {
                    length += step(cur, n);
                    points.push(pt(n));
                    radii.push(radius[n]);
                    prev = cur;
                    cur = n;
                }
                None => break,
            }
        }
        let target = node_of[cur];
        if target == usize::MAX {
            return;
        }
        graph.nodes[start_node].degree += 1;
        graph.nodes[target].degree += 1;
        graph.edges.push(SkeletonEdge {
            source: start_node,
            target,
            points,
            radius: radii,
            length,
        });
    };
    let mut done_pairs = std::collections::HashSet::new();
    for &c in &cells {
        let n = node_of[c];
        if n == usize::MAX {
            continue;
        }
        for y in nbrs(c) {
            if node_of[y] == n {
                continue;
            }
            if node_of[y] != usize::MAX {
                // Two node clusters side by side: one short branch.
                let key = (n.min(node_of[y]), n.max(node_of[y]));
                if done_pairs.insert(key) {
                    graph.nodes[n].degree += 1;
                    graph.nodes[node_of[y]].degree += 1;
                    graph.edges.push(SkeletonEdge {
                        source: n,
                        target: node_of[y],
                        points: vec![pt(c), pt(y)],
                        radius: vec![radius[c], radius[y]],
                        length: step(c, y),
                    });
                }
                continue;
            }
            if visited[y] {
                continue;
            }
            walk(n, c, y, &mut visited, &node_of, &mut graph);
        }
    }
    // Closed loops without any node: cut each at one cell.
    for &c in &cells {
        if visited[c] || node_of[c] != usize::MAX {
            continue;
        }
        let id = graph.nodes.len();
        node_of[c] = id;
        graph.nodes.push(SkeletonNode {
            id,
            point: pt(c),
            radius: radius[c],
            degree: 0,
        });
        if let Some(y) = nbrs(c).into_iter().next() {
            walk(id, c, y, &mut visited, &node_of, &mut graph);
        }
    }
    graph
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

    #[test]
    fn three_d_box_axis_and_errors() {
        let grid = Grid::unit(&[12, 12, 30]).unwrap();
        let mask: Vec<bool> = (0..grid.len())
            .map(|c| {
                let p = grid.unravel(c);
                (2..10).contains(&p[0]) && (2..10).contains(&p[1]) && (2..28).contains(&p[2])
            })
            .collect();
        let sk = medial_axis(&grid, &mask, &SkeletonOptions::default(), &Control::new()).unwrap();
        // The central segment of the axis (square cross-section 8 x 8, centre 5.5).
        let on_axis = (6..24)
            .filter(|&k| (4..8).any(|i| (4..8).any(|j| sk.mask[grid.linear([i, j, k])])))
            .count();
        assert_eq!(on_axis, 18);
        assert!(sk.graph.is_none());
        let bad = SkeletonOptions {
            min_boundary_length: -1.0,
            ..SkeletonOptions::default()
        };
        assert!(matches!(
            medial_axis(&grid, &mask, &bad, &Control::new()),
            Err(SkeletonError::Option {
                field: "min_boundary_length",
                ..
            })
        ));
    }
}
