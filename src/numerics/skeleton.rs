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
//! one cell (Zhang–Suen, which keeps end points and connectivity). In 3D the
//! marks are the anchors of a topology-preserving thinning of the whole shape
//! (removal of simple points in the (26, 6) connectivity, shallowest first,
//! peeled from the six directions in turn, never the end of a curve that is
//! a mark): the result is a curve skeleton, one cell thin, with the topology
//! of the shape (26-components, tunnels; a cavity keeps a closed surface
//! around it), whose curves end on medial cells (see `thin_3d`). Pruning acts
//! through the marks: a branch survives only where it ends on a kept mark.
//! The radius
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
    /// 2D only: the skeleton as a graph (in 3D, `mask` holds a curve skeleton).
    pub graph: Option<SkeletonGraph>,
}

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
fn medial_axis_with(
    grid: &Grid,
    mask: &[bool],
    options: &SkeletonOptions,
    control: &Control<'_>,
    thin_3d_cells: bool,
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
        let b = contours::trace(&labels, [ps[1], ps[2]], Some(0), control)
            .map_err(|contours::ContourError::Cancelled| EdtError::Cancelled)?;
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
    } else if thin_3d_cells {
        marks = thin_3d(&pmask, &marks, &dist, ps, h[0].min(h[1]).min(h[2]), control)?;
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

/// Distance-ordered homotopic thinning of a 3D shape to a curve skeleton.
///
/// `shape` is the padded shape (grid `ps`, empty border), `anchors` its medial
/// cells, `dist` the distance to the boundary, `hmin` the smallest spacing.
/// The current set `X` starts as the shape. For the levels `L = 0, 1, 2, …`
/// (cells with `⌊dist / hmin⌋ ≤ L` may go), rounds of six directional
/// sub-iterations (`±e_0, ±e_1, ±e_2`, as in Lee–Kashyap–Chu 1994) run until a
/// round removes nothing. A sub-iteration for the direction `e`:
/// 1. takes, on `X` as it is, the exposed cells: `p ∈ X` at level `≤ L` with
///    `p + e ∉ X` and `p - e ∈ X` (material behind it, so a sheet or a curve
///    one cell thin across `e` is not pierced; a cell with no 6-neighbour in
///    `X` is exposed too);
/// 2. for each of the 8 subfields (parity classes of the coordinates) in
///    turn, removes the exposed cells of the subfield that are simple
///    ([`is_simple`], (26, 6) connectivity) and are not the end of a medial
///    curve (an anchor with exactly one 26-neighbour in `X`). No two cells of a
///    subfield are 26-adjacent, so these tests do not depend on the order of
///    the removals inside it, and removing them all at once keeps the topology.
///
/// Removing only simple points keeps the topology of the shape: as many
/// 26-components, tunnels and cavities. Peeling from the six sides in turn,
/// the shallowest cells first, with the exposure fixed before each
/// sub-iteration (peeling one layer, never two), keeps what is left centred:
/// it ends as curves through the deepest cells (closed surfaces around
/// cavities). A medial cell near the boundary (a spur of the digitised
/// surface) is reached while it is still inside thick material, with many
/// neighbours, and goes; a curve stops shrinking at an anchored end.
/// A last sequential sweep removes the simple cells that no direction exposes
/// (two curves side by side along a diagonal).
fn thin_3d(
    shape: &[bool],
    anchors: &[bool],
    dist: &[f64],
    ps: [usize; 3],
    hmin: f64,
    control: &Control<'_>,
) -> Result<Vec<bool>, SkeletonError> {
    let st = [ps[1] * ps[2], ps[2], 1];
    let mut offset = [0isize; 27];
    for (p, o) in offset.iter_mut().enumerate() {
        let d = cube_pos(p);
        *o = d[0] * st[0] as isize + d[1] * st[1] as isize + d[2] * st[2] as isize;
    }
    let nbhd = |x: &[bool], c: usize| -> u32 {
        let mut bits = 0u32;
        for (p, &o) in offset.iter().enumerate() {
            if p != CENTRE && x[c.wrapping_add_signed(o)] {
                bits |= 1 << p;
            }
        }
        bits
    };
    let level = |c: usize| (dist[c] / hmin) as usize;
    // The parity class of a cell's coordinates: 8 subfields.
    let subfield = |c: usize| (c / st[0] % 2) * 4 + (c / st[1] % ps[1] % 2) * 2 + c % ps[2] % 2;
    let faces = [
        st[0] as isize,
        -(st[0] as isize),
        st[1] as isize,
        -(st[1] as isize),
        1,
        -1,
    ];
    let mut x = shape.to_vec();
    // Border cells (a 6-neighbour outside X): only they can be simple.
    // `active` holds those at the current level or below, `later[l]` those
    // of level l above it.
    let mut listed = vec![false; x.len()];
    let mut later: Vec<Vec<usize>> = Vec::new();
    for c in 0..x.len() {
        if x[c] && faces.iter().any(|&o| !x[c.wrapping_add_signed(o)]) {
            listed[c] = true;
            let l = level(c);
            if later.len() <= l {
                later.resize_with(l + 1, Vec::new);
            }
            later[l].push(c);
        }
    }
    let mut active: Vec<usize> = Vec::new();
    let mut cand = Vec::new();
    let mut exposed = Vec::new();
    let mut l = 0;
    while l < later.len() {
        active.append(&mut later[l]);
        loop {
            if control.is_cancelled() {
                return Err(EdtError::Cancelled.into());
            }
            let mut removed = false;
            for &e in &faces {
                // The cells exposed in the direction e, before any removal
                // of this sub-iteration.
                exposed.clear();
                exposed.extend(active.iter().copied().filter(|&c| {
                    x[c] && !x[c.wrapping_add_signed(e)]
                        && (x[c.wrapping_add_signed(-e)] || nbhd(&x, c) & ADJ6[CENTRE] == 0)
                }));
                for sub in 0..8 {
                    cand.clear();
                    cand.extend(exposed.iter().copied().filter(|&c| {
                        subfield(c) == sub && {
                            let n = nbhd(&x, c);
                            !(anchors[c] && n.count_ones() == 1) && is_simple(n)
                        }
                    }));
                    // No two cells of a subfield are 26-adjacent: removing
                    // one changes no other's neighbourhood, so the tests
                    // above hold for all of them at once.
                    for &c in &cand {
                        x[c] = false;
                        removed = true;
                        for &o in &faces {
                            let y = c.wrapping_add_signed(o);
                            if x[y] && !listed[y] {
                                listed[y] = true;
                                let ly = level(y);
                                if ly <= l {
                                    active.push(y);
                                } else {
                                    if later.len() <= ly {
                                        later.resize_with(ly + 1, Vec::new);
                                    }
                                    later[ly].push(y);
                                }
                            }
                        }
                    }
                }
            }
            active.retain(|&c| x[c]);
            if !removed {
                break;
            }
        }
        l += 1;
    }
    // What the directional passes cannot reach: simple cells with
    // 6-neighbours on opposite sides only across the thin set (two curves
    // side by side along a diagonal), removed one at a time.
    let mut cells: Vec<usize> = (0..x.len()).filter(|&c| x[c]).collect();
    loop {
        let mut removed = false;
        for &c in &cells {
            let n = nbhd(&x, c);
            if !(anchors[c] && n.count_ones() == 1) && is_simple(n) {
                x[c] = false;
                removed = true;
            }
        }
        if !removed {
            break;
        }
        cells.retain(|&c| x[c]);
    }
    Ok(x)
}

/// Position of the centre in the 3×3×3 neighbourhood, whose position
/// `p = 9 (d0 + 1) + 3 (d1 + 1) + (d2 + 1)` is the offset `(d0, d1, d2)`.
const CENTRE: usize = 13;

/// The offset `(d0, d1, d2) ∈ {-1, 0, 1}³` of position `p` of the 3×3×3 neighbourhood.
const fn cube_pos(p: usize) -> [isize; 3] {
    [
        (p / 9) as isize - 1,
        ((p / 3) % 3) as isize - 1,
        (p % 3) as isize - 1,
    ]
}

/// Adjacency of the 27 positions as bit masks: `ADJ26[p]` has the positions
/// at Chebyshev distance 1 from `p` (26-adjacency), `ADJ6[p]` those at
/// Manhattan distance 1 (6-adjacency).
const fn cube_adjacency(six: bool) -> [u32; 27] {
    let mut adj = [0u32; 27];
    let mut p = 0;
    while p < 27 {
        let a = cube_pos(p);
        let mut q = 0;
        while q < 27 {
            let b = cube_pos(q);
            let d = [
                (a[0] - b[0]).abs(),
                (a[1] - b[1]).abs(),
                (a[2] - b[2]).abs(),
            ];
            let cheb = if d[0] > d[1] { d[0] } else { d[1] };
            let cheb = if cheb > d[2] { cheb } else { d[2] };
            let manh = d[0] + d[1] + d[2];
            if p != q && cheb == 1 && (!six || manh == 1) {
                adj[p] |= 1 << q;
            }
            q += 1;
        }
        p += 1;
    }
    adj
}

const ADJ26: [u32; 27] = cube_adjacency(false);
const ADJ6: [u32; 27] = cube_adjacency(true);

/// The 18-neighbourhood of the centre without it: every position but the
/// centre and the eight corners (offsets with three non-zero coordinates).
const N18: u32 = {
    let mut m = 0u32;
    let mut p = 0;
    while p < 27 {
        let d = cube_pos(p);
        let nz = (d[0] != 0) as u32 + (d[1] != 0) as u32 + (d[2] != 0) as u32;
        if nz == 1 || nz == 2 {
            m |= 1 << p;
        }
        p += 1;
    }
    m
};

/// The component of `set` (bit mask of positions) that contains the
/// positions of `seed`, under the adjacency `adj`.
fn grow(seed: u32, set: u32, adj: &[u32; 27]) -> u32 {
    let mut comp = seed & set;
    let mut front = comp;
    while front != 0 {
        let mut next = 0u32;
        let mut bits = front;
        while bits != 0 {
            let q = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            next |= adj[q];
        }
        front = next & set & !comp;
        comp |= front;
    }
    comp
}

/// Whether the centre of a 3×3×3 neighbourhood is a simple point of the
/// foreground in the (26, 6) connectivity (Bertrand–Malandain 1994):
/// `nbhd` has bit `p` set when position `p` is foreground (the centre's bit
/// is ignored). With `X* = N26*(p) ∩ X` and `B = N18*(p) \ X`, the centre is
/// simple iff
/// * the topological number `T26 = #26-components of X*` is 1, and
/// * `T6 = #6-components of B that contain a 6-neighbour of p` is 1.
///
/// Removing a simple point from `X` changes neither the 26-components of `X`,
/// nor the 6-components of its complement, nor their tunnels.
fn is_simple(nbhd: u32) -> bool {
    let all = ((1u32 << 27) - 1) & !(1 << CENTRE);
    let fg = nbhd & all;
    if fg == 0 {
        return false;
    }
    let first = fg & fg.wrapping_neg();
    if grow(first, fg, &ADJ26) != fg {
        return false;
    }
    let bg = N18 & !fg;
    let faces = ADJ6[CENTRE] & bg;
    if faces == 0 {
        return false;
    }
    let first = faces & faces.wrapping_neg();
    // One component iff the component of one free face reaches all free faces.
    grow(first, bg, &ADJ6) & faces == faces
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

    /// The 27-bit neighbourhood with the given offsets set.
    fn cube(offsets: &[[isize; 3]]) -> u32 {
        offsets
            .iter()
            .map(|d| 1u32 << ((d[0] + 1) * 9 + (d[1] + 1) * 3 + d[2] + 1))
            .fold(0, |a, b| a | b)
    }

    /// All offsets of the neighbourhood but the centre that satisfy `f`.
    fn cube_where(f: impl Fn([isize; 3]) -> bool) -> u32 {
        (0..27)
            .filter(|&p| p != CENTRE && f(cube_pos(p)))
            .fold(0, |a, p| a | (1 << p))
    }

    #[test]
    fn simple_points_in_26_6_connectivity() {
        // Isolated voxel: removing it deletes a component.
        assert!(!is_simple(0));
        // End of a line (face, edge or corner neighbour): simple.
        assert!(is_simple(cube(&[[0, 0, 1]])));
        assert!(is_simple(cube(&[[0, 1, 1]])));
        assert!(is_simple(cube(&[[1, 1, 1]])));
        // Middle of a line, straight or bent: removing it splits the line.
        assert!(!is_simple(cube(&[[0, 0, -1], [0, 0, 1]])));
        assert!(!is_simple(cube(&[[-1, -1, -1], [1, 1, 1]])));
        assert!(!is_simple(cube(&[[0, -1, 0], [1, 1, 1]])));
        // A corner of a bent line whose two neighbours touch each other: simple.
        assert!(is_simple(cube(&[[0, 0, 1], [0, 1, 0]])));
        // The centre of a ring in a plane: removing it opens a tunnel through
        // the ring (the background above and below would join), not simple.
        let ring = cube_where(|d| d[0] == 0);
        assert!(!is_simple(ring));
        // Interior of a solid: removing it creates a cavity.
        assert!(!is_simple(cube_where(|_| true)));
        // Flat face of a solid (foreground on one side, including the face plane): simple.
        assert!(is_simple(cube_where(|d| d[0] >= 0)));
        // An edge and a corner of a solid cube: simple.
        assert!(is_simple(cube_where(|d| d[0] >= 0 && d[1] >= 0)));
        assert!(is_simple(cube_where(|d| d[0] >= 0
            && d[1] >= 0
            && d[2] >= 0)));
        // A ring broken at a face cell: removing the centre leaves a bent
        // line and no tunnel, simple. (Broken at a corner cell, the ring is
        // still closed through the 26-adjacent face cells.)
        assert!(is_simple(ring & !cube(&[[0, 1, 0]])));
        assert!(!is_simple(ring & !cube(&[[0, 1, 1]])));
        // The centre of a solid pierced by a background line through it: the
        // two background faces are not
        // 6-connected in N18, removing the centre would join them (a tunnel).
        assert!(!is_simple(cube_where(|d| !(d[0] == 0 && d[1] == 0))));
        // The same with a background bridge in N18 joining them: simple.
        assert!(is_simple(cube_where(|d| {
            !(d[1] == 0 && (d[0] == 0 || d[0] == 1))
        })));
    }

    /// 26-connected components of the cells of `m` (shape `s`).
    fn components_26(m: &[bool], s: [usize; 3]) -> usize {
        let mut seen = vec![false; m.len()];
        let mut count = 0;
        for start in 0..m.len() {
            if !m[start] || seen[start] {
                continue;
            }
            count += 1;
            seen[start] = true;
            let mut stack = vec![start];
            while let Some(c) = stack.pop() {
                let p = [c / (s[1] * s[2]), (c / s[2]) % s[1], c % s[2]];
                for q in 0..27 {
                    let d = cube_pos(q);
                    let n: Option<Vec<usize>> = (0..3)
                        .map(|a| p[a].checked_add_signed(d[a]).filter(|&v| v < s[a]))
                        .collect();
                    if let Some(n) = n {
                        let n = (n[0] * s[1] + n[1]) * s[2] + n[2];
                        if m[n] && !seen[n] {
                            seen[n] = true;
                            stack.push(n);
                        }
                    }
                }
            }
        }
        count
    }

    fn solid(s: [usize; 3], inside: impl Fn(f64, f64, f64) -> bool) -> Vec<bool> {
        (0..s[0] * s[1] * s[2])
            .map(|c| {
                let (i, j, k) = (c / (s[1] * s[2]), (c / s[2]) % s[1], c % s[2]);
                inside(i as f64, j as f64, k as f64)
            })
            .collect()
    }

    #[test]
    fn three_d_cylinder_thins_to_its_axis() {
        // Cylinder of radius 6.5 around (j, k) = (10, 10), i in 2..=33.
        let s = [36usize, 21, 21];
        let mask = solid(s, |i, j, k| {
            (2.0..=33.0).contains(&i) && (j - 10.0).powi(2) + (k - 10.0).powi(2) <= 6.5 * 6.5
        });
        let grid = Grid::unit(&s).unwrap();
        let opts = SkeletonOptions::default();
        let raw = medial_axis_with(&grid, &mask, &opts, &Control::new(), false).unwrap();
        let sk = medial_axis(&grid, &mask, &opts, &Control::new()).unwrap();
        let m = &sk.mask;
        let cells: Vec<[usize; 3]> = (0..m.len())
            .filter(|&c| m[c])
            .map(|c| grid.unravel(c))
            .collect();
        let n_raw = raw.mask.iter().filter(|&&v| v).count();
        assert!(
            cells.len() * 4 < n_raw,
            "{} cells of {n_raw} medial cells",
            cells.len()
        );
        assert_eq!(components_26(m, s), 1);
        for p in &cells {
            let off = ((p[1] as f64 - 10.0).powi(2) + (p[2] as f64 - 10.0).powi(2)).sqrt();
            assert!(off <= 1.5, "{p:?} is {off} from the axis");
            assert!(mask[grid.linear(*p)]);
        }
        // A contiguous line: every section from i = 9 to 26 (the axis is
        // the medial axis between 6.5 + 0.5 cells from each cap) holds
        // one or two cells, with the radius function about 7.
        for i in 9..=26 {
            let section: Vec<&[usize; 3]> = cells.iter().filter(|p| p[0] == i).collect();
            assert!((1..=2).contains(&section.len()), "section {i}: {section:?}");
            for p in section {
                let r = sk.radius[grid.linear(*p)];
                assert!((6.0..=7.5).contains(&r), "radius {r} at {p:?}");
            }
        }
        assert!(sk.radius.iter().zip(m).all(|(&r, &k)| (r > 0.0) == k));
    }

    #[test]
    fn three_d_box_thins_and_keeps_topology() {
        // Box of 24 x 18 x 9 cells in a 28 x 22 x 13 grid.
        let s = [28usize, 22, 13];
        let (lo, hi) = ([2.0, 2.0, 2.0], [25.0, 19.0, 10.0]);
        let mask = solid(s, |i, j, k| {
            [i, j, k]
                .iter()
                .enumerate()
                .all(|(a, &v)| (lo[a]..=hi[a]).contains(&v))
        });
        let grid = Grid::unit(&s).unwrap();
        let opts = SkeletonOptions::default();
        let raw = medial_axis_with(&grid, &mask, &opts, &Control::new(), false).unwrap();
        let sk = medial_axis(&grid, &mask, &opts, &Control::new()).unwrap();
        let m = &sk.mask;
        let n = m.iter().filter(|&&v| v).count();
        let n_raw = raw.mask.iter().filter(|&&v| v).count();
        assert!(n > 0 && n * 4 < n_raw, "{n} cells of {n_raw} medial cells");
        assert_eq!(components_26(m, s), 1);
        // Thin: no 2 x 2 block of skeleton cells in any plane.
        for c in 0..m.len() {
            let p = grid.unravel(c);
            if p.iter().zip(&s).any(|(&v, &n)| v + 1 >= n) {
                continue;
            }
            for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                let mut q = p;
                let mut all = true;
                for (da, db) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    q[a] = p[a] + da;
                    q[b] = p[b] + db;
                    all &= m[grid.linear(q)];
                }
                assert!(!all, "2 x 2 block at {p:?} in axes ({a}, {b})");
            }
        }
        // The deepest cells of the box form the sheet k = 6 (between the
        // outside cells at k = 1 and 11), i in 7..=20, j in 7..=14; the
        // skeleton is a curve along the sheet's long axis j = 10.5: every
        // cell within one cell of it, one or two cells per section, and the
        // sections contiguous over the middle of the box.
        let cells: Vec<[usize; 3]> = (0..m.len())
            .filter(|&c| m[c])
            .map(|c| grid.unravel(c))
            .collect();
        for p in &cells {
            assert!(
                (p[1] as f64 - 10.5).abs() <= 1.0 && p[2] == 6,
                "{p:?} is off the axis"
            );
        }
        let lo_i = cells.iter().map(|p| p[0]).min().unwrap();
        let hi_i = cells.iter().map(|p| p[0]).max().unwrap();
        assert!(lo_i <= 12 && hi_i >= 15, "from {lo_i} to {hi_i}");
        for i in lo_i..=hi_i {
            let k = cells.iter().filter(|p| p[0] == i).count();
            assert!((1..=2).contains(&k), "section {i}: {k} cells");
        }
    }

    #[test]
    fn three_d_torus_keeps_its_tunnel() {
        // Torus of radii 9 and 3.5 around the axis 0 through (16, 16).
        let s = [12usize, 33, 33];
        let mask = solid(s, |i, j, k| {
            let rho = ((j - 16.0).powi(2) + (k - 16.0).powi(2)).sqrt();
            (rho - 9.0).powi(2) + (i - 6.0).powi(2) <= 3.5 * 3.5
        });
        let grid = Grid::unit(&s).unwrap();
        let sk = medial_axis(&grid, &mask, &SkeletonOptions::default(), &Control::new()).unwrap();
        let m = &sk.mask;
        assert_eq!(components_26(m, s), 1);
        // A closed curve around the hole: cells in each of the 8 octants of
        // angle, all within 1.5 cells of the core circle.
        let mut octants = [0usize; 8];
        for c in (0..m.len()).filter(|&c| m[c]) {
            let p = grid.unravel(c);
            let (y, z) = (p[1] as f64 - 16.0, p[2] as f64 - 16.0);
            let off = ((y.hypot(z) - 9.0).powi(2) + (p[0] as f64 - 6.0).powi(2)).sqrt();
            assert!(off <= 1.5, "{p:?} is {off} from the core circle");
            let oct = ((z.atan2(y) + std::f64::consts::PI) / (std::f64::consts::PI / 4.0)) as usize;
            octants[oct.min(7)] += 1;
        }
        assert!(octants.iter().all(|&k| k > 0), "{octants:?}");
        // Thin: a one-cell-thin digital circle of radius 9 has about 50
        // cells (the tube holds about 2200).
        let cells = m.iter().filter(|&&v| v).count();
        assert!(cells < 80, "{cells} cells");
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
