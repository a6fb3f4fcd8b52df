//! Domain meshing (the monograph's section 4.5): a planar domain, given as
//! polygons with holes or as a mask, becomes a triangle mesh whose vertices
//! follow a size field and whose boundary edges lie on the boundary.
//!
//! # Method
//!
//! The size field is `h(x) = h₀ · s(x)`: `s = 1` for a uniform mesh, or
//! `s = 1/W` for an isotropic metric `W`, so that neighbouring vertices sit
//! at about the same *geodesic* distance `h₀` (a constant metric gives
//! Euclidean spacing `h₀`). `h₀` is the requested edge length, or is found
//! from a vertex count: a mesh of near-equilateral triangles of side `h`
//! has about `2A / (√3 h²)` vertices on an area `A`, so
//! `h₀ = (2 ∫ s⁻² dA / (√3 N))^{1/2}`, then corrected from the count the
//! first mesh reaches (`h₀ ← h₀ · (N_got / N)^{1/2}`).
//!
//! 1. **Boundary first.** Every ring keeps its vertices (so every boundary
//!    edge lies on an input edge), and each input edge of geodesic length
//!    `L = ∫ ds / h` is cut into `max(1, round(L))` pieces of equal geodesic
//!    length.
//! 2. **Constrained Delaunay** of those points with the ring edges as
//!    constraints (`spade`, exact predicates). A face is inside when it is
//!    reached from the outer face across an odd number of constraints
//!    (even-odd rule: holes need no orientation).
//! 3. **Inside.** With a uniform size, the hexagonal lattice of side `h₀`
//!    (each vertex at distance `h₀` from six others, the optimal packing),
//!    kept where it is inside (even-odd count of the boundary crossings of
//!    its row) and at least `h₀/2` from the boundary. Then,
//!    and alone under a metric, passes of Chew-style insertion: each inside triangle whose
//!    circumradius `R` exceeds `β h` (`β = 0.7`; an equilateral triangle of
//!    side `h` has `R = h/√3 ≈ 0.58 h`) proposes its circumcenter, unless
//!    it lies outside the domain, inside the diametral circle of a boundary
//!    edge, or within `h/2` of a point accepted in the same pass.
//! 4. **Relaxation.** Optimal Delaunay triangulation smoothing (Chen and
//!    Xu): each inner vertex moves to the density-weighted mean of the
//!    circumcenters of its triangles, `x ← Σ_T ρ_T |T| c_T / Σ_T ρ_T |T|`
//!    with `ρ = h⁻²`, which minimises the interpolation error of `|x|²`
//!    (the centroidal Voronoi energy's Delaunay counterpart). Many moves
//!    rebuild the triangulation, a few (the band along the boundary) remove
//!    and reinsert their vertices; a lattice vertex amid lattice vertices is
//!    its own target and is not looked at. A move that would leave the
//!    domain is not made.
//! 5. **Quality.** Ruppert's Delaunay refinement (`spade`'s `refine`) to
//!    the angle bound (25° by default): triangles with a smaller angle get
//!    their circumcenter inserted, boundary edges they encroach are split
//!    at their midpoint (which stays on the boundary). The vertices it adds
//!    are counted in [`DomainMesh::refined`]. It is not run when it would
//!    change nothing: no inside triangle below the bound and no boundary
//!    edge encroached (checked first, with a margin; the usual case after
//!    relaxation).
//!
//! Angles below the bound remain only at input corners sharper than it
//! (no refinement can open them).
//!
//! The caller's cancel flag is polled once per pass, sweep and lattice
//! row and every 4,096 insertions or moves; the bulk loads of the
//! triangulation and `spade`'s refinement run to their end (about a second
//! per million vertices).

use std::collections::HashMap;

use spade::handles::{FixedVertexHandle, InnerTag};
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, PositionInTriangulation,
    RefinementParameters, Triangulation,
};

use crate::numerics::contours;
use crate::numerics::control::Control;
use crate::numerics::polyline;

type Cdt = ConstrainedDelaunayTriangulation<Point2<f64>>;

/// FxHash-style multiplicative hashing of small integer keys (grid cells,
/// coordinate bits): `SipHash` took a tenth of the meshing time.
#[derive(Default)]
pub(crate) struct CellHasher(u64);

impl std::hash::Hasher for CellHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x517c_c1b7_2722_0a95);
    }

    fn write_i64(&mut self, v: i64) {
        self.write_u64(v as u64);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

pub(crate) type CellMap<K, V> = HashMap<K, V, std::hash::BuildHasherDefault<CellHasher>>;

/// Ratio of circumradius to local size above which a triangle gets a vertex.
const BETA: f64 = 0.7;
/// Vertices per `2A / (√3 h₀²)` of a relaxed mesh from circumcenter
/// insertion (measured: 1.19 to 1.26).
const KAPPA: f64 = 1.22;
/// The same from the hexagonal lattice (exactly 1 inside, a little more
/// in the band along the boundary).
const KAPPA_LATTICE: f64 = 1.05;
/// Largest angle bound accepted (Ruppert's refinement terminates up to
/// about 33.8°).
pub const MAX_MIN_ANGLE: f64 = 33.0;

/// A planar domain: closed rings in physical coordinates (axis 0, axis 1),
/// inside by the even-odd rule (a point is inside when a ray from it
/// crosses the rings an odd number of times), so outer rings and holes may
/// turn either way.
#[derive(Debug, Clone, PartialEq)]
pub struct Domain {
    rings: Vec<Vec<[f64; 2]>>,
}

/// Why a domain could not be meshed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DomainError {
    /// A ring is degenerate or has a non-finite coordinate.
    #[error("ring {ring}: {reason}")]
    Ring {
        /// Index of the ring.
        ring: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// Two boundary edges cross (a ring crosses itself or another ring).
    #[error("ring {ring} crosses a ring (itself or another) at its edge {edge}; boundaries may touch at a vertex but not cross")]
    Crossing {
        /// Index of the ring.
        ring: usize,
        /// Index of the edge in the ring (from vertex `edge` to `edge + 1`).
        edge: usize,
    },
    /// The domain has no inside (no ring, or no cell of a mask).
    #[error("the domain is empty: {0}")]
    Empty(String),
    /// The size parameters are out of range.
    #[error("{0}")]
    Size(String),
    /// The mesh would exceed the vertex limit.
    #[error("the mesh would have more than {limit} vertices (about {estimate}); ask for fewer or a longer edge length")]
    TooLarge {
        /// The limit.
        limit: usize,
        /// The estimated vertex count.
        estimate: usize,
    },
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

impl Domain {
    /// A domain from closed rings (the closing vertex may be repeated or
    /// not). Consecutive duplicate vertices are dropped; every ring must keep
    /// at least three vertices, finite coordinates and a non-zero area.
    pub fn new(rings: Vec<Vec<[f64; 2]>>) -> Result<Self, DomainError> {
        if rings.is_empty() {
            return Err(DomainError::Empty("no ring was given".into()));
        }
        let mut clean = Vec::with_capacity(rings.len());
        for (r, ring) in rings.into_iter().enumerate() {
            if let Some(v) = ring
                .iter()
                .position(|p| !(p[0].is_finite() && p[1].is_finite()))
            {
                return Err(DomainError::Ring {
                    ring: r,
                    reason: format!("vertex {v} has a non-finite coordinate"),
                });
            }
            let mut pts: Vec<[f64; 2]> = Vec::with_capacity(ring.len());
            for p in ring {
                if pts.last() != Some(&p) {
                    pts.push(p);
                }
            }
            while pts.len() > 1 && pts.first() == pts.last() {
                pts.pop();
            }
            if pts.len() < 3 {
                return Err(DomainError::Ring {
                    ring: r,
                    reason: "has fewer than 3 distinct vertices".into(),
                });
            }
            if signed_area(&pts).abs() <= f64::EPSILON * bbox_extent(&pts).powi(2) {
                return Err(DomainError::Ring {
                    ring: r,
                    reason: "has zero area".into(),
                });
            }
            clean.push(pts);
        }
        Ok(Self { rings: clean })
    }

    /// The domain of the non-zero cells of a 2D mask (C order, shape
    /// `(n0, n1)`), cell `(i, j)` being the square of side `spacing` centred
    /// at `(i · s₀, j · s₁)`. The cell-edge boundary is simplified within
    /// `tolerance` cells (Ramer-Douglas-Peucker; 0.36 turns a diagonal
    /// staircase into a straight edge); where the simplified rings would
    /// cross, the exact staircase is used instead.
    pub fn from_mask(
        mask: &[bool],
        shape: [usize; 2],
        spacing: [f64; 2],
        tolerance: f64,
        control: &Control<'_>,
    ) -> Result<Self, DomainError> {
        let labels: Vec<i64> = mask.iter().map(|&m| i64::from(m)).collect();
        let boundaries = contours::trace(&labels, shape, Some(0), control)
            .map_err(|_| DomainError::Cancelled)?;
        let polygons = boundaries.polygons();
        if polygons.is_empty() {
            return Err(DomainError::Empty("the mask has no non-zero cell".into()));
        }
        let rings = |tol: f64| -> Vec<Vec<[f64; 2]>> {
            polygons
                .iter()
                .flat_map(|p| p.rings.iter())
                .map(|ring| {
                    let keep = if tol > 0.0 {
                        polyline::simplify(ring, tol)
                    } else {
                        (0..ring.len()).collect()
                    };
                    keep.into_iter()
                        .map(|k| [ring[k][0] * spacing[0], ring[k][1] * spacing[1]])
                        .collect()
                })
                .collect()
        };
        let simplified = Self::new(rings(tolerance));
        match simplified {
            Ok(d) if tolerance > 0.0 && d.check_crossings().is_err() => Self::new(rings(0.0)),
            Ok(d) => Ok(d),
            Err(_) if tolerance > 0.0 => Self::new(rings(0.0)),
            Err(e) => Err(e),
        }
    }

    /// The rings (open: the first vertex is not repeated).
    pub fn rings(&self) -> &[Vec<[f64; 2]>] {
        &self.rings
    }

    /// The area inside by the even-odd rule, from the rings' shoelace
    /// areas: `Σ_r (−1)^{d_r} |A_r|`, `d_r` the number of other rings
    /// around ring `r` (counted at the midpoint of its first edge). `None`
    /// when that is not clear-cut: a midpoint on another ring, more than 64
    /// rings (the count is quadratic), or a total that is not positive (a
    /// ring crossing itself); the boundary triangulation decides then.
    fn even_odd_area(&self) -> Option<f64> {
        if self.rings.len() > 64 {
            return None;
        }
        let mut area = 0.0;
        for (r, ring) in self.rings.iter().enumerate() {
            let p = [
                (ring[0][0] + ring[1][0]) / 2.0,
                (ring[0][1] + ring[1][1]) / 2.0,
            ];
            let mut depth = 0;
            for (q, other) in self.rings.iter().enumerate() {
                if q == r {
                    continue;
                }
                let tolerance = 1e-12 * bbox_extent(other);
                let n = other.len();
                let mut odd = false;
                for k in 0..n {
                    let (a, b) = (other[k], other[(k + 1) % n]);
                    if segment_distance(p, a, b) <= tolerance {
                        return None;
                    }
                    if (a[0] <= p[0]) != (b[0] <= p[0])
                        && a[1] + (p[0] - a[0]) * (b[1] - a[1]) / (b[0] - a[0]) < p[1]
                    {
                        odd = !odd;
                    }
                }
                depth += usize::from(odd);
            }
            let a = signed_area(ring).abs();
            area += if depth % 2 == 0 { a } else { -a };
        }
        (area > 0.0).then_some(area)
    }

    /// Whether some boundary edges cross: triangulates the ring vertices.
    fn check_crossings(&self) -> Result<(), DomainError> {
        let (points, edges, origin) = self.boundary_points(&|_| 1.0, f64::INFINITY);
        build(&points, &edges, &origin).map(|_| ())
    }

    /// The boundary points of step 1 (ring vertices and the points that cut
    /// each edge into pieces of geodesic length about 1 under `inv_h`), the
    /// constraint edges between consecutive points, and for each edge the
    /// ring edge it lies on (`(ring, edge)`). Shared vertices are merged.
    #[allow(clippy::type_complexity)]
    fn boundary_points(
        &self,
        h: &dyn Fn([f64; 2]) -> f64,
        h0: f64,
    ) -> (Vec<[f64; 2]>, Vec<[usize; 2]>, Vec<(usize, usize)>) {
        let mut points: Vec<[f64; 2]> = Vec::new();
        let mut index: CellMap<[u64; 2], usize> = CellMap::default();
        let mut id = |p: [f64; 2], points: &mut Vec<[f64; 2]>| -> usize {
            *index
                .entry([p[0].to_bits(), p[1].to_bits()])
                .or_insert_with(|| {
                    points.push(p);
                    points.len() - 1
                })
        };
        let mut edges = Vec::new();
        let mut origin = Vec::new();
        for (r, ring) in self.rings.iter().enumerate() {
            let n = ring.len();
            for k in 0..n {
                let (a, b) = (ring[k], ring[(k + 1) % n]);
                let pieces = if h0.is_finite() {
                    let length = geodesic_length(a, b, h, h0);
                    (length.round() as usize).clamp(1, 1 << 20)
                } else {
                    1
                };
                let cuts = cut_points(a, b, pieces, h, h0);
                let mut prev = id(a, &mut points);
                for c in cuts.into_iter().chain(std::iter::once(b)) {
                    let next = id(c, &mut points);
                    if next != prev {
                        edges.push([prev, next]);
                        origin.push((r, k));
                    }
                    prev = next;
                }
            }
        }
        (points, edges, origin)
    }
}

/// The isotropic size field `h(x) = h₀ · s(x)`: the relative size `s`
/// (1, or `1/W` for a metric `W`) sampled on a grid and interpolated
/// bilinearly between cell centres (clamped at the border).
#[derive(Debug, Clone, PartialEq)]
pub enum SizeField {
    /// `s = 1`.
    Uniform,
    /// `s` on the cells of a grid of `shape` cells of size `spacing`.
    Raster {
        /// `(n0, n1)`.
        shape: [usize; 2],
        /// Physical size of a cell per axis.
        spacing: [f64; 2],
        /// `s` per cell, C order, finite and > 0.
        scale: Vec<f64>,
    },
}

impl SizeField {
    /// The size field `1/W` of an isotropic metric `W` (finite, > 0).
    pub fn from_metric(
        cost: &[f64],
        shape: [usize; 2],
        spacing: [f64; 2],
    ) -> Result<Self, DomainError> {
        if cost.len() != shape[0] * shape[1] {
            return Err(DomainError::Size(format!(
                "the metric has {} values for {shape:?} cells",
                cost.len()
            )));
        }
        if let Some(k) = cost.iter().position(|w| !(w.is_finite() && *w > 0.0)) {
            return Err(DomainError::Size(format!(
                "the metric must be finite and > 0 (cell {k} is {})",
                cost[k]
            )));
        }
        Ok(Self::Raster {
            shape,
            spacing,
            scale: cost.iter().map(|w| 1.0 / w).collect(),
        })
    }

    /// The relative size `s(x)` at a physical point.
    pub fn at(&self, p: [f64; 2]) -> f64 {
        match self {
            Self::Uniform => 1.0,
            Self::Raster {
                shape,
                spacing,
                scale,
            } => {
                let u = |a: usize| {
                    let t = (p[a] / spacing[a]).clamp(0.0, (shape[a] - 1) as f64);
                    let i = (t.floor() as usize).min(shape[a].saturating_sub(2));
                    (i, (t - i as f64).clamp(0.0, 1.0))
                };
                if shape[0] < 2 || shape[1] < 2 {
                    let i = (p[0] / spacing[0])
                        .round()
                        .clamp(0.0, (shape[0] - 1) as f64) as usize;
                    let j = (p[1] / spacing[1])
                        .round()
                        .clamp(0.0, (shape[1] - 1) as f64) as usize;
                    return scale[i * shape[1] + j];
                }
                let ((i, a), (j, b)) = (u(0), u(1));
                let s = |i: usize, j: usize| scale[i * shape[1] + j];
                (1.0 - a) * ((1.0 - b) * s(i, j) + b * s(i, j + 1))
                    + a * ((1.0 - b) * s(i + 1, j) + b * s(i + 1, j + 1))
            }
        }
    }
}

/// The target of [`mesh_domain`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MeshSize {
    /// About this many vertices (within a few per cent).
    Count(usize),
    /// Edges of about this (geodesic) length.
    EdgeLength(f64),
}

/// Options of [`mesh_domain`].
#[derive(Debug, Clone, PartialEq)]
pub struct DomainMeshOptions {
    /// Vertex count or edge length.
    pub size: MeshSize,
    /// The size field (uniform by default).
    pub field: SizeField,
    /// Smallest angle to reach, in degrees (0 to [`MAX_MIN_ANGLE`]; 25 by default).
    pub min_angle: f64,
    /// Relaxation sweeps (3 by default).
    pub smoothing: usize,
    /// Refuse meshes with more vertices than this.
    pub max_vertices: usize,
}

impl Default for DomainMeshOptions {
    fn default() -> Self {
        Self {
            size: MeshSize::Count(1000),
            field: SizeField::Uniform,
            min_angle: 25.0,
            smoothing: 3,
            max_vertices: 4_000_000,
        }
    }
}

/// A mesh of a domain.
#[derive(Debug, Clone, PartialEq)]
pub struct DomainMesh {
    /// Vertex positions (physical coordinates, axis 0 first).
    pub points: Vec<[f64; 2]>,
    /// Triangles, counter-clockwise in the `(axis 0, axis 1)` plane.
    pub triangles: Vec<[u32; 3]>,
    /// Boundary edges, with the domain on their left.
    pub boundary_edges: Vec<[u32; 2]>,
    /// Vertices on the boundary.
    pub boundary_vertices: usize,
    /// Vertices the quality refinement added (step 5).
    pub refined: usize,
    /// The size `h₀` used (geodesic edge length).
    pub h0: f64,
    /// Meshing attempts made to reach the vertex count.
    pub attempts: usize,
    /// Area of the domain (sum of the inside triangles of the boundary
    /// triangulation).
    pub area: f64,
    /// Whether the refinement reached the angle bound everywhere outside
    /// sharp input corners (false: it ran out of its vertex budget).
    pub refinement_complete: bool,
}

/// Meshes `domain` (see the module documentation for the method).
///
/// # Examples
/// ```
/// use geodex::numerics::meshing::domain::{mesh_domain, Domain, DomainMeshOptions, MeshSize};
/// use geodex::numerics::Control;
/// # fn main() -> Result<(), geodex::numerics::meshing::domain::DomainError> {
/// let square = Domain::new(vec![vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]])?;
/// let options = DomainMeshOptions { size: MeshSize::EdgeLength(1.0), ..Default::default() };
/// let mesh = mesh_domain(&square, &options, &Control::default())?;
/// let area: f64 = mesh.triangles.iter().map(|t| {
///     let [a, b, c] = t.map(|v| mesh.points[v as usize]);
///     ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])) / 2.0
/// }).sum();
/// assert!((area - 100.0).abs() < 1e-9);
/// assert!(mesh.points.len() > 100 && mesh.points.len() < 160);
/// # Ok(())
/// # }
/// ```
pub fn mesh_domain(
    domain: &Domain,
    options: &DomainMeshOptions,
    control: &Control<'_>,
) -> Result<DomainMesh, DomainError> {
    if !(options.min_angle.is_finite() && (0.0..=MAX_MIN_ANGLE).contains(&options.min_angle)) {
        return Err(DomainError::Size(format!(
            "the angle bound must be between 0 and {MAX_MIN_ANGLE} degrees"
        )));
    }
    let field = &options.field;
    let s = |p: [f64; 2]| field.at(p);
    // The area and ∫ s⁻² dA: from the rings alone for a uniform size, else
    // (or when the nesting of the rings is unclear) over the boundary
    // triangulation, at the centroids.
    let uniform_area = match field {
        SizeField::Uniform => domain.even_odd_area(),
        SizeField::Raster { .. } => None,
    };
    let (area, weighted) = match uniform_area {
        Some(a) => (a, a),
        None => {
            let (points, edges, origin) = domain.boundary_points(&s, f64::INFINITY);
            let cdt = build(&points, &edges, &origin)?;
            let inside = classify(&cdt);
            let (mut area, mut weighted) = (0.0, 0.0);
            for f in cdt.inner_faces() {
                if inside[f.fix().index()] {
                    let a = f.area();
                    area += a;
                    weighted += a / s(centroid(&f.positions())).powi(2);
                }
            }
            (area, weighted)
        }
    };
    if area <= 0.0 {
        return Err(DomainError::Empty(
            "no triangle lies inside the rings".into(),
        ));
    }
    // The boundary's geodesic length at h₀ = 1: about P / h₀ boundary points.
    let perimeter: f64 = domain
        .rings
        .iter()
        .map(|r| {
            (0..r.len())
                .map(|k| geodesic_length(r[k], r[(k + 1) % r.len()], &s, 1.0))
                .sum::<f64>()
        })
        .sum();
    let ring_vertices: usize = domain.rings.iter().map(Vec::len).sum();
    let estimate = |h0: f64| {
        (2.0 * weighted / (3f64.sqrt() * h0 * h0) + perimeter / h0).ceil() + ring_vertices as f64
    };
    let mut h0 = match options.size {
        MeshSize::EdgeLength(h) => {
            if !(h.is_finite() && h > 0.0) {
                return Err(DomainError::Size(
                    "the edge length must be finite and > 0".into(),
                ));
            }
            h
        }
        MeshSize::Count(n) => {
            if n < 3 {
                return Err(DomainError::Size("the vertex count must be >= 3".into()));
            }
            // N ≈ κ · 2 ∫ s⁻² dA / (√3 h₀²) + P / (2 h₀), with P the
            // boundary's geodesic length at h₀ = 1 and κ = 1.22 measured
            // (relaxed Delaunay triangles are smaller than equilateral
            // ones of side h₀): a quadratic in 1 / h₀.
            let kappa = if matches!(field, SizeField::Uniform) {
                KAPPA_LATTICE
            } else {
                KAPPA
            };
            let a = kappa * 2.0 * weighted / 3f64.sqrt();
            let b = perimeter / 2.0;
            let x = (-b + (b * b + 4.0 * a * n as f64).sqrt()) / (2.0 * a);
            1.0 / x
        }
    };
    let limit = options.max_vertices;
    if estimate(h0) > limit as f64 {
        return Err(DomainError::TooLarge {
            limit,
            estimate: estimate(h0).min(usize::MAX as f64) as usize,
        });
    }
    let mut attempts = 0;
    loop {
        attempts += 1;
        let mut mesh = mesh_once(domain, options, h0, control)?;
        mesh.attempts = attempts;
        mesh.area = area;
        let MeshSize::Count(n) = options.size else {
            return Ok(mesh);
        };
        let got = mesh.points.len() as f64;
        let ratio = got / n as f64;
        if (ratio - 1.0).abs() <= 0.05
            || attempts >= 4
            || mesh.points.len() <= mesh.boundary_vertices
        {
            return Ok(mesh);
        }
        h0 *= ratio.sqrt();
    }
}

/// Steps 1 to 5 at one size `h₀`.
fn mesh_once(
    domain: &Domain,
    options: &DomainMeshOptions,
    h0: f64,
    control: &Control<'_>,
) -> Result<DomainMesh, DomainError> {
    let poll = || {
        if control.is_cancelled() {
            Err(DomainError::Cancelled)
        } else {
            Ok(())
        }
    };
    let field = &options.field;
    let h = |p: [f64; 2]| h0 * field.at(p);
    let s = |p: [f64; 2]| field.at(p);
    let limit = options.max_vertices;
    // 1-2: boundary points and their constrained triangulation.
    let (boundary, edges, origin) = domain.boundary_points(&s, h0);
    if boundary.len() > limit {
        return Err(DomainError::TooLarge {
            limit,
            estimate: boundary.len(),
        });
    }
    let boundary_cdt = build(&boundary, &edges, &origin)?;
    let oracle = Oracle {
        inside: classify(&boundary_cdt),
        cdt: boundary_cdt,
        nb: boundary.len(),
    };
    let mut interior: Vec<[f64; 2]> = Vec::new();
    // The number of lattice points (they come first in `interior`).
    let mut lattice_len = None;
    let mut cdt = if matches!(field, SizeField::Uniform) {
        // 3 (uniform size): the hexagonal lattice of side h₀, kept where it
        // is inside and at least h₀/2 from the boundary, in one bulk load.
        interior = lattice(&boundary, &edges, h0, limit, control)?;
        lattice_len = Some(interior.len());
        poll()?;
        let mut all = boundary.clone();
        all.extend_from_slice(&interior);
        build(&all, &edges, &origin)?
    } else {
        oracle.cdt.clone()
    };
    // 3: passes of circumcenter insertion (with a uniform size, they only
    // fill what the lattice left between it and the boundary).
    // The vertices whose triangles the next pass looks at (`None`: all
    // triangles). Every triangle an insertion creates has the new vertex as
    // a corner, so after the first pass only the stars of the new vertices
    // and of the triangles whose candidate was crowded out can hold work.
    let mut work: Option<Vec<usize>> = None;
    let mut seen: Vec<u32> = Vec::new();
    for pass in 0..200u32 {
        poll()?;
        let mut candidates: Vec<(f64, [f64; 2], FixedVertexHandle)> = Vec::new();
        let mut consider = |f: spade::handles::FaceHandle<'_, InnerTag, _, _, _, _>| {
            let vs = f.vertices();
            let pos = vs.map(|v| v.position());
            if !oracle.face(vs.map(|v| v.fix().index()), &pos) {
                return;
            }
            let c = f.circumcenter();
            let radius = dist([c.x, c.y], [pos[0].x, pos[0].y]);
            let hc = h(centroid(&pos));
            if radius > BETA * hc {
                candidates.push((radius / hc, [c.x, c.y], vs[0].fix()));
            }
        };
        match &work {
            None => cdt.inner_faces().for_each(&mut consider),
            Some(vertices) => {
                seen.resize(cdt.num_all_faces(), u32::MAX);
                for &v in vertices {
                    for e in cdt.vertex(FixedVertexHandle::from_index(v)).out_edges() {
                        if let Some(f) = e.face().as_inner() {
                            let k = f.fix().index();
                            if seen[k] != pass {
                                seen[k] = pass;
                                consider(f);
                            }
                        }
                    }
                }
            }
        }
        let mut next: Vec<usize> = Vec::new();
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0));
        // Accepted points, each with a vertex of the face it came from (a
        // walk from there to the point is short).
        let mut accepted: Vec<([f64; 2], FixedVertexHandle)> = Vec::new();
        let cell = h0 * 0.25;
        let mut grid: CellMap<(i64, i64), Vec<usize>> = CellMap::default();
        let key = |p: [f64; 2]| ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64);
        for (k, (_, c, hint)) in candidates.into_iter().enumerate() {
            if k % 4096 == 4095 {
                poll()?;
            }
            if !admissible(&cdt, &oracle, c, hint) {
                continue;
            }
            let hc = h(c);
            let reach = (0.5 * hc / cell).ceil() as i64;
            let (ki, kj) = key(c);
            let mut near = false;
            'scan: for di in -reach..=reach {
                for dj in -reach..=reach {
                    if let Some(list) = grid.get(&(ki + di, kj + dj)) {
                        if list.iter().any(|&a| dist(accepted[a].0, c) < 0.5 * hc) {
                            near = true;
                            break 'scan;
                        }
                    }
                }
            }
            if near {
                next.push(hint.index());
                continue;
            }
            grid.entry(key(c)).or_default().push(accepted.len());
            accepted.push((c, hint));
        }
        if accepted.is_empty() {
            break;
        }
        if boundary.len() + interior.len() + accepted.len() > limit {
            return Err(DomainError::TooLarge {
                limit,
                estimate: boundary.len() + interior.len() + accepted.len(),
            });
        }
        // Insert in row order of the hash cells so that the walks are short.
        accepted.sort_by(|a, b| {
            let (ka, kb) = (key(a.0), key(b.0));
            (ka.0 / 8, ka.1, ka.0).cmp(&(kb.0 / 8, kb.1, kb.0))
        });
        for (k, (p, hint)) in accepted.into_iter().enumerate() {
            if k % 4096 == 4095 {
                poll()?;
            }
            // A point that lands on an existing vertex returns that vertex.
            // Vertices are only appended here, so the hint still exists.
            let fresh = boundary.len() + interior.len();
            if let Ok(v) = cdt.insert_with_hint(Point2::new(p[0], p[1]), hint) {
                if v.index() == fresh {
                    interior.push(p);
                    next.push(fresh);
                }
            }
        }
        work = Some(next);
    }
    // 4: relaxation sweeps. A vertex's target depends on its star only, so
    // after the first sweep only the vertices next to one that moved (before
    // or after the move) are looked at again (`None`: all of them).
    let mut active: Option<Vec<usize>> = None;
    if let Some(l) = lattice_len {
        // A lattice vertex whose neighbours are all lattice vertices is the
        // centre of six equilateral triangles: its target is itself. The
        // first sweep looks at the others only: the inserted vertices and
        // the lattice vertices next to one of them or to the boundary.
        let nb = boundary.len();
        let mut list: Vec<usize> = (l..interior.len()).collect();
        let mut marked = vec![false; l];
        for v in (0..nb).chain(nb + l..nb + interior.len()) {
            for e in cdt.vertex(FixedVertexHandle::from_index(v)).out_edges() {
                let j = e.to().fix().index();
                if (nb..nb + l).contains(&j) && !marked[j - nb] {
                    marked[j - nb] = true;
                    list.push(j - nb);
                }
            }
        }
        list.sort_unstable();
        active = Some(list);
    }
    for sweep in 0..options.smoothing {
        poll()?;
        control.report(sweep as f64 / (options.smoothing + 1) as f64);
        let nb = boundary.len();
        let targets: Vec<(usize, [f64; 2])> = match &active {
            None => {
                let mut sum = vec![[0.0f64; 3]; interior.len()];
                // Faces with an inner vertex are inside (the others move nothing).
                for f in cdt.inner_faces() {
                    let vs = f.vertices();
                    if vs.iter().all(|v| v.fix().index() < nb) {
                        continue;
                    }
                    let pos = f.positions();
                    let w = f.area() / h(centroid(&pos)).powi(2);
                    let c = f.circumcenter();
                    for v in vs {
                        let k = v.fix().index();
                        if k >= nb {
                            let e = &mut sum[k - nb];
                            e[0] += w * c.x;
                            e[1] += w * c.y;
                            e[2] += w;
                        }
                    }
                }
                sum.iter()
                    .enumerate()
                    .filter(|(_, e)| e[2] > 0.0)
                    .map(|(k, e)| (k, [e[0] / e[2], e[1] / e[2]]))
                    .collect()
            }
            Some(list) => list
                .iter()
                .filter_map(|&k| {
                    star_target(&cdt, FixedVertexHandle::from_index(nb + k), &h).map(|q| (k, q))
                })
                .collect(),
        };
        // The vertices that move by more than 5 % of the local size (inside
        // a lattice the target is the vertex itself). Against 2 % this kept
        // the smallest angles on the bench's domains at 2k vertices (the
        // share >= 40° on the disc, the L-shape and the square with holes
        // 94.1, 99.3 and 99.0 % against 93.8, 99.3 and 99.2 %; the disc's
        // smallest angle 26.2° against 26.4°, the others the same) and took
        // 10-20 % less time: most of the later sweeps' moves are below 5 %.
        let mut moves: Vec<(usize, [f64; 2])> = Vec::new();
        for (k, q) in targets {
            let p = interior[k];
            if dist(p, q) <= 0.05 * h(p) {
                continue;
            }
            let v = FixedVertexHandle::from_index(nb + k);
            if in_star(&cdt, v, q) || admissible(&cdt, &oracle, q, v) {
                moves.push((k, q));
            }
        }
        if moves.is_empty() {
            break;
        }
        if moves.len() * 4 > interior.len() {
            active = None;
            // Many moves: rebuild the triangulation at the new positions.
            let mut moved = interior.clone();
            for &(k, q) in &moves {
                moved[k] = q;
            }
            let mut all = boundary.clone();
            all.extend_from_slice(&moved);
            let rebuilt = build(&all, &edges, &origin)?;
            if rebuilt.num_vertices() != all.len() {
                // Two vertices met: keep the previous positions.
                break;
            }
            cdt = rebuilt;
            interior = moved;
        } else {
            // Few moves (the band along the boundary): remove and reinsert
            // each. Removal swaps the last vertex into the freed index and
            // insertion appends, so `slot` follows where each vertex went.
            let mut slot: Vec<usize> = (0..interior.len()).collect();
            let mut at: Vec<usize> = (0..interior.len()).collect();
            // Ids (original slots) of the vertices whose stars change.
            let mut touched: Vec<usize> = Vec::new();
            for (m, (id, q)) in moves.into_iter().enumerate() {
                if m % 4096 == 4095 {
                    poll()?;
                }
                let (k, last) = (slot[id], interior.len() - 1);
                let old = interior[k];
                let here = FixedVertexHandle::from_index(nb + k);
                let mut near = nb + k;
                for e in cdt.vertex(here).out_edges() {
                    let j = e.to().fix().index();
                    near = j;
                    if j >= nb {
                        touched.push(at[j - nb]);
                    }
                }
                touched.push(id);
                cdt.remove(here);
                // Removal moved the last vertex into the freed index.
                if near == nb + last {
                    near = nb + k;
                }
                interior.swap_remove(k);
                if k < last {
                    let other = at[last];
                    at[k] = other;
                    slot[other] = k;
                }
                let fresh = nb + interior.len();
                let hint = FixedVertexHandle::from_index(near);
                let placed = match cdt.insert_with_hint(Point2::new(q[0], q[1]), hint) {
                    Ok(v) if v.index() == fresh => q,
                    _ => {
                        // It met a vertex: put it back where it was.
                        match cdt.insert_with_hint(Point2::new(old[0], old[1]), hint) {
                            Ok(v) if v.index() == fresh => old,
                            _ => {
                                return Err(DomainError::Size(
                                    "a relaxed vertex could not be reinserted".into(),
                                ))
                            }
                        }
                    }
                };
                interior.push(placed);
                if at.len() <= last {
                    at.push(id);
                } else {
                    at[last] = id;
                }
                slot[id] = last;
                for e in cdt.vertex(FixedVertexHandle::from_index(fresh)).out_edges() {
                    let j = e.to().fix().index();
                    if j >= nb {
                        touched.push(at[j - nb]);
                    }
                }
            }
            let mut next: Vec<usize> = touched.into_iter().map(|id| slot[id]).collect();
            next.sort_unstable();
            next.dedup();
            active = Some(next);
        }
    }
    poll()?;
    // 5: quality refinement.
    let before = cdt.num_vertices();
    // Every vertex after the boundary's lies inside, so the oracle mostly
    // classifies the faces without a flood fill; that stays right as long
    // as the refinement adds nothing (its boundary splits would break it).
    let inside = oracle.faces(&cdt).unwrap_or_else(|| classify(&cdt));
    let limit_ratio = AngleLimit::from_deg(options.min_angle).radius_to_shortest_edge_limit();
    let refinement_complete =
        if options.min_angle > 0.0 && !refined_already(&cdt, &inside, limit_ratio) {
            let result = cdt.refine(
                RefinementParameters::<f64>::new()
                    .exclude_outer_faces(true)
                    .with_angle_limit(AngleLimit::from_deg(options.min_angle))
                    .with_max_additional_vertices(before + 64),
            );
            result.refinement_complete
        } else {
            true
        };
    let refined = cdt.num_vertices() - before;
    if cdt.num_vertices() > limit {
        return Err(DomainError::TooLarge {
            limit,
            estimate: cdt.num_vertices(),
        });
    }
    let inside = if refined == 0 { inside } else { classify(&cdt) };
    Ok(extract(&cdt, &inside, h0, refined, refinement_complete))
}

/// Whether Ruppert's refinement would leave the triangulation as it is: no
/// inside triangle is skinny (circumradius over shortest edge above
/// `limit = 1 / (2 sin θ)`, i.e. an angle below θ) and no boundary edge has
/// the opposite vertex of an inside triangle strictly within its diametral
/// circle; the two things `spade`'s `refine` acts on. Decided with a
/// relative margin of `1e-9`: a borderline mesh goes through `refine`.
fn refined_already(cdt: &Cdt, inside: &[bool], limit: f64) -> bool {
    let margin = 1.0 - 1e-9;
    cdt.inner_faces().all(|f| {
        if !inside[f.fix().index()] {
            return true;
        }
        let p = f.positions();
        let d2 = |a: Point2<f64>, b: Point2<f64>| (a.x - b.x).powi(2) + (a.y - b.y).powi(2);
        // Edge k runs from corner k to corner k + 1, opposite corner k + 2.
        let e2 = [d2(p[0], p[1]), d2(p[1], p[2]), d2(p[2], p[0])];
        let cross = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[1].y - p[0].y) * (p[2].x - p[0].x);
        // R² = a²b²c² / (16 A²) = a²b²c² / (4 cross²).
        let shortest = e2[0].min(e2[1]).min(e2[2]);
        // A degenerate or non-finite triangle (NaN) is not fine.
        let fine = e2[0] * e2[1] * e2[2] <= limit * limit * shortest * 4.0 * cross * cross * margin;
        if !fine {
            return false;
        }
        f.adjacent_edges().iter().enumerate().all(|(k, e)| {
            if !e.is_constraint_edge() {
                return true;
            }
            let (a, b, q) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            let m = Point2::new((a.x + b.x) / 2.0, (a.y + b.y) / 2.0);
            d2(q, m) * margin >= e2[k] / 4.0
        })
    })
}

/// The inside triangles, their vertices (compacted) and boundary edges.
fn extract(
    cdt: &Cdt,
    inside: &[bool],
    h0: f64,
    refined: usize,
    refinement_complete: bool,
) -> DomainMesh {
    let mut map = vec![u32::MAX; cdt.num_vertices()];
    let mut points = Vec::new();
    let mut triangles = Vec::new();
    let mut boundary_edges = Vec::new();
    let mut id = |k: usize, p: Point2<f64>, points: &mut Vec<[f64; 2]>| {
        if map[k] == u32::MAX {
            map[k] = points.len() as u32;
            points.push([p.x, p.y]);
        }
        map[k]
    };
    for f in cdt.inner_faces() {
        if !inside[f.fix().index()] {
            continue;
        }
        let v = f.vertices();
        let t = [0, 1, 2].map(|k| id(v[k].fix().index(), v[k].position(), &mut points));
        triangles.push(t);
        for e in f.adjacent_edges() {
            if e.is_constraint_edge() {
                let [a, b] = e.vertices();
                let a = id(a.fix().index(), a.position(), &mut points);
                let b = id(b.fix().index(), b.position(), &mut points);
                boundary_edges.push([a, b]);
            }
        }
    }
    let mut on_boundary = vec![false; points.len()];
    for e in &boundary_edges {
        on_boundary[e[0] as usize] = true;
        on_boundary[e[1] as usize] = true;
    }
    DomainMesh {
        boundary_vertices: on_boundary.iter().filter(|&&b| b).count(),
        points,
        triangles,
        boundary_edges,
        refined,
        h0,
        attempts: 1,
        area: 0.0,
        refinement_complete,
    }
}

/// The constrained Delaunay triangulation of `points` with `edges`; a
/// crossing names the ring edge it lies on.
fn build(
    points: &[[f64; 2]],
    edges: &[[usize; 2]],
    origin: &[(usize, usize)],
) -> Result<Cdt, DomainError> {
    let mut conflict = None;
    let vertices = points.iter().map(|p| Point2::new(p[0], p[1])).collect();
    let cdt = Cdt::try_bulk_load_cdt(vertices, edges.to_vec(), |e| {
        conflict.get_or_insert(e);
    })
    .map_err(|e| DomainError::Size(format!("the boundary cannot be triangulated: {e:?}")))?;
    if let Some(e) = conflict {
        let k = edges
            .iter()
            .position(|x| *x == e || *x == [e[1], e[0]])
            .unwrap_or(0);
        let (ring, edge) = origin.get(k).copied().unwrap_or((0, 0));
        return Err(DomainError::Crossing { ring, edge });
    }
    Ok(cdt)
}

/// Inside flags per face index (the outer face, index 0, is outside): a
/// 0-1 breadth-first search from the outer face, where crossing a
/// constraint edge costs 1; odd depth is inside.
fn classify(cdt: &Cdt) -> Vec<bool> {
    let n = cdt.num_all_faces();
    // Neighbours of every inner face: (face index, across a constraint).
    let mut neighbours = vec![[(0usize, false); 3]; n];
    let mut depth = vec![u32::MAX; n];
    let mut queue = std::collections::VecDeque::new();
    depth[0] = 0;
    for f in cdt.inner_faces() {
        let k = f.fix().index();
        for (slot, e) in f.adjacent_edges().iter().enumerate() {
            let g = e.rev().face();
            let constraint = e.is_constraint_edge();
            neighbours[k][slot] = (g.fix().index(), constraint);
            if g.is_outer() {
                let d = u32::from(constraint);
                if d < depth[k] {
                    depth[k] = d;
                }
            }
        }
    }
    for (k, &d) in depth.iter().enumerate().skip(1) {
        if d == 0 {
            queue.push_front(k);
        } else if d == 1 {
            queue.push_back(k);
        }
    }
    while let Some(k) = queue.pop_front() {
        for &(j, constraint) in &neighbours[k] {
            if j == 0 {
                continue;
            }
            let w = u32::from(constraint);
            let d = depth[k] + w;
            if d < depth[j] {
                depth[j] = d;
                if w == 0 {
                    queue.push_front(j);
                } else {
                    queue.push_back(j);
                }
            }
        }
    }
    depth.iter().map(|&d| d != u32::MAX && d % 2 == 1).collect()
}

/// Inside tests for the triangulations of one mesh: the boundary points
/// come first (indices `0..nb`) and every later vertex lies inside, so a
/// face with a later vertex is inside (it crosses no constraint), and the
/// others are decided by locating their centroid in the boundary-only
/// triangulation, whose faces were classified once.
struct Oracle {
    /// The constrained triangulation of the boundary points alone.
    cdt: Cdt,
    /// Its inside flags by face index.
    inside: Vec<bool>,
    /// Number of boundary points.
    nb: usize,
}

impl Oracle {
    /// Inside flags per face index of `cdt`, a triangulation of this
    /// oracle's boundary points followed by inside points only; `None` when
    /// a face of boundary points alone is not a face of the boundary
    /// triangulation (cocircular points triangulated the other way), which
    /// only a flood fill ([`classify`]) decides for certain.
    fn faces(&self, cdt: &Cdt) -> Option<Vec<bool>> {
        let mut inside = vec![false; cdt.num_all_faces()];
        for f in cdt.inner_faces() {
            let v = f.vertices().map(|v| v.fix().index());
            inside[f.fix().index()] = self.known(v)?;
        }
        Some(inside)
    }

    /// Whether the face with vertex indices `v` (counterclockwise) is
    /// inside, when that follows from its vertices: a later vertex, or the
    /// same triangle in the boundary triangulation.
    fn known(&self, v: [usize; 3]) -> Option<bool> {
        if v.iter().any(|&k| k >= self.nb) {
            return Some(true);
        }
        let (a, b, c) = (v[0], v[1], v[2]);
        let e = self
            .cdt
            .vertex(FixedVertexHandle::from_index(a))
            .out_edges()
            .find(|e| e.to().fix().index() == b)?;
        let f = e.face().as_inner()?;
        (e.next().to().fix().index() == c).then(|| self.inside[f.fix().index()])
    }

    /// Whether the face with vertex indices `v` and positions `pos` is inside.
    fn face(&self, v: [usize; 3], pos: &[Point2<f64>; 3]) -> bool {
        // The same triangle in the boundary triangulation is the usual case:
        // a sliver along the boundary has its centroid on an edge, where
        // locating it could land on the other side.
        if let Some(inside) = self.known(v) {
            return inside;
        }
        let g = centroid(pos);
        let hint = FixedVertexHandle::from_index(v[0]);
        match self.cdt.locate_with_hint(Point2::new(g[0], g[1]), hint) {
            PositionInTriangulation::OnFace(f) => self.inside[f.index()],
            PositionInTriangulation::OnEdge(e) => {
                // Not a constraint (the face would cross it): both sides agree.
                let e = self.cdt.directed_edge(e);
                e.face()
                    .as_inner()
                    .or(e.rev().face().as_inner())
                    .is_some_and(|f| self.inside[f.fix().index()])
            }
            _ => false,
        }
    }
}

/// The points of the hexagonal lattice of side `h0` (rows along axis 1,
/// `h0 √3/2` apart along axis 0, every other row shifted by `h0/2`) that lie
/// inside the domain and at least `h0/2` from every boundary edge.
///
/// Inside is decided per row by the even-odd rule on the row's crossings
/// with the boundary edges (the classification of the constrained
/// triangulation, without locating each point in it); the distance test
/// runs only where a boundary edge's bounding box touches the point's cell
/// of side `h0` or one next to it.
fn lattice(
    boundary: &[[f64; 2]],
    edges: &[[usize; 2]],
    h0: f64,
    limit: usize,
    control: &Control<'_>,
) -> Result<Vec<[f64; 2]>, DomainError> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in boundary {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let dy = h0 * 3f64.sqrt() / 2.0;
    let rows = ((hi[0] - lo[0]) / dy).floor() as usize + 1;
    let columns = ((hi[1] - lo[1]) / h0).floor() as usize + 2;
    if (rows as f64) * (columns as f64) > 4.0 * limit as f64 + 1e6 {
        return Err(DomainError::TooLarge {
            limit,
            estimate: (rows as f64 * columns as f64).min(usize::MAX as f64) as usize,
        });
    }
    // Boundary edges by the cells (side h0) their bounding boxes touch, in
    // one dense table (offsets and edge lists).
    let n0 = ((hi[0] - lo[0]) / h0).floor() as usize + 1;
    let n1 = ((hi[1] - lo[1]) / h0).floor() as usize + 1;
    let cell = |p: [f64; 2]| {
        (
            (((p[0] - lo[0]) / h0).floor().max(0.0) as usize).min(n0 - 1),
            (((p[1] - lo[1]) / h0).floor().max(0.0) as usize).min(n1 - 1),
        )
    };
    let boxes = |f: &mut dyn FnMut(usize, usize)| {
        for (k, e) in edges.iter().enumerate() {
            let (a, b) = (cell(boundary[e[0]]), cell(boundary[e[1]]));
            for i in a.0.min(b.0)..=a.0.max(b.0) {
                for j in a.1.min(b.1)..=a.1.max(b.1) {
                    f(k, i * n1 + j);
                }
            }
        }
    };
    let mut start = vec![0usize; n0 * n1 + 1];
    boxes(&mut |_, c| start[c + 1] += 1);
    for c in 0..n0 * n1 {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut listed = vec![0usize; start[n0 * n1]];
    boxes(&mut |k, c| {
        listed[fill[c]] = k;
        fill[c] += 1;
    });
    let near_boundary = |p: [f64; 2]| {
        let (i, j) = cell(p);
        (i.saturating_sub(1)..=(i + 1).min(n0 - 1)).any(|a| {
            (j.saturating_sub(1)..=(j + 1).min(n1 - 1)).any(|b| {
                let c = a * n1 + b;
                listed[start[c]..start[c + 1]].iter().any(|&k| {
                    let e = edges[k];
                    segment_distance(p, boundary[e[0]], boundary[e[1]]) < 0.5 * h0
                })
            })
        })
    };
    // The edges whose axis-0 span holds each row, for the crossings.
    let row_of = |x: f64| (x - lo[0]) / dy;
    let mut row_start = vec![0usize; rows + 1];
    let spans = |f: &mut dyn FnMut(usize, usize)| {
        for (k, e) in edges.iter().enumerate() {
            let (a, b) = (boundary[e[0]][0], boundary[e[1]][0]);
            let first = row_of(a.min(b)).ceil().max(0.0) as usize;
            let last = (row_of(a.max(b)).floor().max(-1.0) + 1.0) as usize;
            for r in first..last.min(rows) {
                f(k, r);
            }
        }
    };
    spans(&mut |_, r| row_start[r + 1] += 1);
    for r in 0..rows {
        row_start[r + 1] += row_start[r];
    }
    let mut row_fill = row_start.clone();
    let mut row_edges = vec![0usize; row_start[rows]];
    spans(&mut |k, r| {
        row_edges[row_fill[r]] = k;
        row_fill[r] += 1;
    });
    let mut out = Vec::new();
    let mut crossings: Vec<f64> = Vec::new();
    for r in 0..rows {
        if control.is_cancelled() {
            return Err(DomainError::Cancelled);
        }
        let x = lo[0] + r as f64 * dy;
        // Even-odd: an edge crosses the row when its ends lie on either
        // side (an end on the row counts as above it).
        crossings.clear();
        for &k in &row_edges[row_start[r]..row_start[r + 1]] {
            let (a, b) = (boundary[edges[k][0]], boundary[edges[k][1]]);
            if (a[0] <= x) != (b[0] <= x) {
                crossings.push(a[1] + (x - a[0]) * (b[1] - a[1]) / (b[0] - a[0]));
            }
        }
        crossings.sort_by(f64::total_cmp);
        let shift = if r % 2 == 1 { 0.5 * h0 } else { 0.0 };
        let row_first = out.len();
        for pair in crossings.chunks_exact(2) {
            // The lattice columns strictly inside the interval.
            let first = ((pair[0] - lo[1] - shift) / h0).floor() as i64 + 1;
            let last = ((pair[1] - lo[1] - shift) / h0).ceil() as i64 - 1;
            for c in first.max(0)..=last.min(columns as i64 - 1) {
                let p = [x, lo[1] + shift + c as f64 * h0];
                if p[1] > hi[1] || near_boundary(p) {
                    continue;
                }
                out.push(p);
                if out.len() > limit {
                    return Err(DomainError::TooLarge {
                        limit,
                        estimate: out.len(),
                    });
                }
            }
        }
        // Rows run alternately left and right: consecutive points are
        // neighbours (the vertex order of the mesh).
        if r % 2 == 1 {
            out[row_first..].reverse();
        }
    }
    Ok(out)
}

/// Distance from `p` to the segment `[a, b]`.
fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    dist(p, [a[0] + t * d[0], a[1] + t * d[1]])
}

/// The optimal-Delaunay target of the inner vertex `v`: the mean of the
/// circumcentres of its triangles, weighted by area / h² (what the sweep
/// over all faces computes, from the star alone).
fn star_target(cdt: &Cdt, v: FixedVertexHandle, h: &impl Fn([f64; 2]) -> f64) -> Option<[f64; 2]> {
    let mut e = [0.0f64; 3];
    for edge in cdt.vertex(v).out_edges() {
        if let Some(f) = edge.face().as_inner() {
            let pos = f.positions();
            let w = f.area() / h(centroid(&pos)).powi(2);
            let c = f.circumcenter();
            e[0] += w * c.x;
            e[1] += w * c.y;
            e[2] += w;
        }
    }
    (e[2] > 0.0).then(|| [e[0] / e[2], e[1] / e[2]])
}

/// Whether `q` lies in one of the triangles around the inner vertex `v`.
fn in_star(cdt: &Cdt, v: FixedVertexHandle, q: [f64; 2]) -> bool {
    cdt.vertex(v).out_edges().any(|e| {
        e.face().as_inner().is_some_and(|f| {
            let p = f.positions();
            (0..3).all(|k| {
                let (a, b) = (p[k], p[(k + 1) % 3]);
                (b.x - a.x) * (q[1] - a.y) - (b.y - a.y) * (q[0] - a.x) > 0.0
            })
        })
    })
}

/// Whether `c` may become a vertex: it lies in an inside face and outside
/// the diametral circles of that face's boundary edges.
fn admissible(cdt: &Cdt, oracle: &Oracle, c: [f64; 2], hint: FixedVertexHandle) -> bool {
    if !(c[0].is_finite() && c[1].is_finite()) {
        return false;
    }
    let PositionInTriangulation::OnFace(face) = cdt.locate_with_hint(Point2::new(c[0], c[1]), hint)
    else {
        return false;
    };
    let face = cdt.face(face);
    if !oracle.face(face.vertices().map(|v| v.fix().index()), &face.positions()) {
        return false;
    }
    face.adjacent_edges().iter().all(|e| {
        if !e.is_constraint_edge() {
            return true;
        }
        let [a, b] = e.positions();
        let m = [(a.x + b.x) / 2.0, (a.y + b.y) / 2.0];
        dist(m, c) > dist([a.x, a.y], [b.x, b.y]) / 2.0
    })
}

/// `∫_a^b ds / (h₀ s)`, by the midpoint rule on pieces shorter than the
/// local size.
fn geodesic_length(a: [f64; 2], b: [f64; 2], s: &dyn Fn([f64; 2]) -> f64, h0: f64) -> f64 {
    let length = dist(a, b);
    let steps = ((length / (0.25 * h0 * s(a).min(s(b)))).ceil() as usize).clamp(1, 4096);
    let dt = 1.0 / steps as f64;
    (0..steps)
        .map(|k| {
            let t = (k as f64 + 0.5) * dt;
            length * dt / (h0 * s(lerp(a, b, t)))
        })
        .sum()
}

/// The `pieces − 1` points that cut `[a, b]` into pieces of equal geodesic length.
fn cut_points(
    a: [f64; 2],
    b: [f64; 2],
    pieces: usize,
    s: &dyn Fn([f64; 2]) -> f64,
    h0: f64,
) -> Vec<[f64; 2]> {
    if pieces <= 1 {
        return Vec::new();
    }
    let steps = (pieces * 8).max(64);
    let mut cumulative = Vec::with_capacity(steps + 1);
    cumulative.push(0.0);
    for k in 0..steps {
        let t = (k as f64 + 0.5) / steps as f64;
        let last = cumulative[k];
        cumulative.push(last + 1.0 / (h0 * s(lerp(a, b, t))));
    }
    let total = cumulative[steps];
    let mut out = Vec::with_capacity(pieces - 1);
    let mut k = 0;
    for piece in 1..pieces {
        let target = total * piece as f64 / pieces as f64;
        while k < steps && cumulative[k + 1] < target {
            k += 1;
        }
        let span = cumulative[k + 1] - cumulative[k];
        let frac = if span > 0.0 {
            (target - cumulative[k]) / span
        } else {
            0.0
        };
        out.push(lerp(a, b, (k as f64 + frac) / steps as f64));
    }
    out
}

fn lerp(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn centroid(p: &[Point2<f64>; 3]) -> [f64; 2] {
    [
        (p[0].x + p[1].x + p[2].x) / 3.0,
        (p[0].y + p[1].y + p[2].y) / 3.0,
    ]
}

fn signed_area(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|k| {
            let (a, b) = (ring[k], ring[(k + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

fn bbox_extent(ring: &[[f64; 2]]) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in ring {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (hi[0] - lo[0]).max(hi[1] - lo[1])
}

/// The smallest angle of each triangle, in degrees.
pub fn min_angles(points: &[[f64; 2]], triangles: &[[u32; 3]]) -> Vec<f64> {
    triangles
        .iter()
        .map(|t| {
            let p = t.map(|v| points[v as usize]);
            (0..3)
                .map(|k| {
                    let (a, b, c) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
                    let u = [b[0] - a[0], b[1] - a[1]];
                    let v = [c[0] - a[0], c[1] - a[1]];
                    let cross = u[0] * v[1] - u[1] * v[0];
                    let dot = u[0] * v[0] + u[1] * v[1];
                    cross.abs().atan2(dot).to_degrees()
                })
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::sampling::triangulation::check_planar;

    fn square(n: f64) -> Vec<[f64; 2]> {
        vec![[0.0, 0.0], [n, 0.0], [n, n], [0.0, n]]
    }

    fn area(points: &[[f64; 2]], triangles: &[[u32; 3]]) -> f64 {
        triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| points[v as usize]);
                ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])) / 2.0
            })
            .sum()
    }

    #[test]
    fn square_with_a_hole_is_tiled_exactly() {
        let hole = vec![[4.0, 4.0], [4.0, 6.0], [6.0, 6.0], [6.0, 4.0]];
        let d = Domain::new(vec![square(10.0), hole]).unwrap();
        let o = DomainMeshOptions {
            size: MeshSize::EdgeLength(0.8),
            ..Default::default()
        };
        let m = mesh_domain(&d, &o, &Control::default()).unwrap();
        assert!((area(&m.points, &m.triangles) - 96.0).abs() < 1e-9);
        assert!(check_planar(&m.points, &m.triangles).is_empty());
        assert!((m.area - 96.0).abs() < 1e-9);
        let angles = min_angles(&m.points, &m.triangles);
        assert!(
            angles.iter().all(|&a| a >= 25.0 - 1e-9),
            "{:?}",
            angles.iter().cloned().fold(90.0, f64::min)
        );
    }

    /// Even-odd ray test against every boundary edge.
    fn inside_by_rays(p: [f64; 2], boundary: &[[f64; 2]], edges: &[[usize; 2]]) -> bool {
        let mut odd = false;
        for e in edges {
            let (a, b) = (boundary[e[0]], boundary[e[1]]);
            if (a[0] <= p[0]) != (b[0] <= p[0]) {
                let y = a[1] + (p[0] - a[0]) * (b[1] - a[1]) / (b[0] - a[0]);
                if y < p[1] {
                    odd = !odd;
                }
            }
        }
        odd
    }

    #[test]
    fn the_lattice_is_every_lattice_point_inside_and_away_from_the_boundary() {
        let disc = |c: [f64; 2], r: f64, n: usize| -> Vec<[f64; 2]> {
            (0..n)
                .map(|k| {
                    let t = std::f64::consts::TAU * k as f64 / n as f64;
                    [c[0] + r * t.cos(), c[1] + r * t.sin()]
                })
                .collect()
        };
        let hole = vec![[20.0, 20.0], [20.0, 45.0], [45.0, 45.0], [45.0, 20.0]];
        let d = Domain::new(vec![square(100.0), hole, disc([70.0, 65.0], 15.0, 48)]).unwrap();
        for h0 in [2.9, 7.3] {
            let (boundary, edges, _) = d.boundary_points(&|_| 1.0, h0);
            let got = lattice(&boundary, &edges, h0, 1 << 20, &Control::default()).unwrap();
            // Brute force over the same lattice positions.
            let dy = h0 * 3f64.sqrt() / 2.0;
            let mut want = Vec::new();
            let mut doubtful = 0;
            for r in 0..=((100.0 / dy) as usize) {
                let shift = if r % 2 == 1 { 0.5 * h0 } else { 0.0 };
                for c in 0..=((100.0 / h0) as usize + 1) {
                    let p = [r as f64 * dy, shift + c as f64 * h0];
                    if p[1] > 100.0 || !inside_by_rays(p, &boundary, &edges) {
                        continue;
                    }
                    let near = edges
                        .iter()
                        .map(|e| segment_distance(p, boundary[e[0]], boundary[e[1]]))
                        .fold(f64::INFINITY, f64::min);
                    if (near - 0.5 * h0).abs() < 1e-9 {
                        doubtful += 1;
                    } else if near > 0.5 * h0 {
                        want.push(p);
                    }
                }
            }
            let key = |p: &[f64; 2]| (p[0].to_bits(), p[1].to_bits());
            let mut g: Vec<_> = got.iter().map(key).collect();
            let mut w: Vec<_> = want.iter().map(key).collect();
            g.sort_unstable();
            w.sort_unstable();
            assert!(w.len() > 100, "{h0}: {}", w.len());
            // Points at exactly h0/2 from the boundary may fall either way.
            let missing = w.iter().filter(|k| g.binary_search(k).is_err()).count();
            let extra = g.iter().filter(|k| w.binary_search(k).is_err()).count();
            assert!(
                missing + extra <= doubtful,
                "{h0}: {missing} missing, {extra} extra"
            );
        }
    }

    #[test]
    fn the_even_odd_area_of_nested_rings_is_the_triangulated_one() {
        let ring = |c: [f64; 2], r: f64| -> Vec<[f64; 2]> {
            (0..40)
                .map(|k| {
                    let t = std::f64::consts::TAU * k as f64 / 40.0;
                    [c[0] + r * t.cos(), c[1] + r * t.sin()]
                })
                .collect()
        };
        // A square with a hole holding an island, and a second square apart;
        // rings turning either way.
        let mut hole = ring([5.0, 5.0], 3.0);
        hole.reverse();
        let domains = [
            vec![square(10.0), hole, ring([5.0, 5.0], 1.0)],
            vec![square(10.0), ring([20.0, 5.0], 2.0)],
        ];
        for rings in domains {
            let d = Domain::new(rings).unwrap();
            let (points, edges, origin) = d.boundary_points(&|_| 1.0, f64::INFINITY);
            let cdt = build(&points, &edges, &origin).unwrap();
            let inside = classify(&cdt);
            let want: f64 = cdt
                .inner_faces()
                .filter(|f| inside[f.fix().index()])
                .map(|f| f.area())
                .sum();
            let got = d.even_odd_area().unwrap();
            assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
        }
        // Two rings sharing an edge: the midpoint test is unclear.
        let touching = Domain::new(vec![
            square(10.0),
            vec![[0.0, 0.0], [10.0, 0.0], [5.0, -5.0]],
        ])
        .unwrap();
        assert_eq!(touching.even_odd_area(), None);
    }

    #[test]
    fn refinement_is_skipped_only_when_it_would_change_nothing() {
        let limit = AngleLimit::from_deg(25.0).radius_to_shortest_edge_limit();
        // A square cut into two right isoceles triangles (45°): fine; a
        // point just inside the bottom edge's diametral circle encroaches
        // it; a flat triangle is skinny.
        let cases: [(&[[f64; 2]], bool); 3] = [
            (&[], true),
            (&[[5.0, 1.0]], false),
            (&[[5.0, 9.0], [5.2, 9.5]], false),
        ];
        for (extra, fine) in cases {
            let mut points = square(10.0);
            points.extend_from_slice(extra);
            let edges = vec![[0, 1], [1, 2], [2, 3], [3, 0]];
            let origin = vec![(0, 0), (0, 1), (0, 2), (0, 3)];
            let mut cdt = build(&points, &edges, &origin).unwrap();
            let inside = classify(&cdt);
            assert_eq!(refined_already(&cdt, &inside, limit), fine, "{extra:?}");
            let before = cdt.num_vertices();
            cdt.refine(
                RefinementParameters::<f64>::new()
                    .exclude_outer_faces(true)
                    .with_angle_limit(AngleLimit::from_deg(25.0)),
            );
            // What the check says `refine` would do, it does.
            assert_eq!(cdt.num_vertices() == before, fine, "{extra:?}");
        }
    }

    #[test]
    fn count_is_reached_within_five_per_cent() {
        let d = Domain::new(vec![square(100.0)]).unwrap();
        for n in [200, 2000] {
            let o = DomainMeshOptions {
                size: MeshSize::Count(n),
                ..Default::default()
            };
            let m = mesh_domain(&d, &o, &Control::default()).unwrap();
            let r = m.points.len() as f64 / n as f64;
            assert!((r - 1.0).abs() < 0.05, "{n}: {}", m.points.len());
        }
    }

    #[test]
    fn crossing_rings_are_named() {
        // A pentagram: every other vertex of a regular pentagon.
        let star: Vec<[f64; 2]> = (0..5)
            .map(|k| {
                let t = std::f64::consts::TAU * (2 * k) as f64 / 5.0;
                [10.0 * t.cos(), 10.0 * t.sin()]
            })
            .collect();
        let d = Domain::new(vec![star]).unwrap();
        let e = mesh_domain(&d, &DomainMeshOptions::default(), &Control::default()).unwrap_err();
        assert!(matches!(e, DomainError::Crossing { ring: 0, .. }), "{e:?}");
        let e = Domain::new(vec![vec![[0.0, 0.0], [1.0, 1.0], [0.0, 0.0]]]).unwrap_err();
        assert!(matches!(e, DomainError::Ring { ring: 0, .. }), "{e:?}");
    }

    #[test]
    fn a_metric_concentrates_vertices() {
        // W = 4 on the left half: edges there are 4 times shorter, so about
        // 16 times more vertices per unit area.
        let shape = [64, 64];
        let cost: Vec<f64> = (0..64 * 64)
            .map(|k| if k % 64 < 32 { 4.0 } else { 1.0 })
            .collect();
        let field = SizeField::from_metric(&cost, shape, [1.0, 1.0]).unwrap();
        let d = Domain::new(vec![square(63.0)]).unwrap();
        let o = DomainMeshOptions {
            size: MeshSize::Count(1500),
            field,
            ..Default::default()
        };
        let m = mesh_domain(&d, &o, &Control::default()).unwrap();
        let left = m.points.iter().filter(|p| p[1] < 28.0).count() as f64;
        let right = m.points.iter().filter(|p| p[1] > 35.0).count() as f64;
        assert!(left / right > 8.0 && left / right < 24.0, "{left} {right}");
    }
}
