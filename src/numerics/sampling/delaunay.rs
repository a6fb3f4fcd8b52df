//! Geodesic Voronoi adjacency, Voronoi vertices and the geodesic Delaunay
//! triangulation of a 2D grid sampling (the monograph's section 4.1), with
//! the repair of its failure modes.
//!
//! # Math
//!
//! The geodesic Voronoi cell of sample `s_i` is `V_i = {x : d_W(x, s_i) ≤
//! d_W(x, s_j) ∀ j}`; on the grid it is the set of cells with label `i`.
//! Two cells are *adjacent* when two 4-neighbouring grid cells carry their
//! labels; a *Voronoi vertex* is a 2×2 block of grid cells carrying three
//! distinct labels, placed at the block's centre. The geodesic Delaunay
//! triangulation is the dual: one triangle `(i, j, k)` per Voronoi vertex,
//! oriented counter-clockwise in the (axis 0, axis 1) plane from the sample
//! positions. A block with four labels (four cells meeting at a point:
//! cocircular samples) gives the two triangles of the diagonal whose cells
//! touch elsewhere, or else the diagonal that passes the in-circle test on
//! the physical positions (the Euclidean Delaunay choice). For a constant
//! metric and well-spread samples the dual is the Euclidean Delaunay
//! triangulation, minus the triangles whose circumcentre (their Voronoi
//! vertex) lies outside the grid (`tests` compare it with `spade`).
//!
//! # Failure modes and their repair
//!
//! The dual is a valid triangulation only when the sampling is dense enough
//! for the metric (Leibon and Letscher's conditions). Each round detects
//! * two cells touching in two places or more (their common boundary has
//!   several connected components: a pair of Voronoi edges where the dual
//!   has one edge);
//! * a cell in several pieces (possible around obstacles);
//! * an adjacency in no triangle (a Voronoi edge that crosses the domain
//!   from boundary to boundary: low density) and a sample in no triangle;
//! * every defect of [`triangulation::check_planar`] (degenerate, overlapping
//!   or non-manifold triangles);
//! * with [`DelaunayOptions::conforming`]: a grid corner that is not a
//!   sample, and a cell that touches the grid's border while its sample does
//!   not (there the dual leaves the domain uncovered: the missing triangles
//!   near the boundary);
//!
//! and adds, for each, the farthest point (largest `U`) of the offending
//! region (the union of the cells involved; for a cell off the border, its
//! part of the border) with the same local front as farthest-point
//! sampling, at most one new sample per cell and round. The rounds stop
//! when no defect remains (the count added is reported) or fail after
//! [`DelaunayOptions::max_added`] samples.
//!
//! # Reuse
//!
//! The dual itself ([`voronoi_dual`]) only needs labels on a 2D grid; the
//! checker only points and triangles. Domain meshing needs a mask (cells
//! outside are walls: unreached, label `-1`, so no Voronoi vertex forms
//! there) plus the conforming rule on the mask's border; surface remeshing
//! needs the same dual over a mesh's faces (three labels on a face) and a
//! manifold check instead of the planar overlap test.

use std::collections::{BTreeMap, HashMap, HashSet};

use super::farthest::{Front, GridSampling, Sampler, SamplingError, SamplingStop};
use super::tensor_farthest::TensorSampler;
use super::triangulation::{self, check_planar, Defect};
use crate::numerics::anisotropic::TensorField;
use crate::numerics::control::Control;
use crate::numerics::grid::Grid;
use crate::numerics::metric::IsotropicCost;

/// Options of [`geodesic_delaunay`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DelaunayOptions {
    /// Make the triangulation cover the grid: corners become samples and a
    /// cell touching the border gets a sample on the border.
    pub conforming: bool,
    /// Most samples the repair may add. Default: none (the number of cells).
    pub max_added: Option<usize>,
}

impl Default for DelaunayOptions {
    fn default() -> Self {
        Self {
            conforming: true,
            max_added: None,
        }
    }
}

/// A Voronoi vertex: where three cells meet.
#[derive(Debug, Clone, PartialEq)]
pub struct VoronoiVertex {
    /// The three labels, increasing.
    pub cells: [u32; 3],
    /// Position in index coordinates (axis 0 first): the mean of the centres
    /// of the 2×2 blocks that carry these three labels.
    pub position: [f64; 2],
}

/// The dual of a labelling: adjacency, Voronoi vertices and triangles.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VoronoiDual {
    /// Adjacent cells `[i, j]`, `i < j`, sorted.
    pub adjacency: Vec<[u32; 2]>,
    /// Connected pieces of the common boundary of each adjacent pair (same order).
    pub contacts: Vec<u32>,
    /// The Voronoi vertices, sorted by labels.
    pub vertices: Vec<VoronoiVertex>,
    /// The dual triangles, counter-clockwise in the (axis 0, axis 1) plane,
    /// sorted; collinear triples are kept (the checker reports them).
    pub triangles: Vec<[u32; 3]>,
}

/// A geodesic Delaunay triangulation.
#[derive(Debug, Clone, PartialEq)]
pub struct GeodesicDelaunay {
    /// The sampling, with the samples added by the repair at the end.
    pub sampling: GridSampling,
    /// The samples as points in index coordinates (axis 0 first).
    pub points: Vec<[f64; 2]>,
    /// The dual of the final labels.
    pub dual: VoronoiDual,
    /// Samples added by the repair.
    pub added: usize,
    /// Repair rounds run (1 when the first dual was valid).
    pub rounds: usize,
    /// Defects found over all rounds, by kind.
    pub repaired: RepairCounts,
}

/// Defects found and repaired, by kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RepairCounts {
    /// Cells touching in two places or more.
    pub double_contact: usize,
    /// Cells in several pieces.
    pub split_cell: usize,
    /// Adjacencies or samples in no triangle.
    pub missing_triangle: usize,
    /// Defects of the checker (degenerate, overlapping, non-manifold).
    pub invalid: usize,
    /// Corners and border cells without a sample on the border.
    pub boundary: usize,
}

/// Why no valid triangulation was produced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DelaunayError {
    /// The grid is not 2D.
    #[error("geodesic Delaunay is defined on 2D grids; this grid has {0} axes")]
    NotPlanar(usize),
    /// The labels or distances do not match the grid.
    #[error("the sampling has {got} cells, the grid {expected}")]
    Size {
        /// Cells of the grid.
        expected: usize,
        /// Cells of the sampling.
        got: usize,
    },
    /// The repair reached its limit with defects left.
    #[error(
        "{defects} defects left after adding {added} samples (the limit); sample more densely"
    )]
    Unrepaired {
        /// Samples added.
        added: usize,
        /// Defects left.
        defects: usize,
    },
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

impl From<SamplingError> for DelaunayError {
    fn from(e: SamplingError) -> Self {
        match e {
            SamplingError::Cancelled => DelaunayError::Cancelled,
            // The repair only adds open, unsampled cells: nothing else can fail.
            _ => DelaunayError::Unrepaired {
                added: 0,
                defects: 1,
            },
        }
    }
}

/// The dual of the labels of a 2D grid (`labels` in C order, `-1` for
/// unreached cells); `points` are the samples (index coordinates), used to
/// orient the triangles and break four-cell ties, `spacing` the grid's.
pub fn voronoi_dual(
    shape: [usize; 2],
    spacing: [f64; 2],
    labels: &[i32],
    points: &[[f64; 2]],
) -> VoronoiDual {
    let [n0, n1] = shape;
    let at = |r: usize, c: usize| labels[r * n1 + c];
    // Boundary pixel edges per adjacent pair, as the two lattice corners
    // (on the (n0+1)×(n1+1) lattice) they join.
    let corner = |r: usize, c: usize| (r * (n1 + 1) + c) as u64;
    let mut edges: BTreeMap<(u32, u32), Vec<(u64, u64)>> = BTreeMap::new();
    let mut pair = |a: i32, b: i32, e: (u64, u64)| {
        if a >= 0 && b >= 0 && a != b {
            let (a, b) = (a.min(b) as u32, a.max(b) as u32);
            edges.entry((a, b)).or_default().push(e);
        }
    };
    for r in 0..n0 {
        for c in 0..n1 {
            if c + 1 < n1 {
                pair(
                    at(r, c),
                    at(r, c + 1),
                    (corner(r, c + 1), corner(r + 1, c + 1)),
                );
            }
            if r + 1 < n0 {
                pair(
                    at(r, c),
                    at(r + 1, c),
                    (corner(r + 1, c), corner(r + 1, c + 1)),
                );
            }
        }
    }
    let mut adjacency = Vec::with_capacity(edges.len());
    let mut contacts = Vec::with_capacity(edges.len());
    for (&(a, b), list) in &edges {
        adjacency.push([a, b]);
        contacts.push(components(list));
    }
    let adjacent: HashSet<(u32, u32)> = edges.keys().copied().collect();
    let touch = |a: u32, b: u32| adjacent.contains(&(a.min(b), a.max(b)));

    // Voronoi vertices from the 2×2 blocks.
    let phys = |v: u32| {
        let p = points[v as usize];
        [p[0] * spacing[0], p[1] * spacing[1]]
    };
    let mut blocks: BTreeMap<[u32; 3], ([f64; 2], usize)> = BTreeMap::new();
    let mut add = |cells: [u32; 3], centre: [f64; 2]| {
        let mut key = cells;
        key.sort_unstable();
        let e = blocks.entry(key).or_insert(([0.0; 2], 0));
        e.0[0] += centre[0];
        e.0[1] += centre[1];
        e.1 += 1;
    };
    for r in 0..n0.saturating_sub(1) {
        for c in 0..n1.saturating_sub(1) {
            // Around the block: a (r, c), b (r, c+1), d (r+1, c+1), e (r+1, c).
            let ring = [at(r, c), at(r, c + 1), at(r + 1, c + 1), at(r + 1, c)];
            if ring.iter().any(|&l| l < 0) {
                continue;
            }
            let centre = [r as f64 + 0.5, c as f64 + 0.5];
            let mut distinct: Vec<u32> = ring.iter().map(|&l| l as u32).collect();
            distinct.sort_unstable();
            distinct.dedup();
            match distinct.len() {
                3 => add([distinct[0], distinct[1], distinct[2]], centre),
                4 => {
                    let [a, b, d, e] = ring.map(|l| l as u32);
                    let ad = touch(a, d);
                    let be = touch(b, e);
                    let use_ad = if ad != be {
                        ad
                    } else {
                        // In-circle: e inside the circle of (a, b, d) -> diagonal b-e.
                        !in_circle(phys(a), phys(b), phys(d), phys(e))
                    };
                    if use_ad {
                        add([a, b, d], centre);
                        add([a, d, e], centre);
                    } else {
                        add([a, b, e], centre);
                        add([b, d, e], centre);
                    }
                }
                _ => {}
            }
        }
    }
    let mut vertices = Vec::with_capacity(blocks.len());
    let mut triangles = Vec::with_capacity(blocks.len());
    for (cells, (sum, count)) in blocks {
        vertices.push(VoronoiVertex {
            cells,
            position: [sum[0] / count as f64, sum[1] / count as f64],
        });
        let [a, b, c] = cells;
        let o = triangulation::orient(phys(a), phys(b), phys(c));
        triangles.push(if o < 0.0 { [a, c, b] } else { [a, b, c] });
    }
    triangles.sort_unstable();
    VoronoiDual {
        adjacency,
        contacts,
        vertices,
        triangles,
    }
}

/// Whether `p` is strictly inside the circumcircle of `(a, b, c)` (any orientation).
fn in_circle(a: [f64; 2], b: [f64; 2], c: [f64; 2], p: [f64; 2]) -> bool {
    let row = |q: [f64; 2]| {
        let (x, y) = (q[0] - p[0], q[1] - p[1]);
        [x, y, x * x + y * y]
    };
    let (r0, r1, r2) = (row(a), row(b), row(c));
    let det = r0[0] * (r1[1] * r2[2] - r1[2] * r2[1]) - r0[1] * (r1[0] * r2[2] - r1[2] * r2[0])
        + r0[2] * (r1[0] * r2[1] - r1[1] * r2[0]);
    det * triangulation::orient(a, b, c) > 0.0
}

/// Connected pieces of a set of lattice segments (joined at shared corners).
fn components(segments: &[(u64, u64)]) -> u32 {
    let mut id: HashMap<u64, usize> = HashMap::with_capacity(2 * segments.len());
    let mut parent: Vec<usize> = Vec::with_capacity(2 * segments.len());
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut slot = |c: u64, parent: &mut Vec<usize>| {
        *id.entry(c).or_insert_with(|| {
            parent.push(parent.len());
            parent.len() - 1
        })
    };
    for &(p, q) in segments {
        let (i, j) = (slot(p, &mut parent), slot(q, &mut parent));
        let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
        if ri != rj {
            parent[ri] = rj;
        }
    }
    (0..parent.len())
        .filter(|&x| find(&mut parent, x) == x)
        .count() as u32
}

/// The geodesic Delaunay triangulation of `sampling` (a farthest-point
/// sampling of `grid` under `cost`, or any labelling with its distance map),
/// repaired until it is a valid triangulation; see the module docs.
///
/// Polls `control` once per round and per added sample's front.
///
/// # Examples
/// ```
/// use geodex::numerics::sampling::{farthest_point_sampling, SamplingOptions};
/// use geodex::numerics::sampling::delaunay::{geodesic_delaunay, DelaunayOptions};
/// use geodex::numerics::sampling::triangulation::check_planar;
/// use geodex::numerics::{Control, Grid, IsotropicCost};
/// let grid = Grid::unit(&[40, 40])?;
/// let cost = IsotropicCost::constant(1.0)?;
/// let options = SamplingOptions { count: Some(30), ..Default::default() };
/// let s = farthest_point_sampling(&grid, &cost, &options, &Control::new())?;
/// let d = geodesic_delaunay(&grid, &cost, s, &DelaunayOptions::default(), &Control::new())?;
/// assert!(check_planar(&d.points, &d.dual.triangles).is_empty());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn geodesic_delaunay(
    grid: &Grid,
    cost: &IsotropicCost<'_>,
    sampling: GridSampling,
    options: &DelaunayOptions,
    control: &Control<'_>,
) -> Result<GeodesicDelaunay, DelaunayError> {
    let (cells, distance, labels, radii, visited) = unpack(grid, sampling)?;
    let sampler = Sampler::resume(grid, cost, distance, labels);
    repair(grid, sampler, cells, radii, visited, options, control)
}

/// [`geodesic_delaunay`] for a sampling under a Riemannian metric (a
/// [`tensor_farthest_point_sampling`](super::tensor_farthest_point_sampling)
/// of `grid` under `metric`): the same dual and the same repairs, each
/// added sample's front run with the metric's adaptive stencils. The dual
/// is oriented and checked on the samples' positions in the plane of the
/// grid, so a repaired result is a valid planar triangulation whatever the
/// metric.
///
/// # Examples
/// ```
/// use geodex::numerics::anisotropic::TensorField;
/// use geodex::numerics::sampling::{tensor_farthest_point_sampling, SamplingOptions};
/// use geodex::numerics::sampling::delaunay::{geodesic_delaunay_tensor, DelaunayOptions};
/// use geodex::numerics::sampling::triangulation::check_planar;
/// use geodex::numerics::{Control, Grid};
/// let grid = Grid::unit(&[40, 40])?;
/// let metric = TensorField::from_eigen(&grid, &[1.0, 4.0], &[1.0, 0.0])?;
/// let options = SamplingOptions { count: Some(30), ..Default::default() };
/// let s = tensor_farthest_point_sampling(&grid, &metric, &options, &Control::new())?;
/// let d = geodesic_delaunay_tensor(&grid, &metric, s, &DelaunayOptions::default(), &Control::new())?;
/// assert!(check_planar(&d.points, &d.dual.triangles).is_empty());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn geodesic_delaunay_tensor(
    grid: &Grid,
    metric: &TensorField,
    sampling: GridSampling,
    options: &DelaunayOptions,
    control: &Control<'_>,
) -> Result<GeodesicDelaunay, DelaunayError> {
    let (cells, distance, labels, radii, visited) = unpack(grid, sampling)?;
    let sampler = TensorSampler::resume(grid, metric, distance, labels, control)?;
    repair(grid, sampler, cells, radii, visited, options, control)
}

/// What the repair needs of a 2D sampling: the sample cells (flat), the
/// distance, labels, radii and visit count, after checking the sizes.
#[allow(clippy::type_complexity)]
fn unpack(
    grid: &Grid,
    sampling: GridSampling,
) -> Result<(Vec<usize>, Vec<f64>, Vec<i32>, Vec<f64>, usize), DelaunayError> {
    if grid.ndim() != 2 {
        return Err(DelaunayError::NotPlanar(grid.ndim()));
    }
    let n = grid.len();
    if sampling.labels.len() != n || sampling.distance.len() != n {
        return Err(DelaunayError::Size {
            expected: n,
            got: sampling.labels.len(),
        });
    }
    let n1 = grid.shape3()[2];
    let GridSampling {
        samples,
        distance,
        labels,
        radii,
        visited,
        ..
    } = sampling;
    let cells: Vec<usize> = samples.iter().map(|p| p[0] * n1 + p[1]).collect();
    Ok((cells, distance, labels, radii, visited))
}

/// The repair rounds of [`geodesic_delaunay`] over any local-front sampler.
fn repair<F: Front>(
    grid: &Grid,
    mut sampler: F,
    mut cells: Vec<usize>,
    mut radii: Vec<f64>,
    visited: usize,
    options: &DelaunayOptions,
    control: &Control<'_>,
) -> Result<GeodesicDelaunay, DelaunayError> {
    let n = grid.len();
    let [_, n0, n1] = grid.shape3();
    let sp = grid.spacing3();
    let spacing = [sp[1], sp[2]];
    let max_added = options.max_added.unwrap_or(n);
    let mut repaired = RepairCounts::default();
    let mut added = 0;
    let mut rounds = 0;
    loop {
        rounds += 1;
        if control.is_cancelled() {
            return Err(DelaunayError::Cancelled);
        }
        let points: Vec<[f64; 2]> = cells
            .iter()
            .map(|&i| [(i / n1) as f64, (i % n1) as f64])
            .collect();
        let dual = voronoi_dual([n0, n1], spacing, sampler.labels(), &points);
        let regions = defects(
            &dual,
            [n0, n1],
            sampler.labels(),
            &cells,
            &points,
            options,
            &mut repaired,
        );
        if regions.is_empty() {
            let (distance, labels, front) = sampler.into_parts();
            let covering_radius = radii.last().copied().unwrap_or(0.0);
            let sampling = GridSampling {
                samples: cells.iter().map(|&i| vec![i / n1, i % n1]).collect(),
                distance,
                labels,
                radii,
                covering_radius,
                stop: SamplingStop::Count,
                visited: visited + front,
                clustered: None,
            };
            return Ok(GeodesicDelaunay {
                sampling,
                points,
                dual,
                added,
                rounds,
                repaired,
            });
        }
        // One new sample per offending region, at most one per cell and round.
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); cells.len()];
        for (i, &l) in sampler.labels().iter().enumerate() {
            if l >= 0 {
                members[l as usize].push(i);
            }
        }
        let mut used: HashSet<u32> = HashSet::new();
        let before = added;
        for region in &regions {
            if region.cells.iter().any(|c| used.contains(c)) {
                continue;
            }
            let u = sampler.distance();
            let on_border = |i: usize| {
                let (r, c) = (i / n1, i % n1);
                r == 0 || c == 0 || r + 1 == n0 || c + 1 == n1
            };
            let best = match region.target {
                Target::Cell(i) => Some(i).filter(|&i| u[i] > 0.0),
                Target::Farthest { border } => region
                    .cells
                    .iter()
                    .flat_map(|&c| members[c as usize].iter().copied())
                    .filter(|&i| u[i] > 0.0 && u[i] < f64::INFINITY && (!border || on_border(i)))
                    .max_by(|&a, &b| u[a].total_cmp(&u[b]).then(b.cmp(&a))),
                Target::Pieces(ref pieces) => pieces
                    .iter()
                    .copied()
                    .filter(|&i| u[i] > 0.0)
                    .max_by(|&a, &b| u[a].total_cmp(&u[b]).then(b.cmp(&a))),
            };
            let Some(best) = best else { continue };
            if added >= max_added {
                return Err(DelaunayError::Unrepaired {
                    added,
                    defects: regions.len(),
                });
            }
            used.extend(region.cells.iter().copied());
            sampler.add(best, cells.len() as i32, control)?;
            cells.push(best);
            radii.push(sampler.covering_radius());
            added += 1;
        }
        if added == before {
            return Err(DelaunayError::Unrepaired {
                added,
                defects: regions.len(),
            });
        }
    }
}

/// Where a repair sample goes.
#[derive(Debug, Clone)]
enum Target {
    /// The farthest cell of the region (on the grid's border only, if `border`).
    Farthest {
        /// Restrict to the border.
        border: bool,
    },
    /// This cell (a corner).
    Cell(usize),
    /// The farthest of these cells (the smaller pieces of a split cell).
    Pieces(Vec<usize>),
}

/// An offending region: the labels involved and where its sample goes.
#[derive(Debug, Clone)]
struct Region {
    cells: Vec<u32>,
    target: Target,
}

/// Every defect of the dual, as regions to repair (empty: valid).
fn defects(
    dual: &VoronoiDual,
    shape: [usize; 2],
    labels: &[i32],
    cells: &[usize],
    points: &[[f64; 2]],
    options: &DelaunayOptions,
    counts: &mut RepairCounts,
) -> Vec<Region> {
    let [n0, n1] = shape;
    let far = |cells: Vec<u32>| Region {
        cells,
        target: Target::Farthest { border: false },
    };
    let mut out: Vec<Region> = Vec::new();
    // Cells touching in two places.
    for (pair, &k) in dual.adjacency.iter().zip(&dual.contacts) {
        if k > 1 {
            counts.double_contact += 1;
            out.push(far(pair.to_vec()));
        }
    }
    // Cells in several pieces.
    for (label, pieces) in split_cells(shape, labels, cells) {
        counts.split_cell += 1;
        out.push(Region {
            cells: vec![label],
            target: Target::Pieces(pieces),
        });
    }
    // Adjacencies and samples in no triangle.
    let mut in_triangle: HashSet<(u32, u32)> = HashSet::new();
    let mut covered = vec![false; cells.len()];
    for t in &dual.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            in_triangle.insert((a.min(b), a.max(b)));
            covered[a as usize] = true;
        }
    }
    for pair in &dual.adjacency {
        if !in_triangle.contains(&(pair[0], pair[1])) {
            counts.missing_triangle += 1;
            out.push(far(pair.to_vec()));
        }
    }
    for (v, _) in covered.iter().enumerate().filter(|(_, &c)| !c) {
        counts.missing_triangle += 1;
        out.push(far(vec![v as u32]));
    }
    // The checker's defects.
    for d in check_planar(points, &dual.triangles) {
        counts.invalid += 1;
        let involved: Vec<u32> = match d {
            Defect::Degenerate { triangle }
            | Defect::Flipped { triangle }
            | Defect::BadIndex { triangle } => dual.triangles[triangle].to_vec(),
            Defect::NonManifoldEdge { edge } => edge.to_vec(),
            Defect::NonManifoldVertex { vertex } => vec![vertex],
            Defect::Overlap { triangles } => {
                let mut v: Vec<u32> = triangles.iter().flat_map(|&t| dual.triangles[t]).collect();
                v.sort_unstable();
                v.dedup();
                v
            }
        };
        out.push(far(involved));
    }
    if options.conforming {
        let sampled: HashSet<usize> = cells.iter().copied().collect();
        for corner in [0, n1 - 1, (n0 - 1) * n1, n0 * n1 - 1] {
            if labels[corner] >= 0 && !sampled.contains(&corner) {
                counts.boundary += 1;
                out.push(Region {
                    cells: vec![labels[corner] as u32],
                    target: Target::Cell(corner),
                });
            }
        }
        let on_border = |i: usize| {
            let (r, c) = (i / n1, i % n1);
            r == 0 || c == 0 || r + 1 == n0 || c + 1 == n1
        };
        let mut touching: Vec<bool> = vec![false; cells.len()];
        for r in 0..n0 {
            for c in 0..n1 {
                let i = r * n1 + c;
                if on_border(i) && labels[i] >= 0 {
                    touching[labels[i] as usize] = true;
                }
            }
        }
        for (v, &cell) in cells.iter().enumerate() {
            if touching[v] && !on_border(cell) {
                counts.boundary += 1;
                out.push(Region {
                    cells: vec![v as u32],
                    target: Target::Farthest { border: true },
                });
            }
        }
    }
    out
}

/// Labels whose cells are in several 4-connected pieces, with the grid
/// cells of every piece but the one holding the sample (`cells[label]`).
///
/// The sample's own piece stays even when it is the smallest: where the
/// metric varies fast, the sample's grid cell can be cut off from the rest
/// of its Voronoi cell, and the repair sample then goes to the farthest
/// cell of that rest (a piece of the sample's cell alone has no cell with
/// `U > 0` to take it).
fn split_cells(shape: [usize; 2], labels: &[i32], cells: &[usize]) -> Vec<(u32, Vec<usize>)> {
    let [n0, n1] = shape;
    let count = cells.len();
    let mut piece = vec![u32::MAX; labels.len()];
    let mut pieces_of: Vec<Vec<Vec<usize>>> = vec![Vec::new(); count];
    let mut stack = Vec::new();
    for start in 0..labels.len() {
        let l = labels[start];
        if l < 0 || piece[start] != u32::MAX {
            continue;
        }
        let id = pieces_of[l as usize].len() as u32;
        let mut members = Vec::new();
        piece[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            members.push(i);
            let (r, c) = (i / n1, i % n1);
            let mut visit = |j: usize| {
                if labels[j] == l && piece[j] == u32::MAX {
                    piece[j] = id;
                    stack.push(j);
                }
            };
            if r > 0 {
                visit(i - n1);
            }
            if r + 1 < n0 {
                visit(i + n1);
            }
            if c > 0 {
                visit(i - 1);
            }
            if c + 1 < n1 {
                visit(i + 1);
            }
        }
        pieces_of[l as usize].push(members);
    }
    let mut out = Vec::new();
    for (l, mut pieces) in pieces_of.into_iter().enumerate() {
        if pieces.len() > 1 {
            let own = pieces.iter().position(|p| p.contains(&cells[l]));
            let keep = own.unwrap_or_else(|| {
                (0..pieces.len())
                    .max_by_key(|&k| (pieces[k].len(), std::cmp::Reverse(k)))
                    .unwrap_or(0)
            });
            pieces.swap_remove(keep);
            out.push((l as u32, pieces.into_iter().flatten().collect()));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::split_cells;

    /// A sample cut off from the rest of its Voronoi cell keeps its own
    /// piece, even the smallest, so that the repair targets the rest (cells
    /// with `U > 0`), not the sample itself.
    #[test]
    fn a_split_cell_keeps_the_piece_holding_its_sample() {
        // 3 x 5 grid; label 0 holds the sample at cell 0 alone and the
        // block of columns 2-4; label 1 fills column 1 between them.
        #[rustfmt::skip]
        let labels = [
            0, 1, 0, 0, 0,
            1, 1, 0, 0, 0,
            1, 1, 0, 0, 0,
        ];
        let cells = [0, 6];
        let split = split_cells([3, 5], &labels, &cells);
        assert_eq!(split.len(), 1);
        let (label, mut pieces) = split[0].clone();
        pieces.sort_unstable();
        assert_eq!(label, 0);
        assert_eq!(pieces, vec![2, 3, 4, 7, 8, 9, 12, 13, 14]);
        // With the sample in the larger piece, the single cell is the rest.
        let split = split_cells([3, 5], &labels, &[3, 6]);
        assert_eq!(split, vec![(0, vec![0])]);
        // A cell in one piece is not split.
        assert!(split_cells([3, 5], &[0; 15], &[7]).is_empty());
    }
}
