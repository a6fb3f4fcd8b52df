//! Surface remeshing (the monograph's sections 4.4 and 4.6): a new triangle
//! mesh of a surface from geodesic sampling, geodesic Lloyd relaxation and
//! the dual of the geodesic Voronoi cells.
//!
//! # Math
//!
//! **Metric.** Distances are weighted geodesic distances `d_W` on the input
//! mesh (fast marching, `|∇_S d| = W`). Farthest-point sampling makes the
//! covering radius uniform in `d_W`, so the Euclidean size of a cell is
//! `∝ 1/W`:
//!
//! ```text
//! W = 1                                (uniform)
//! W = 1 + λ · κ / mean(κ)              (curvature-adapted, λ >= 0)
//! ```
//!
//! where `κ(v) = max_u |2 n_v · (p_u − p_v)| / |p_u − p_v|²` is the largest
//! normal curvature along the edges of `v` (`n_v` the area-weighted vertex
//! normal), averaged once over the one-ring.
//!
//! **Anisotropic metric.** [`Adaptation::Anisotropic`] measures lengths in
//! face `f` by `sqrt(xᵀ M_f x)` with a tensor of the face's plane built from
//! the curvature tensor. At each vertex the second fundamental form
//! `II = [[a, b], [b, c]]` in a tangent frame `(t₁, t₂)` is fitted by least
//! squares to the normal curvatures along the edges,
//! `κ_e = 2 n·d / |d|²` in the direction `(x, y)` of the tangent part of `d`:
//! `min Σ_e (a x² + 2 b x y + c y² − κ_e)²`. Its eigenvalues are the
//! principal curvatures `κ₁, κ₂` with directions `r₁, r₂`, and
//! `|II| = |κ₁| r₁r₁ᵀ + |κ₂| r₂r₂ᵀ` (as a tensor of space) is averaged once
//! over the one-ring. A face averages its corners' `|II|`, projects it onto
//! its plane (`P |II| P`, `P = I − n nᵀ`) and takes the eigenvalues
//! `μ₁ >= μ₂` of that 2×2 tensor with directions `q₁, q₂`; then
//!
//! ```text
//! M_f = m₁ q₁q₁ᵀ + m₂ q₂q₂ᵀ,   m₁ = max(μ₁, ε),   m₂ = max(μ₂, ε, m₁ / ρ²)
//! ```
//!
//! with `ε = mean(μ₁) / 100` (flat parts get isotropic cells ten times
//! the size of those of the mean curvature) and `ρ` = `max_ratio`. A unit
//! ball of `M_f` has radius `1/sqrt(m)` along each eigendirection, so the
//! cells are `sqrt(m₁/m₂) <= ρ` times longer along the direction of low
//! curvature than across it: `|II|` is the metric under which the linear
//! interpolation error of the surface is equidistributed. On a cylinder
//! of radius `R`, `κ₁ = 1/R` around and `κ₂ = 0` along the axis: cells
//! `ρ` times longer along the axis. Distances under `M_f` are computed by
//! the fast marching with face tensors (`numerics::mesh::fast_marching`,
//! the update in the `M_f^{1/2}`-transformed triangle; its limits are
//! documented there).
//!
//! **Sampling.** [`Sampling::Exact`] places each sample at the vertex
//! farthest from those placed and marches its front over the vertices
//! whose distance it lowers: `n (ln k + γ)` vertex visits, about 2 s of
//! the 2.9 s of 1,000 vertices from the 655k-vertex icosphere.
//! [`Sampling::Clustered`] (the default from 8 input vertices per sample,
//! not under a tensor metric) samples clusters of the input's vertices
//! instead ([`super::cluster_sampling`]) and gets the cells by one front per
//! sample started on an upper bound of the distance
//! (`cells_from_bound`): about `1.3 n` visits, 0.7 s there, for the same
//! output quality.
//!
//! **Lloyd (centroidal relaxation).** With `V_i` the geodesic Voronoi cell of
//! sample `s_i` and `A_v` the lumped area of vertex `v` (a third of the
//! areas of its faces), the energy is
//!
//! ```text
//! E = Σ_v A_v · d_W(v, S)²
//! ```
//!
//! One iteration moves every sample to the vertex of its cell nearest to the
//! cell's area-weighted centroid `g_i = Σ_{v∈V_i} A_v p_v / Σ_{v∈V_i} A_v`
//! (the centroid projected back onto the surface, restricted to the cell's
//! vertices), recomputes the cells (one multi-source march) and keeps the
//! move only if `E` did not increase; otherwise the iterations stop on the
//! previous sampling. The reported energies are therefore non-increasing.
//!
//! **Dual triangulation.** Every input face whose three vertices lie in
//! three different cells `(a, b, c)` gives the triangle `(a, b, c)`, in the
//! face's vertex order (so the orientation is the input's); duplicates are
//! dropped. The result is checked: every edge in at most two triangles and
//! traversed in opposite directions, every vertex's triangles one fan (one
//! cycle inside, one path on a boundary), every cell used, no triangle whose
//! normal opposes the input face it came from. The cells involved in a
//! failure get a new sample at their farthest vertex (a local march) and the
//! dual is rebuilt, at most `max_repairs` rounds, and no more once two
//! rounds in a row have not lowered the number of cells at fault (scans
//! with many holes and tiny components, where repairs add samples without
//! end). A dual still invalid then is the best round's (fewest cells at
//! fault), cut down to its manifold part (flipped triangles, extra
//! triangles on an edge and extra fans at a vertex removed, samples left in
//! no triangle dropped): the output is always a manifold, with holes where
//! triangles went, and says what was removed. Then the Euler
//! characteristic `χ = V − E + F`, the components and the boundary loops
//! are compared with the input's: when all three agree (and each component
//! is orientable) the genus `g = (2c − χ − b)/2` agrees too.
//!
//! **Relaxation.** Last, unless `smoothing_iterations` is 0 or the metric
//! is a tensor field, [`super::surface_relax::relax`] flips edges to raise
//! their smallest angles and moves every free vertex towards the centroid
//! of its Voronoi cell within its one-ring (density `W⁴`), projected back
//! onto the input surface:
//! the dual's vertices sit at input vertices, which makes its triangles
//! only as regular as the input's vertex spacing allows.
//!
//! **Hausdorff distance.** [`hausdorff_distance`] samples each mesh at its
//! vertices, edge midpoints and face centroids and takes the largest
//! point-to-triangle distance to the other mesh (uniform grid of triangles),
//! in both directions.

use std::collections::HashMap;

use super::cluster_sampling::{cluster_sampling, worth_clustering};
use super::surface_relax::{relax, InputSurface, RelaxReport};
use crate::numerics::control::Control;
use crate::numerics::mesh::curvature::{face_normal, face_tensors_from_curvature};
use crate::numerics::mesh::fast_marching::{march_metric, MarchPrep, MarchWork, Metric};
use crate::numerics::mesh::sampling::FarthestQueue;
use crate::numerics::mesh::sources::{Seed, VertexGraph};
use crate::numerics::mesh::{
    cross, dot, norm, sub, MeshDistance, MeshSolveError, Topology, TriMesh,
};

/// How the vertex density follows the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Adaptation {
    /// `W = 1`: cells of equal geodesic size.
    Uniform,
    /// `W = 1 + λ κ / mean κ`: smaller cells where the surface bends.
    Curvature {
        /// `λ >= 0`.
        strength: f64,
    },
    /// A tensor per face from the curvature tensor (see the module docs):
    /// cells elongated along the directions of low curvature, by
    /// `sqrt(|κ₁| / |κ₂|)` capped at `max_ratio`.
    Anisotropic {
        /// Largest ratio of a cell's length to its width, `1 ..= 100`.
        max_ratio: f64,
    },
}

/// Options of [`remesh`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RemeshOptions {
    /// Target number of vertices (before repairs), `>= 4` and at most the
    /// input's vertex count.
    pub count: usize,
    /// Density.
    pub adaptation: Adaptation,
    /// Geodesic Lloyd iterations (0 keeps the farthest-point sampling);
    /// `None`: [`RemeshOptions::lloyd_iterations_or_default`].
    pub lloyd_iterations: Option<usize>,
    /// Rounds of dual repair (each adds samples to the offending cells).
    pub max_repairs: usize,
    /// Rounds of edge flips and tangential relaxation of the output on the
    /// input surface ([`super::surface_relax`]); 0 keeps the vertices at
    /// input vertices and the dual's connectivity; `None`:
    /// [`default_smoothing_iterations`]. Not applied under
    /// [`Adaptation::Anisotropic`].
    pub smoothing_iterations: Option<usize>,
    /// How the samples are placed.
    pub sampling: Sampling,
}

/// How [`remesh`] places its samples (step 1).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Sampling {
    /// [`Sampling::Clustered`] when the metric is not a tensor field and
    /// the input has at least 8 vertices per sample
    /// ([`worth_clustering`]), else [`Sampling::Exact`].
    #[default]
    Auto,
    /// Exact farthest-point sampling on the input's vertices, a front per
    /// sample: `n (ln k + γ)` vertex visits.
    Exact,
    /// Farthest-point sampling on clusters of the input's vertices
    /// ([`super::cluster_sampling`]), then a front per sample from an upper
    /// bound of the distance: about `1.3 n` vertex visits. Not under a
    /// tensor metric.
    Clustered,
}

/// What step 1 (the sampling) did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SamplingReport {
    /// The samples were placed on clusters ([`Sampling::Clustered`]).
    pub clustered: bool,
    /// Clusters they were placed on (0: exact sampling).
    pub clusters: usize,
    /// Vertices the fronts froze, over all samples (`n` for one march).
    pub front_visits: usize,
    /// The bound of the clustered sampling stopped every front short of a
    /// vertex, and the cells were marched again from all the samples at
    /// once (never seen on the test meshes; counted to be seen).
    pub restarted: bool,
}

impl Default for RemeshOptions {
    fn default() -> Self {
        Self {
            count: 1000,
            adaptation: Adaptation::Uniform,
            lloyd_iterations: None,
            max_repairs: 8,
            smoothing_iterations: None,
            sampling: Sampling::Auto,
        }
    }
}

impl RemeshOptions {
    /// Whether the final relaxation runs: not under a tensor metric, not
    /// with `smoothing_iterations: Some(0)`.
    pub fn relaxes(&self) -> bool {
        !matches!(self.adaptation, Adaptation::Anisotropic { .. })
            && self.smoothing_iterations != Some(0)
    }

    /// The geodesic Lloyd iterations to run: as given, else none when the
    /// relaxation follows (it does the centroidal work on the output; on
    /// icospheres 0, 1, 2 and 5 geodesic iterations before it give the
    /// same angles and Hausdorff distance within 3 %, and each costs a
    /// march over the whole input, a quarter of the time of 1,000 vertices
    /// from 655k), else 5.
    pub fn lloyd_iterations_or_default(&self) -> usize {
        self.lloyd_iterations
            .unwrap_or(if self.relaxes() { 0 } else { 5 })
    }
}

/// The default number of relaxation sweeps for `count` output vertices:
/// `400,000 / count` clamped to `20 ..= 100` (about 0.8 s of sweeps at
/// most on this project's 2-core machine; measured on icospheres, the
/// smallest angles still rise between 20 and 100 sweeps at 1,000
/// vertices).
pub fn default_smoothing_iterations(count: usize) -> usize {
    (400_000 / count.max(1)).clamp(20, 100)
}

/// Combinatorial topology of a triangle mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopologySummary {
    /// Vertices used by at least one face.
    pub vertices: usize,
    /// Edges.
    pub edges: usize,
    /// Faces.
    pub faces: usize,
    /// Connected components (of the used vertices).
    pub components: usize,
    /// Closed loops of boundary edges.
    pub boundary_loops: usize,
    /// `χ = V − E + F`.
    pub euler: i64,
    /// Total genus `(2c − χ − b) / 2` when the mesh is an oriented manifold.
    pub genus: Option<i64>,
    /// Edges with more than two faces.
    pub non_manifold_edges: usize,
    /// Edges whose two faces traverse them in the same direction.
    pub misoriented_edges: usize,
}

impl TopologySummary {
    /// Counts of `mesh`.
    pub fn of(mesh: &TriMesh) -> Self {
        Self::with(mesh, &Topology::new(mesh))
    }

    /// [`TopologySummary::of`] with the mesh's adjacency already built.
    pub fn with(mesh: &TriMesh, topo: &Topology) -> Self {
        let nf = mesh.num_faces();
        let mut used = vec![false; mesh.num_vertices()];
        for f in mesh.faces() {
            for &v in f {
                used[v as usize] = true;
            }
        }
        let vertices = used.iter().filter(|&&u| u).count();
        let mut comps: Vec<u32> = (0..mesh.num_vertices())
            .filter(|&v| used[v])
            .map(|v| topo.component[v])
            .collect();
        comps.sort_unstable();
        comps.dedup();
        // Interior edges appear twice among the half-edges, boundary ones once.
        let interior = topo.opposite.iter().filter(|&&h| h != NONE).count() / 2;
        let edges = interior + topo.boundary_edges + topo.non_manifold_edges;
        let boundary_loops = boundary_loops(mesh, topo);
        let euler = vertices as i64 - edges as i64 + nf as i64;
        let manifold = topo.non_manifold_edges == 0 && topo.misoriented_edges == 0;
        let twice = 2 * comps.len() as i64 - euler - boundary_loops as i64;
        let genus = (manifold && twice >= 0 && twice % 2 == 0).then_some(twice / 2);
        Self {
            vertices,
            edges,
            faces: nf,
            components: comps.len(),
            boundary_loops,
            euler,
            genus,
            non_manifold_edges: topo.non_manifold_edges,
            misoriented_edges: topo.misoriented_edges,
        }
    }

    /// Same components, boundary loops and Euler characteristic (hence the
    /// same genus on an oriented manifold).
    pub fn same_topology(&self, other: &Self) -> bool {
        self.components == other.components
            && self.boundary_loops == other.boundary_loops
            && self.euler == other.euler
            && self.genus == other.genus
    }
}

const NONE: u32 = u32::MAX;

/// Number of cycles formed by the boundary half-edges (each boundary vertex
/// of a manifold has one outgoing boundary half-edge per boundary pass).
fn boundary_loops(mesh: &TriMesh, topo: &Topology) -> usize {
    let mut next: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut edges = Vec::new();
    for (f, face) in mesh.faces().iter().enumerate() {
        for k in 0..3 {
            if topo.opposite[3 * f + k] == NONE {
                let (a, b) = (face[k], face[(k + 1) % 3]);
                next.entry(a).or_default().push(b);
                edges.push((a, b));
            }
        }
    }
    // Union-find over the boundary vertices: a loop is a connected set.
    let mut id: HashMap<u32, usize> = HashMap::new();
    for &(a, b) in &edges {
        let n = id.len();
        id.entry(a).or_insert(n);
        let n = id.len();
        id.entry(b).or_insert(n);
    }
    let mut parent: Vec<usize> = (0..id.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for &(a, b) in &edges {
        let (ra, rb) = (find(&mut parent, id[&a]), find(&mut parent, id[&b]));
        if ra != rb {
            parent[ra.max(rb)] = ra.min(rb);
        }
    }
    (0..parent.len())
        .filter(|&i| find(&mut parent, i) == i)
        .count()
}

/// Errors of [`remesh`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RemeshError {
    /// An option is out of range.
    #[error("{option}: {reason}")]
    InvalidOption {
        /// The option.
        option: &'static str,
        /// Why.
        reason: String,
    },
    /// The input is not a manifold triangle mesh.
    #[error("the input mesh is not manifold: {non_manifold_edges} edges in more than two faces, {misoriented_edges} edges with inconsistent orientation")]
    NonManifold {
        /// Edges in more than two faces.
        non_manifold_edges: usize,
        /// Edges traversed twice in the same direction.
        misoriented_edges: usize,
    },
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
    /// A distance solve failed.
    #[error(transparent)]
    Solve(#[from] MeshSolveError),
}

/// The new mesh and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct Remesh {
    /// The new mesh, faces oriented like the input: vertices at the samples
    /// (input vertices), then moved on the input surface by the relaxation
    /// when `smoothing_iterations > 0`.
    pub mesh: TriMesh,
    /// Input vertex each output vertex was sampled at.
    pub samples: Vec<u32>,
    /// Lloyd energy `Σ A_v d²` after the sampling and after each accepted
    /// iteration (non-increasing).
    pub energies: Vec<f64>,
    /// Lloyd iterations accepted.
    pub lloyd_accepted: usize,
    /// Samples added by the repairs of the dual.
    pub added: usize,
    /// Repair rounds run.
    pub repair_rounds: usize,
    /// Topology of the input.
    pub input_topology: TopologySummary,
    /// Topology of the output.
    pub output_topology: TopologySummary,
    /// The output is a manifold with consistent orientation, every vertex
    /// link a single fan, no triangle flipped against the input (after the
    /// cut of [`Remesh::cleaned`], if any).
    pub valid: bool,
    /// Components, boundary loops, Euler characteristic and genus agree.
    pub topology_kept: bool,
    /// Output triangles of the dual whose normal opposes their input face's.
    pub flipped: usize,
    /// What was cut from a dual the repairs could not make valid.
    pub cleaned: CleanReport,
    /// What the final flips and tangential relaxation did.
    pub relaxed: RelaxReport,
    /// How the samples were placed.
    pub sampled: SamplingReport,
}

/// Remeshes `mesh`; see the module docs.
///
/// The work runs on a copy of `mesh` whose vertices (and faces) are sorted
/// along a Morton (Z-order) curve of their positions, so that the marches
/// touch memory in spatial order (the fronts' neighbours are then mostly in
/// cache: about 2x on an icosphere, whose subdivision order scatters
/// neighbours); samples are mapped back to the input's vertex ids.
pub fn remesh(
    mesh: &TriMesh,
    options: &RemeshOptions,
    control: &Control<'_>,
) -> Result<Remesh, RemeshError> {
    let (local, old_of_new) = spatially_ordered(mesh);
    let mut r = remesh_ordered(&local, options, control)?;
    for s in r.samples.iter_mut() {
        *s = old_of_new[*s as usize];
    }
    Ok(r)
}

/// `mesh` with its vertices sorted by the Morton code of their position
/// (21 bits per axis over the bounding box) and its faces by the smallest
/// new index of their corners (corner order, hence orientation, kept), and
/// the old id of each new vertex.
pub(super) fn spatially_ordered(mesh: &TriMesh) -> (TriMesh, Vec<u32>) {
    let (lo, hi) = bounds(mesh.positions());
    let scale: [f64; 3] = std::array::from_fn(|j| {
        let e = hi[j] - lo[j];
        if e > 0.0 {
            ((1u64 << 21) - 1) as f64 / e
        } else {
            0.0
        }
    });
    let spread = |x: u64| {
        // Bits of x (21) to every third bit.
        let mut x = x & 0x1f_ffff;
        x = (x | x << 32) & 0x1f00000000ffff;
        x = (x | x << 16) & 0x1f0000ff0000ff;
        x = (x | x << 8) & 0x100f00f00f00f00f;
        x = (x | x << 4) & 0x10c30c30c30c30c3;
        (x | x << 2) & 0x1249249249249249
    };
    let code = |p: [f64; 3]| {
        let q: [u64; 3] = std::array::from_fn(|j| ((p[j] - lo[j]) * scale[j]) as u64);
        spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2
    };
    let mut order: Vec<u32> = (0..mesh.num_vertices() as u32).collect();
    let codes: Vec<u64> = mesh.positions().iter().map(|&p| code(p)).collect();
    order.sort_by_key(|&v| (codes[v as usize], v));
    let mut new_of_old = vec![0u32; order.len()];
    for (new, &old) in order.iter().enumerate() {
        new_of_old[old as usize] = new as u32;
    }
    let positions: Vec<[f64; 3]> = order.iter().map(|&v| mesh.position(v)).collect();
    let mut faces: Vec<[u32; 3]> = mesh
        .faces()
        .iter()
        .map(|f| f.map(|v| new_of_old[v as usize]))
        .collect();
    faces.sort_by_key(|f| (f[0].min(f[1]).min(f[2]), *f));
    (TriMesh::from_parts_unchecked(positions, faces), order)
}

/// [`remesh`] on the mesh as given (samples are its vertex ids).
fn remesh_ordered(
    mesh: &TriMesh,
    options: &RemeshOptions,
    control: &Control<'_>,
) -> Result<Remesh, RemeshError> {
    let n = mesh.num_vertices();
    let topo = Topology::new(mesh);
    if topo.non_manifold_edges > 0 || topo.misoriented_edges > 0 {
        return Err(RemeshError::NonManifold {
            non_manifold_edges: topo.non_manifold_edges,
            misoriented_edges: topo.misoriented_edges,
        });
    }
    if options.count < 4 {
        return Err(RemeshError::InvalidOption {
            option: "count",
            reason: "must be >= 4".into(),
        });
    }
    if options.count > n {
        return Err(RemeshError::InvalidOption {
            option: "count",
            reason: format!(
                "must be at most the input's vertex count ({n}), got {}",
                options.count
            ),
        });
    }
    let mut tensors: Option<Vec<[f64; 6]>> = None;
    let weights = match options.adaptation {
        Adaptation::Uniform => None,
        Adaptation::Anisotropic { max_ratio } => {
            if !(max_ratio.is_finite() && (1.0..=100.0).contains(&max_ratio)) {
                return Err(RemeshError::InvalidOption {
                    option: "max_ratio",
                    reason: "must be finite, >= 1 and <= 100".into(),
                });
            }
            if options.sampling == Sampling::Clustered {
                return Err(RemeshError::InvalidOption {
                    option: "sampling",
                    reason: "clustered sampling measures isotropic lengths: use `auto` or `exact` with the anisotropic adaptation".into(),
                });
            }
            tensors = Some(face_tensors_from_curvature(mesh, &topo, max_ratio));
            None
        }
        Adaptation::Curvature { strength } => {
            if !(strength.is_finite() && strength >= 0.0) {
                return Err(RemeshError::InvalidOption {
                    option: "strength",
                    reason: "must be finite and >= 0".into(),
                });
            }
            Some(curvature_weights(mesh, &topo, strength))
        }
    };
    let w = match &tensors {
        Some(t) => Metric::Faces(t),
        None => Metric::Weights(weights.as_deref()),
    };
    let prep = match &tensors {
        Some(t) => MarchPrep::with_tensors(mesh, &topo, t),
        None => MarchPrep::new(mesh, &topo),
    };
    let areas = vertex_areas(mesh);
    let inner = control.cancel_only();
    let lloyd_iterations = options.lloyd_iterations_or_default();
    let total_steps = (options.count + lloyd_iterations * options.count / 4 + 1) as f64;

    // 1. Farthest-point sampling: exact (a front per sample), or on
    // clusters and then one front per sample from a bound.
    let mut work = MarchWork::new(n);
    let graph = VertexGraph::new(mesh);
    let clustered = match options.sampling {
        Sampling::Exact => false,
        Sampling::Clustered => true,
        Sampling::Auto => tensors.is_none() && worth_clustering(n, options.count),
    };
    let (mut samples, mut field, sampled) = if clustered {
        let c = cluster_sampling(mesh, &graph, weights.as_deref(), options.count, &inner)
            .map_err(|_| RemeshError::Cancelled)?;
        let (field, front_visits, restarted) =
            cells_from_bound(&mut work, mesh, &prep, &c.samples, c.bound, w, &inner)?;
        let report = SamplingReport {
            clustered: true,
            clusters: c.clusters,
            front_visits,
            restarted,
        };
        (c.samples, field, report)
    } else {
        let (samples, field, front_visits) = exact_sampling(
            &mut work,
            mesh,
            &prep,
            &graph,
            w,
            options.count,
            control,
            total_steps,
        )?;
        let report = SamplingReport {
            front_visits,
            ..SamplingReport::default()
        };
        (samples, field, report)
    };
    control.report(samples.len() as f64 / total_steps);

    // 2. Geodesic Lloyd iterations, each kept only if the energy decreased.
    let mut energies = vec![energy(&field, &areas)];
    let mut lloyd_accepted = 0;
    for it in 0..lloyd_iterations {
        if control.is_cancelled() {
            return Err(RemeshError::Cancelled);
        }
        let moved = lloyd_step(mesh, &field, &areas, samples.len());
        let trial = voronoi(&mut work, mesh, &prep, &moved, w, &inner)?;
        let e = energy(&trial, &areas);
        control.report((options.count + (it + 1) * options.count / 4) as f64 / total_steps);
        if e.is_finite() && e <= energies[energies.len() - 1] {
            let changed = moved != samples;
            samples = moved;
            field = trial;
            energies.push(e);
            lloyd_accepted += 1;
            if !changed {
                break;
            }
        } else {
            break;
        }
    }

    // 3. Dual triangulation with repairs.
    let input_topology = TopologySummary::with(mesh, &topo);
    let face_normals: Vec<[f64; 3]> = (0..mesh.num_faces())
        .map(|f| face_normal(mesh, mesh.faces()[f]))
        .collect();
    let mut added = 0;
    let mut repair_rounds = 0;
    // The invalid dual with the fewest cells at fault so far, and how many
    // rounds in a row have not lowered that count.
    let mut best: Option<(Dual, Vec<u32>, usize)> = None;
    let mut stalled = 0;
    loop {
        if control.is_cancelled() {
            return Err(RemeshError::Cancelled);
        }
        let dual = dual_triangulation(mesh, &field.labels, &samples, &face_normals);
        let out_topology = TopologySummary::of(&dual.mesh);
        let valid = dual.bad.is_empty();
        let kept = valid && out_topology.same_topology(&input_topology);
        if !valid {
            if best.as_ref().is_none_or(|b| dual.bad.len() < b.0.bad.len()) {
                best = Some((dual.clone(), samples.clone(), added));
                stalled = 0;
            } else {
                stalled += 1;
            }
        }
        if kept || repair_rounds >= options.max_repairs || stalled >= 2 {
            // An invalid dual falls back on the best one, cut down to its
            // manifold part.
            let (dual, cleaned) = match (valid, best) {
                (false, Some((b, s, a))) => {
                    samples = s;
                    added = a;
                    let (mesh, kept_vertices, report) = manifold_part(&b.mesh, &b.flipped_faces);
                    samples = kept_vertices.iter().map(|&v| samples[v as usize]).collect();
                    (Dual { mesh, ..b }, report)
                }
                _ => (dual, CleanReport::default()),
            };
            let valid = valid || manifold_check(&dual.mesh);
            let mut out = dual.mesh;
            let mut relaxed = RelaxReport::default();
            // 4. Flips and tangential relaxation (not under a tensor metric:
            // they would make the cells isotropic again).
            let sweeps = options
                .smoothing_iterations
                .unwrap_or_else(|| default_smoothing_iterations(options.count));
            if valid && sweeps > 0 && options.relaxes() {
                let density: Option<Vec<f64>> = weights
                    .as_ref()
                    .map(|w| w.iter().map(|x| x.powi(4)).collect());
                let mut host: Vec<u32> = samples
                    .iter()
                    .map(|&s| topo.faces_of(s).first().copied().unwrap_or(0))
                    .collect();
                let mut positions = out.positions().to_vec();
                let mut faces = out.faces().to_vec();
                relaxed = relax(
                    InputSurface {
                        mesh,
                        topology: &topo,
                        face_normals: &face_normals,
                        density: density.as_deref(),
                    },
                    &mut positions,
                    &mut faces,
                    &mut host,
                    sweeps,
                    &inner,
                );
                if control.is_cancelled() {
                    return Err(RemeshError::Cancelled);
                }
                out = TriMesh::from_parts_unchecked(positions, faces);
            }
            let output_topology = TopologySummary::of(&out);
            control.report(1.0);
            return Ok(Remesh {
                mesh: out,
                samples,
                energies,
                lloyd_accepted,
                added,
                repair_rounds,
                input_topology,
                output_topology,
                valid,
                topology_kept: kept && output_topology.same_topology(&input_topology),
                flipped: dual.flipped,
                cleaned,
                relaxed,
                sampled,
            });
        }
        repair_rounds += 1;
        // The cells at fault; if none is (a valid dual of the wrong topology:
        // too coarse a sampling), the largest cells (by geodesic radius).
        let mut bad = dual.bad;
        if bad.is_empty() {
            let radius = cell_radius(&field, samples.len());
            let mut order: Vec<usize> = (0..samples.len()).collect();
            order.sort_by(|&a, &b| radius[b].1.total_cmp(&radius[a].1));
            bad = order
                .into_iter()
                .take((samples.len() / 50).max(1))
                .collect();
        }
        let radius = cell_radius(&field, samples.len());
        let mut seeds = Vec::new();
        bad.sort_unstable();
        bad.dedup();
        for c in bad {
            let (v, d) = radius[c];
            if d > 0.0 && v != NONE {
                seeds.push(Seed {
                    vertex: v,
                    distance: 0.0,
                    label: samples.len() as i32,
                });
                samples.push(v);
            }
        }
        if seeds.is_empty() {
            repair_rounds = options.max_repairs;
            continue;
        }
        added += seeds.len();
        march_metric(
            &mut work,
            mesh,
            &prep,
            &seeds,
            w,
            f64::INFINITY,
            &mut field,
            &inner,
        )?;
    }
}

/// Exact farthest-point sampling of `count` vertices: each new sample is
/// the vertex farthest from those placed (the first, the farthest of an
/// empty sampling: vertex 0), and its front runs over the vertices whose
/// distance it lowers only. Returns the samples, their cells and the
/// fronts' vertex visits.
#[allow(clippy::too_many_arguments)]
fn exact_sampling(
    work: &mut MarchWork,
    mesh: &TriMesh,
    prep: &MarchPrep,
    graph: &VertexGraph,
    w: Metric<'_>,
    count: usize,
    control: &Control<'_>,
    total_steps: f64,
) -> Result<(Vec<u32>, MeshDistance, usize), RemeshError> {
    let n = mesh.num_vertices();
    let inner = control.cancel_only();
    let mut field = MeshDistance {
        distance: vec![f64::INFINITY; n],
        labels: vec![-1; n],
    };
    let mut samples: Vec<u32> = Vec::with_capacity(count);
    let mut queue = FarthestQueue::new(&field.distance);
    let mut visits = 0;
    let mut next = queue.farthest(&field.distance).map_or(0, |(v, _)| v);
    while samples.len() < count {
        if control.is_cancelled() {
            return Err(RemeshError::Cancelled);
        }
        let seed = Seed {
            vertex: next,
            distance: 0.0,
            label: samples.len() as i32,
        };
        samples.push(next);
        visits += march_metric(
            work,
            mesh,
            prep,
            &[seed],
            w,
            f64::INFINITY,
            &mut field,
            &inner,
        )?;
        queue.lowered_on(graph, work.changed(), &field.distance);
        if samples.len().is_multiple_of(64) {
            control.report(samples.len() as f64 / total_steps);
        }
        match queue.farthest(&field.distance) {
            Some((v, d)) if d > 0.0 => next = v,
            _ => break,
        }
    }
    Ok((samples, field, visits))
}

/// The geodesic Voronoi cells of `samples` by one front per sample, in the
/// vertex order (a Morton order in [`remesh`]: consecutive fronts touch
/// nearby memory), each over the vertices where it goes below the current
/// value, which starts at `bound` (an upper bound of the distance to the
/// samples, [`super::cluster_sampling::ClusterSampling::bound`]): each front
/// then stays near its cell instead of crossing the mesh, the cost of
/// about one march over the input where a single multi-source march
/// from all the samples, its front spread over the whole mesh at once,
/// is several times slower for the cache misses. A vertex no front reached
/// although its bound is finite (the bound was below the marched distance
/// there) makes it start again with that single march. Returns the cells, the fronts' vertex visits and
/// whether it started again.
fn cells_from_bound(
    work: &mut MarchWork,
    mesh: &TriMesh,
    prep: &MarchPrep,
    samples: &[u32],
    bound: Vec<f64>,
    w: Metric<'_>,
    control: &Control<'_>,
) -> Result<(MeshDistance, usize, bool), RemeshError> {
    let n = mesh.num_vertices();
    let mut field = MeshDistance {
        distance: bound,
        labels: vec![-1; n],
    };
    let seed = |i: usize| Seed {
        vertex: samples[i],
        distance: 0.0,
        label: i as i32,
    };
    let mut order: Vec<usize> = (0..samples.len()).collect();
    order.sort_unstable_by_key(|&i| samples[i]);
    let mut visits = 0;
    for (j, i) in order.into_iter().enumerate() {
        // Each front is small (about `n / k` visits): poll between them.
        if j.is_multiple_of(64) && control.is_cancelled() {
            return Err(RemeshError::Cancelled);
        }
        field.distance[samples[i] as usize] = f64::INFINITY;
        visits += march_metric(
            work,
            mesh,
            prep,
            &[seed(i)],
            w,
            f64::INFINITY,
            &mut field,
            control,
        )?;
    }
    // Unreached with a finite bound: the bound was too low there. (An
    // infinite bound is a component without a sample: unreached anyway.)
    let restarted = field
        .labels
        .iter()
        .zip(&field.distance)
        .any(|(&l, d)| l < 0 && d.is_finite());
    if restarted {
        field = voronoi(work, mesh, prep, samples, w, control)?;
        visits += work.changed().len();
    }
    Ok((field, visits, restarted))
}

/// What [`manifold_part`] removed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CleanReport {
    /// Triangles removed: flipped against the input, on an edge of more
    /// than two triangles or of inconsistent orientation, or in a second
    /// fan around a vertex.
    pub removed_faces: usize,
    /// Samples left in no triangle, dropped from the output.
    pub dropped_vertices: usize,
}

/// The largest manifold part of a triangle soup: flipped faces removed,
/// then, until nothing changes, every edge of more than two faces or of two
/// faces in the same direction keeps only its first face and the first
/// one that runs the other way, and every vertex
/// keeps only its largest fan (faces around it connected through edges at
/// it). Vertices left in no face are dropped; returns the mesh, the old id
/// of each kept vertex and what was removed.
fn manifold_part(mesh: &TriMesh, flipped: &[bool]) -> (TriMesh, Vec<u32>, CleanReport) {
    let nv = mesh.num_vertices();
    let mut faces: Vec<[u32; 3]> = mesh
        .faces()
        .iter()
        .zip(flipped)
        .filter(|(_, &x)| !x)
        .map(|(f, _)| *f)
        .collect();
    let mut removed = mesh.num_faces() - faces.len();
    for _ in 0..64 {
        let mut drop = vec![false; faces.len()];
        // Edges: (smaller end, larger end, face, direction).
        let mut ends: Vec<(u32, u32, u32, bool)> = Vec::with_capacity(3 * faces.len());
        for (f, t) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                ends.push((a.min(b), a.max(b), f as u32, a < b));
            }
        }
        ends.sort_unstable();
        for group in ends.chunk_by(|x, y| x.0 == y.0 && x.1 == y.1) {
            let bad = group.len() > 2 || (group.len() == 2 && group[0].3 == group[1].3);
            if bad {
                // Keep the first face and the first one the other way.
                let partner = group[1..].iter().position(|e| e.3 != group[0].3);
                for (i, e) in group[1..].iter().enumerate() {
                    if Some(i) != partner {
                        drop[e.2 as usize] = true;
                    }
                }
            }
        }
        // Fans: the faces around each vertex, joined when they share an
        // edge at the vertex; all but the largest group go.
        let mut around: Vec<Vec<u32>> = vec![Vec::new(); nv];
        for (f, t) in faces.iter().enumerate() {
            if !drop[f] {
                for &v in t {
                    around[v as usize].push(f as u32);
                }
            }
        }
        for (v, fs) in around.iter().enumerate() {
            if fs.len() < 2 {
                continue;
            }
            let mut group: Vec<usize> = (0..fs.len()).collect();
            fn root(g: &mut [usize], mut i: usize) -> usize {
                while g[i] != i {
                    g[i] = g[g[i]];
                    i = g[i];
                }
                i
            }
            for i in 0..fs.len() {
                for j in i + 1..fs.len() {
                    let (p, q) = (faces[fs[i] as usize], faces[fs[j] as usize]);
                    let shares = p.iter().any(|&u| u as usize != v && q.contains(&u));
                    if shares {
                        let (ri, rj) = (root(&mut group, i), root(&mut group, j));
                        group[ri.max(rj)] = ri.min(rj);
                    }
                }
            }
            let mut size = vec![0usize; fs.len()];
            for i in 0..fs.len() {
                let r = root(&mut group, i);
                size[r] += 1;
            }
            let largest = (0..fs.len()).max_by_key(|&i| (size[i], usize::MAX - i));
            if let Some(largest) = largest {
                for i in 0..fs.len() {
                    if root(&mut group, i) != largest {
                        drop[fs[i] as usize] = true;
                    }
                }
            }
        }
        let before = faces.len();
        let mut k = 0;
        faces.retain(|_| {
            k += 1;
            !drop[k - 1]
        });
        removed += before - faces.len();
        if faces.len() == before {
            break;
        }
    }
    let mut new_id = vec![NONE; nv];
    let mut old_of_new = Vec::new();
    for t in &faces {
        for &v in t {
            if new_id[v as usize] == NONE {
                new_id[v as usize] = old_of_new.len() as u32;
                old_of_new.push(v);
            }
        }
    }
    // Keep the samples' order.
    old_of_new.sort_unstable();
    for (i, &v) in old_of_new.iter().enumerate() {
        new_id[v as usize] = i as u32;
    }
    let positions = old_of_new.iter().map(|&v| mesh.position(v)).collect();
    let faces = faces
        .iter()
        .map(|t| t.map(|v| new_id[v as usize]))
        .collect();
    let report = CleanReport {
        removed_faces: removed,
        dropped_vertices: nv - old_of_new.len(),
    };
    (
        TriMesh::from_parts_unchecked(positions, faces),
        old_of_new,
        report,
    )
}

/// Whether every edge has at most two faces traversing it in opposite
/// directions and every vertex's faces form one fan.
fn manifold_check(mesh: &TriMesh) -> bool {
    let topo = Topology::new(mesh);
    if topo.non_manifold_edges > 0 || topo.misoriented_edges > 0 {
        return false;
    }
    let mut link: Vec<Vec<(u32, u32)>> = vec![Vec::new(); mesh.num_vertices()];
    for f in mesh.faces() {
        for j in 0..3 {
            link[f[j] as usize].push((f[(j + 1) % 3], f[(j + 2) % 3]));
        }
    }
    link.iter().all(|edges| single_fan(edges))
}

/// The dual of the Voronoi labels and the cells at fault.
#[derive(Clone)]
struct Dual {
    mesh: TriMesh,
    /// Labels (indices into the samples) involved in a failure.
    bad: Vec<usize>,
    flipped: usize,
    /// Whether each face of `mesh` opposes the input face it came from.
    flipped_faces: Vec<bool>,
}

fn dual_triangulation(
    mesh: &TriMesh,
    labels: &[i32],
    samples: &[u32],
    face_normals: &[[f64; 3]],
) -> Dual {
    let k = samples.len();
    let positions: Vec<[f64; 3]> = samples.iter().map(|&s| mesh.position(s)).collect();
    let mut seen: HashMap<[u32; 3], ()> = HashMap::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    let mut bad = Vec::new();
    let mut flipped = 0;
    let mut flipped_faces = Vec::new();
    for (f, face) in mesh.faces().iter().enumerate() {
        let l = face.map(|v| labels[v as usize]);
        if l.iter().any(|&x| x < 0) || l[0] == l[1] || l[1] == l[2] || l[0] == l[2] {
            continue;
        }
        let t = l.map(|x| x as u32);
        let mut key = t;
        key.sort_unstable();
        if seen.insert(key, ()).is_some() {
            continue;
        }
        let nt = cross(
            sub(positions[t[1] as usize], positions[t[0] as usize]),
            sub(positions[t[2] as usize], positions[t[0] as usize]),
        );
        let opposed = dot(nt, face_normals[f]) <= 0.0;
        if opposed {
            flipped += 1;
            bad.extend(t.iter().map(|&x| x as usize));
        }
        faces.push(t);
        flipped_faces.push(opposed);
    }
    let out = TriMesh::from_parts_unchecked(positions, faces);
    // Vertex links: the edges opposite each vertex must chain into one fan.
    let mut link: Vec<Vec<(u32, u32)>> = vec![Vec::new(); k];
    for f in out.faces() {
        for j in 0..3 {
            link[f[j] as usize].push((f[(j + 1) % 3], f[(j + 2) % 3]));
        }
    }
    for (v, edges) in link.iter().enumerate() {
        if !single_fan(edges) {
            bad.push(v);
            bad.extend(edges.iter().flat_map(|&(a, b)| [a as usize, b as usize]));
        }
    }
    Dual {
        mesh: out,
        bad,
        flipped,
        flipped_faces,
    }
}

/// Whether the link edges `(a → b)` of a vertex form one cycle or one path
/// visiting each link vertex once (an empty link is a vertex in no triangle).
fn single_fan(edges: &[(u32, u32)]) -> bool {
    if edges.is_empty() {
        return false;
    }
    let mut next: HashMap<u32, u32> = HashMap::with_capacity(edges.len());
    let mut has_pred: HashMap<u32, bool> = HashMap::with_capacity(edges.len() + 1);
    for &(a, b) in edges {
        if next.insert(a, b).is_some() {
            return false;
        }
        if has_pred.insert(b, true) == Some(true) {
            return false;
        }
        has_pred.entry(a).or_insert(false);
    }
    let starts: Vec<u32> = has_pred
        .iter()
        .filter(|(_, &p)| !p)
        .map(|(&v, _)| v)
        .collect();
    let start = match starts.len() {
        0 => edges[0].0,
        1 => starts[0],
        _ => return false,
    };
    let mut cur = start;
    let mut steps = 0;
    while let Some(&b) = next.get(&cur) {
        steps += 1;
        cur = b;
        if cur == start || steps > edges.len() {
            break;
        }
    }
    steps == edges.len()
}

/// The farthest vertex of each cell and its distance (`NONE` for an empty cell).
fn cell_radius(field: &MeshDistance, k: usize) -> Vec<(u32, f64)> {
    let mut out = vec![(NONE, -1.0); k];
    for (v, (&l, &d)) in field.labels.iter().zip(&field.distance).enumerate() {
        if l >= 0 && (l as usize) < k && d.is_finite() && d > out[l as usize].1 {
            out[l as usize] = (v as u32, d);
        }
    }
    out
}

/// Lumped vertex areas: a third of the areas of the incident faces.
fn vertex_areas(mesh: &TriMesh) -> Vec<f64> {
    let mut a = vec![0.0; mesh.num_vertices()];
    for (f, face) in mesh.faces().iter().enumerate() {
        let third = mesh.face_area(f) / 3.0;
        for &v in face {
            a[v as usize] += third;
        }
    }
    a
}

/// `Σ_v A_v d(v)²` over the reached vertices.
fn energy(field: &MeshDistance, areas: &[f64]) -> f64 {
    field
        .distance
        .iter()
        .zip(areas)
        .filter(|(d, _)| d.is_finite())
        .map(|(d, a)| a * d * d)
        .sum()
}

/// One Lloyd move: each sample to the vertex of its cell nearest to the
/// cell's area-weighted centroid.
fn lloyd_step(mesh: &TriMesh, field: &MeshDistance, areas: &[f64], k: usize) -> Vec<u32> {
    let mut acc = vec![([0.0f64; 3], 0.0f64); k];
    for (v, &l) in field.labels.iter().enumerate() {
        if l < 0 {
            continue;
        }
        let p = mesh.position(v as u32);
        let e = &mut acc[l as usize];
        for (s, x) in e.0.iter_mut().zip(p) {
            *s += areas[v] * x;
        }
        e.1 += areas[v];
    }
    let centroids: Vec<[f64; 3]> = acc
        .iter()
        .map(|(s, a)| if *a > 0.0 { s.map(|x| x / a) } else { *s })
        .collect();
    let mut best = vec![(NONE, f64::INFINITY); k];
    for (v, &l) in field.labels.iter().enumerate() {
        if l < 0 {
            continue;
        }
        let d = norm(sub(mesh.position(v as u32), centroids[l as usize]));
        if d < best[l as usize].1 {
            best[l as usize] = (v as u32, d);
        }
    }
    best.iter().map(|b| b.0).collect()
}

/// The Voronoi cells of `samples` (labels index `samples`): one
/// multi-source march.
pub(super) fn voronoi(
    work: &mut MarchWork,
    mesh: &TriMesh,
    prep: &MarchPrep,
    samples: &[u32],
    w: Metric<'_>,
    control: &Control<'_>,
) -> Result<MeshDistance, MeshSolveError> {
    let n = mesh.num_vertices();
    let mut field = MeshDistance {
        distance: vec![f64::INFINITY; n],
        labels: vec![-1; n],
    };
    let seeds: Vec<Seed> = samples
        .iter()
        .enumerate()
        .filter(|(_, &s)| s != NONE)
        .map(|(i, &s)| Seed {
            vertex: s,
            distance: 0.0,
            label: i as i32,
        })
        .collect();
    march_metric(
        work,
        mesh,
        prep,
        &seeds,
        w,
        f64::INFINITY,
        &mut field,
        control,
    )?;
    Ok(field)
}

/// `W = 1 + λ κ / mean κ` (see the module docs).
fn curvature_weights(mesh: &TriMesh, topo: &Topology, strength: f64) -> Vec<f64> {
    let n = mesh.num_vertices();
    let mut normals = vec![[0.0f64; 3]; n];
    for face in mesh.faces() {
        let nf = face_normal(mesh, *face);
        for &v in face {
            for j in 0..3 {
                normals[v as usize][j] += nf[j];
            }
        }
    }
    let mut kappa = vec![0.0f64; n];
    for face in mesh.faces() {
        for j in 0..3 {
            let (v, u) = (face[j] as usize, face[(j + 1) % 3] as usize);
            let e = sub(mesh.position(u as u32), mesh.position(v as u32));
            let l2 = dot(e, e);
            for (a, b) in [(v, e), (u, e.map(|x| -x))] {
                let nn = norm(normals[a]);
                if l2 > 0.0 && nn > 0.0 {
                    let k = (2.0 * dot(normals[a], b) / nn).abs() / l2;
                    kappa[a] = kappa[a].max(k);
                }
            }
        }
    }
    // One pass of one-ring averaging (through the faces of each vertex).
    let smooth: Vec<f64> = (0..n)
        .map(|v| {
            let fs = topo.faces_of(v as u32);
            let (mut s, mut c) = (kappa[v], 1.0);
            for &f in fs {
                for &u in &mesh.faces()[f as usize] {
                    s += kappa[u as usize];
                    c += 1.0;
                }
            }
            s / c
        })
        .collect();
    let mean = smooth.iter().sum::<f64>() / n.max(1) as f64;
    smooth
        .iter()
        .map(|&k| {
            if mean > 0.0 {
                1.0 + strength * k / mean
            } else {
                1.0
            }
        })
        .collect()
}

/// Distance from `p` to the triangle `(a, b, c)`: the distance to its plane
/// when the projection falls inside (barycentric coordinates all `>= 0`),
/// else the distance to the nearest of its three edges (segments).
pub fn point_triangle_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (e0, e1) = (sub(b, a), sub(c, a));
    let nrm = cross(e0, e1);
    let n2 = dot(nrm, nrm);
    if n2 > 0.0 {
        let ap = sub(p, a);
        // Barycentric coordinates of the projection: u along e0, v along e1.
        let u = dot(cross(ap, e1), nrm) / n2;
        let v = dot(cross(e0, ap), nrm) / n2;
        if u >= 0.0 && v >= 0.0 && u + v <= 1.0 {
            return (dot(ap, nrm) / n2.sqrt()).abs();
        }
    }
    segment_distance(p, a, b)
        .min(segment_distance(p, b, c))
        .min(segment_distance(p, c, a))
}

/// Distance from `p` to the segment `[a, b]`: to `a + t (b − a)` with
/// `t = clamp((p − a)·(b − a) / |b − a|², 0, 1)`.
fn segment_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let e = sub(b, a);
    let l2 = dot(e, e);
    let t = if l2 > 0.0 {
        (dot(sub(p, a), e) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm(sub(p, [a[0] + t * e[0], a[1] + t * e[1], a[2] + t * e[2]]))
}

/// A uniform grid of a mesh's triangles for nearest-triangle queries.
struct TriangleGrid<'m> {
    mesh: &'m TriMesh,
    origin: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    offsets: Vec<u32>,
    items: Vec<u32>,
    /// Bounding sphere of each triangle (centroid, largest corner distance).
    spheres: Vec<([f64; 3], f64)>,
}

impl<'m> TriangleGrid<'m> {
    fn new(mesh: &'m TriMesh) -> Self {
        let (lo, hi) = bounds(mesh.positions());
        let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let diag = norm(ext).max(f64::MIN_POSITIVE);
        let nf = mesh.num_faces().max(1);
        // About one triangle per cell on a surface, at most ~4M cells.
        let mut cell = (2.0 * mesh.mean_edge_length()).max(diag * 1e-6);
        let count = |c: f64| ext.map(|e| (e / c).floor() as usize + 1);
        while count(cell).iter().product::<usize>() > (4 * nf).clamp(1, 4_000_000) {
            cell *= 1.5;
        }
        let dims = count(cell);
        let idx = |p: [f64; 3], j: usize| {
            (((p[j] - lo[j]) / cell).floor().max(0.0) as usize).min(dims[j] - 1)
        };
        let ncell = dims.iter().product::<usize>();
        let mut counts = vec![0u32; ncell + 1];
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for (f, face) in mesh.faces().iter().enumerate() {
            let ps = face.map(|v| mesh.position(v));
            let mn: [usize; 3] =
                std::array::from_fn(|j| idx([ps[0][j].min(ps[1][j]).min(ps[2][j]); 3], j));
            let mx: [usize; 3] =
                std::array::from_fn(|j| idx([ps[0][j].max(ps[1][j]).max(ps[2][j]); 3], j));
            for i in mn[0]..=mx[0] {
                for j in mn[1]..=mx[1] {
                    for k in mn[2]..=mx[2] {
                        let c = (i * dims[1] + j) * dims[2] + k;
                        counts[c + 1] += 1;
                        pairs.push((c as u32, f as u32));
                    }
                }
            }
        }
        for c in 0..ncell {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; pairs.len()];
        for (c, f) in pairs {
            items[fill[c as usize] as usize] = f;
            fill[c as usize] += 1;
        }
        let spheres = mesh
            .faces()
            .iter()
            .map(|face| {
                let ps = face.map(|v| mesh.position(v));
                let g: [f64; 3] = std::array::from_fn(|j| (ps[0][j] + ps[1][j] + ps[2][j]) / 3.0);
                let r = ps.iter().map(|&q| norm(sub(q, g))).fold(0.0f64, f64::max);
                (g, r)
            })
            .collect();
        Self {
            mesh,
            origin: lo,
            cell,
            dims,
            offsets: counts,
            items,
            spheres,
        }
    }

    /// Distance from `p` to the nearest triangle: blocks of cells growing
    /// around the cell of `p`, stopping once the best distance is within the
    /// distance from `p` to the outside of the block (a triangle registered
    /// in no visited cell has its bounding box, hence all its points,
    /// outside the block). Triangles whose bounding sphere is farther than
    /// the best so far are skipped.
    fn distance(&self, p: [f64; 3]) -> f64 {
        let c: [i64; 3] = std::array::from_fn(|j| {
            (((p[j] - self.origin[j]) / self.cell).floor() as i64).clamp(0, self.dims[j] as i64 - 1)
        });
        let maxr = *self.dims.iter().max().unwrap_or(&1) as i64;
        let mut best = f64::INFINITY;
        for r in 0..=maxr {
            for i in (c[0] - r)..=(c[0] + r) {
                for j in (c[1] - r)..=(c[1] + r) {
                    for k in (c[2] - r)..=(c[2] + r) {
                        let on_shell =
                            (i - c[0]).abs() == r || (j - c[1]).abs() == r || (k - c[2]).abs() == r;
                        if !on_shell
                            || i < 0
                            || j < 0
                            || k < 0
                            || i >= self.dims[0] as i64
                            || j >= self.dims[1] as i64
                            || k >= self.dims[2] as i64
                        {
                            continue;
                        }
                        let cell =
                            (i as usize * self.dims[1] + j as usize) * self.dims[2] + k as usize;
                        let (a, b) = (self.offsets[cell] as usize, self.offsets[cell + 1] as usize);
                        for &f in &self.items[a..b] {
                            let (centre, radius) = self.spheres[f as usize];
                            if norm(sub(p, centre)) - radius >= best {
                                continue;
                            }
                            let t = self.mesh.faces()[f as usize].map(|v| self.mesh.position(v));
                            best = best.min(point_triangle_distance(p, t[0], t[1], t[2]));
                        }
                    }
                }
            }
            // Distance from `p` to the outside of the block of cells
            // `c - r ..= c + r` (infinite on the sides where the block
            // reaches the end of the grid: nothing lies beyond them).
            let inside = (0..3)
                .map(|j| {
                    let lo_cell = c[j] - r;
                    let hi_cell = c[j] + r + 1;
                    let lo = if lo_cell <= 0 {
                        f64::INFINITY
                    } else {
                        p[j] - (self.origin[j] + lo_cell as f64 * self.cell)
                    };
                    let hi = if hi_cell >= self.dims[j] as i64 {
                        f64::INFINITY
                    } else {
                        self.origin[j] + hi_cell as f64 * self.cell - p[j]
                    };
                    lo.min(hi)
                })
                .fold(f64::INFINITY, f64::min);
            if best <= inside {
                break;
            }
        }
        best
    }
}

fn bounds(ps: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in ps {
        for j in 0..3 {
            lo[j] = lo[j].min(p[j]);
            hi[j] = hi[j].max(p[j]);
        }
    }
    (lo, hi)
}

/// Length of the diagonal of the bounding box of `mesh`'s vertices.
pub fn bounding_diagonal(mesh: &TriMesh) -> f64 {
    let (lo, hi) = bounds(mesh.positions());
    norm(sub(hi, lo))
}

/// Largest distance from the sample points of `from` (vertices, edge
/// midpoints, face centroids) to the surface `to`.
fn one_sided(from: &TriMesh, to: &TriMesh, control: &Control<'_>) -> Result<f64, RemeshError> {
    let grid = TriangleGrid::new(to);
    let mut worst = 0.0f64;
    for (i, p) in from.positions().iter().enumerate() {
        if i % 4096 == 0 && control.is_cancelled() {
            return Err(RemeshError::Cancelled);
        }
        worst = worst.max(grid.distance(*p));
    }
    for (f, face) in from.faces().iter().enumerate() {
        if f % 4096 == 0 && control.is_cancelled() {
            return Err(RemeshError::Cancelled);
        }
        let ps = face.map(|v| from.position(v));
        let mid = |a: [f64; 3], b: [f64; 3]| std::array::from_fn(|j| 0.5 * (a[j] + b[j]));
        let g = std::array::from_fn(|j| (ps[0][j] + ps[1][j] + ps[2][j]) / 3.0);
        for q in [g, mid(ps[0], ps[1]), mid(ps[1], ps[2]), mid(ps[2], ps[0])] {
            worst = worst.max(grid.distance(q));
        }
    }
    Ok(worst)
}

/// Symmetric Hausdorff distance between two surfaces, estimated at the
/// vertices, edge midpoints and face centroids of each (a lower bound of the
/// exact value, tight to the second order in the mesh size).
pub fn hausdorff_distance(
    a: &TriMesh,
    b: &TriMesh,
    control: &Control<'_>,
) -> Result<f64, RemeshError> {
    let ab = one_sided(a, b, control)?;
    control.report(0.5);
    let ba = one_sided(b, a, control)?;
    control.report(1.0);
    Ok(ab.max(ba))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::curvature::absolute_tensors;
    use crate::numerics::mesh::shapes::{flat_square, icosphere, torus};

    fn check_valid(r: &Remesh) {
        assert!(r.valid, "invalid output: {:?}", r.output_topology);
        assert_eq!(r.output_topology.non_manifold_edges, 0);
        assert_eq!(r.output_topology.misoriented_edges, 0);
        assert_eq!(r.flipped, 0);
        for w in r.energies.windows(2) {
            assert!(w[1] <= w[0], "energy increased: {:?}", r.energies);
        }
    }

    fn run(mesh: &TriMesh, count: usize, adaptation: Adaptation) -> (Remesh, f64) {
        let options = RemeshOptions {
            count,
            adaptation,
            ..Default::default()
        };
        let r = remesh(mesh, &options, &Control::new()).expect("remesh");
        let h = hausdorff_distance(mesh, &r.mesh, &Control::new()).expect("hausdorff");
        (r, h / bounding_diagonal(mesh))
    }

    #[test]
    fn point_triangle_distance_cases() {
        let (a, b, c) = ([0., 0., 0.], [1., 0., 0.], [0., 1., 0.]);
        assert!((point_triangle_distance([0.2, 0.2, 0.5], a, b, c) - 0.5).abs() < 1e-12);
        assert!((point_triangle_distance([2., 0., 0.], a, b, c) - 1.0).abs() < 1e-12);
        let d = point_triangle_distance([1., 1., 0.], a, b, c);
        assert!((d - 0.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn small_sphere_keeps_topology_and_energy_never_increases() {
        let mesh = icosphere(4, 1.0);
        // Geodesic Lloyd is off by default before the relaxation: ask for it.
        let options = RemeshOptions {
            count: 500,
            lloyd_iterations: Some(5),
            ..Default::default()
        };
        let r = remesh(&mesh, &options, &Control::new()).expect("remesh");
        let rel = hausdorff_distance(&mesh, &r.mesh, &Control::new()).expect("hausdorff")
            / bounding_diagonal(&mesh);
        assert!(r.lloyd_accepted >= 1, "{:?}", r.energies);
        assert_eq!(r.energies.len(), r.lloyd_accepted + 1);
        assert!(
            r.energies[r.lloyd_accepted] < r.energies[0],
            "{:?}",
            r.energies
        );
        check_valid(&r);
        assert!(
            r.topology_kept,
            "{:?} vs {:?}",
            r.output_topology, r.input_topology
        );
        assert_eq!(r.output_topology.genus, Some(0));
        assert!(rel < 0.02, "hausdorff {rel}");
    }

    /// The final relaxation: on an icosphere the output's smallest angles
    /// rise, every vertex stays on the input surface, the Hausdorff
    /// distance does not grow and the topology is kept.
    #[test]
    fn relaxation_regularises_the_triangles_on_the_surface() {
        let mesh = icosphere(5, 1.0);
        let options = |smoothing_iterations| RemeshOptions {
            count: 600,
            smoothing_iterations,
            ..Default::default()
        };
        let plain = remesh(&mesh, &options(Some(0)), &Control::new()).expect("remesh");
        let relaxed = remesh(&mesh, &options(None), &Control::new()).expect("remesh");
        assert_eq!(plain.relaxed, RelaxReport::default());
        assert_eq!(relaxed.relaxed.sweeps, default_smoothing_iterations(600));
        assert!(relaxed.relaxed.moves > 0 && relaxed.relaxed.flips > 0);
        check_valid(&relaxed);
        assert!(relaxed.topology_kept, "{:?}", relaxed.output_topology);
        let angles = |m: &TriMesh| -> Vec<f64> {
            m.faces()
                .iter()
                .map(|f| {
                    let p = f.map(|v| m.position(v));
                    crate::numerics::meshing::surface_relax::min_angle_sin(p[0], p[1], p[2])
                        .asin()
                        .to_degrees()
                })
                .collect()
        };
        let (a, b) = (angles(&plain.mesh), angles(&relaxed.mesh));
        let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
        let least = |x: &[f64]| x.iter().copied().fold(90.0, f64::min);
        println!(
            "mean smallest angle {:.2} -> {:.2}, least {:.2} -> {:.2}",
            mean(&a),
            mean(&b),
            least(&a),
            least(&b)
        );
        assert!(mean(&b) >= mean(&a) + 3.0);
        assert!(least(&b) >= 30.0);
        let grid = TriangleGrid::new(&mesh);
        for p in relaxed.mesh.positions() {
            assert!(grid.distance(*p) < 1e-9, "{p:?} off the surface");
        }
        let h = |m: &TriMesh| hausdorff_distance(&mesh, m, &Control::new()).expect("hausdorff");
        let (ha, hb) = (h(&plain.mesh), h(&relaxed.mesh));
        println!("hausdorff {ha:.3e} -> {hb:.3e}");
        assert!(hb <= ha, "{hb} > {ha}");
    }

    /// A soup with a fin (three triangles on one edge), a bow tie (two
    /// fans at one vertex), a flipped face and a lone vertex: its manifold
    /// part passes the checker, and the removals are counted.
    #[test]
    fn the_manifold_part_of_a_soup_is_manifold() {
        let positions = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.5, 0.5, 1.0],
            [-1.0, 1.0, 0.0],
            [-1.0, 2.0, 0.0],
            [5.0, 5.0, 5.0],
        ];
        let faces = vec![
            [0, 1, 2], // kept
            [1, 0, 3], // kept: shares edge 0-1 with the first
            [0, 1, 4], // a third face on 0-1, in the first's direction
            [2, 5, 6], // second fan at 2 (touches it by a vertex only)
            [3, 1, 0], // same triangle as the second, flipped
        ];
        let flipped = [false, false, false, false, true];
        let soup = TriMesh::from_parts_unchecked(positions, faces);
        assert!(!manifold_check(&soup));
        let (mesh, kept, report) = manifold_part(&soup, &flipped);
        assert!(manifold_check(&mesh), "{:?}", mesh.faces());
        assert_eq!(mesh.num_faces(), 2, "{:?}", mesh.faces());
        assert_eq!(report.removed_faces, 3);
        assert_eq!(kept, vec![0, 1, 2, 3]);
        assert_eq!(report.dropped_vertices, 4);
    }

    #[test]
    fn curvature_adapted_torus_keeps_genus() {
        let mesh = torus(120, 48, 1.0, 0.35);
        let (r, _) = run(&mesh, 800, Adaptation::Curvature { strength: 2.0 });
        check_valid(&r);
        assert!(r.topology_kept, "{:?}", r.output_topology);
        assert_eq!(r.output_topology.genus, Some(1));
    }

    #[test]
    fn flat_square_keeps_its_boundary() {
        let mesh = flat_square(60, 1.0, 0.0);
        let (r, _) = run(&mesh, 300, Adaptation::Uniform);
        assert_eq!(r.output_topology.misoriented_edges, 0);
        assert_eq!(r.output_topology.non_manifold_edges, 0);
        assert_eq!(r.input_topology.boundary_loops, 1);
    }

    /// The issue's bound: at 5,000 vertices the output keeps the genus and
    /// the components and lies within 0.5 % of the bounding-box diagonal.
    /// The clustered sampling (the default from 8 input vertices per
    /// sample) against the exact one on the same sphere: a fraction of the
    /// fronts' work, and a remesh as good (topology, angles, Hausdorff).
    #[test]
    fn clustered_sampling_remeshes_like_the_exact_one() {
        let mesh = icosphere(5, 1.0);
        let n = mesh.num_vertices();
        let run = |sampling| {
            let options = RemeshOptions {
                count: 400,
                sampling,
                ..Default::default()
            };
            let r = remesh(&mesh, &options, &Control::new()).expect("remesh");
            let h = hausdorff_distance(&mesh, &r.mesh, &Control::new()).expect("hausdorff");
            check_valid(&r);
            assert!(r.topology_kept, "{sampling:?}: {:?}", r.output_topology);
            let good = r
                .mesh
                .faces()
                .iter()
                .filter(|f| {
                    let p = f.map(|v| r.mesh.position(v));
                    crate::numerics::meshing::surface_relax::min_angle_sin(p[0], p[1], p[2]) >= 0.5
                })
                .count();
            (
                r.sampled,
                h / bounding_diagonal(&mesh),
                good as f64 / r.mesh.num_faces() as f64,
            )
        };
        let (clustered, h_clustered, good_clustered) = run(Sampling::Auto);
        let (exact, h_exact, good_exact) = run(Sampling::Exact);
        println!("clustered {clustered:?} {h_clustered:.5} {good_clustered:.4}");
        println!("exact {exact:?} {h_exact:.5} {good_exact:.4}");
        assert!(clustered.clustered && !clustered.restarted);
        assert!(clustered.clusters >= 400 * 3, "{clustered:?}");
        assert!(!exact.clustered && exact.clusters == 0);
        // Exact: about n (ln 400 + 0.58) = 6.6 n visits; clustered: < 2 n.
        assert!(exact.front_visits > 4 * n, "{exact:?}");
        assert!(clustered.front_visits < 2 * n, "{clustered:?}");
        assert!(
            h_clustered <= 1.25 * h_exact,
            "{h_clustered} against {h_exact}"
        );
        assert!(good_clustered >= 0.99 && good_exact >= 0.99);
    }

    /// One front per sample from the clusters' bound gives the cells of a
    /// single march from every sample at once, for about one march's
    /// visits; a bound below the distances (zero) stops every front, and
    /// then that single march is run instead.
    #[test]
    fn fronts_from_the_cluster_bound_give_the_cells_of_one_march() {
        let mesh = icosphere(5, 1.0);
        let n = mesh.num_vertices();
        let topo = Topology::new(&mesh);
        let prep = MarchPrep::new(&mesh, &topo);
        let graph = VertexGraph::new(&mesh);
        let c = cluster_sampling(&mesh, &graph, None, 200, &Control::new()).expect("sampling");
        let w = Metric::Weights(None);
        let mut work = MarchWork::new(n);
        let one = voronoi(&mut work, &mesh, &prep, &c.samples, w, &Control::new()).expect("march");
        let radius = one.distance.iter().copied().fold(0.0, f64::max);
        let (f, visits, restarted) = cells_from_bound(
            &mut work,
            &mesh,
            &prep,
            &c.samples,
            c.bound.clone(),
            w,
            &Control::new(),
        )
        .expect("fronts");
        assert!(!restarted);
        assert!(visits < 2 * n, "{visits} visits for {n} vertices");
        let agree = (0..n).filter(|&v| f.labels[v] == one.labels[v]).count();
        assert!(
            agree as f64 >= 0.98 * n as f64,
            "{agree} of {n} labels agree"
        );
        for v in 0..n {
            assert!(f.labels[v] >= 0);
            assert!(
                one.distance[v] <= c.bound[v],
                "the bound is below the distance at {v}"
            );
            let gap = (f.distance[v] - one.distance[v]).abs();
            assert!(
                gap <= 0.03 * radius,
                "vertex {v}: {} against {}",
                f.distance[v],
                one.distance[v]
            );
        }
        let (z, _, restarted) = cells_from_bound(
            &mut work,
            &mesh,
            &prep,
            &c.samples,
            vec![0.0; n],
            w,
            &Control::new(),
        )
        .expect("fronts");
        assert!(restarted);
        assert_eq!(z, one);
    }

    /// Fewer samples than components: the components without one keep
    /// `+inf` and label -1, as under exact sampling, without a restart.
    #[test]
    fn components_without_a_sample_stay_unreached() {
        let sphere = icosphere(3, 1.0);
        let ns = sphere.num_vertices() as u32;
        let mut positions = Vec::new();
        let mut faces = Vec::new();
        for c in 0..6u32 {
            positions.extend(
                sphere
                    .positions()
                    .iter()
                    .map(|p| [p[0] + 5.0 * c as f64, p[1], p[2]]),
            );
            faces.extend(sphere.faces().iter().map(|f| f.map(|v| v + c * ns)));
        }
        let mesh = TriMesh::from_parts_unchecked(positions, faces);
        let n = mesh.num_vertices();
        let topo = Topology::new(&mesh);
        let prep = MarchPrep::new(&mesh, &topo);
        let graph = VertexGraph::new(&mesh);
        let c = cluster_sampling(&mesh, &graph, None, 4, &Control::new()).expect("sampling");
        let mut hit: Vec<u32> = c.samples.iter().map(|&v| v / ns).collect();
        hit.sort_unstable();
        hit.dedup();
        assert_eq!(hit.len(), 4, "one sample in each of four components");
        let (f, _, restarted) = cells_from_bound(
            &mut MarchWork::new(n),
            &mesh,
            &prep,
            &c.samples,
            c.bound,
            Metric::Weights(None),
            &Control::new(),
        )
        .expect("fronts");
        assert!(!restarted);
        for v in 0..n {
            let sampled = hit.contains(&(v as u32 / ns));
            assert_eq!(f.labels[v] >= 0, sampled, "vertex {v}");
            assert_eq!(f.distance[v].is_finite(), sampled, "vertex {v}");
        }
    }

    #[test]
    fn clustered_sampling_is_refused_under_a_tensor_metric() {
        let options = RemeshOptions {
            count: 100,
            adaptation: Adaptation::Anisotropic { max_ratio: 3.0 },
            sampling: Sampling::Clustered,
            ..Default::default()
        };
        let err = remesh(&icosphere(3, 1.0), &options, &Control::new()).unwrap_err();
        assert!(
            matches!(
                err,
                RemeshError::InvalidOption {
                    option: "sampling",
                    ..
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn five_thousand_vertices_on_sphere_and_torus() {
        let sphere = icosphere(6, 1.0);
        let torus = torus(300, 120, 1.0, 0.4);
        for (mesh, genus) in [(sphere, 0), (torus, 1)] {
            let started = std::time::Instant::now();
            let (r, rel) = run(&mesh, 5000, Adaptation::Uniform);
            println!(
                "genus {genus}: {} vertices ({} added in {} rounds), hausdorff/diag {rel:.5}, energies {:?}, {:.2} s",
                r.mesh.num_vertices(),
                r.added,
                r.repair_rounds,
                r.energies,
                started.elapsed().as_secs_f64()
            );
            check_valid(&r);
            assert!(r.topology_kept, "{:?}", r.output_topology);
            assert_eq!(r.output_topology.genus, Some(genus));
            assert_eq!(r.output_topology.components, 1);
            assert!(rel <= 0.005, "hausdorff / diagonal = {rel}");
        }
    }

    /// Cell shape on the open cylinder of radius 1 (a 160-sided prism,
    /// height 8): principal curvatures 1 around and 0 along the axis, so
    /// the anisotropic cells are `max_ratio` = 3 times longer along the axis
    /// than around it, the uniform ones about as long as wide. Measured by
    /// the second moments of each cell's vertices along the axis (`z`) and
    /// around it (arc length), median over the cells away from the rims.
    #[test]
    fn anisotropic_cells_are_elongated_along_the_cylinder_axis() {
        let (sides, rings, height) = (160usize, 200usize, 8.0);
        let mesh = crate::numerics::mesh::shapes::prism(sides, rings, 1.0, height);
        let ratio = |adaptation: Adaptation| {
            let options = RemeshOptions {
                count: 400,
                adaptation,
                ..Default::default()
            };
            let r = remesh(&mesh, &options, &Control::new()).expect("remesh");
            assert_eq!(r.output_topology.non_manifold_edges, 0);
            assert_eq!(r.output_topology.misoriented_edges, 0);
            assert!(r.valid, "{:?}", r.output_topology);
            assert!(
                r.topology_kept,
                "{:?} vs {:?}",
                r.output_topology, r.input_topology
            );
            // Per cell: Σ dz², Σ ds² around the sample (s = arc length).
            let k = r.samples.len();
            let mut m = vec![(0.0f64, 0.0f64, 0usize); k];
            // Cells of the final samples: one multi-source march.
            let tensors = match adaptation {
                Adaptation::Anisotropic { max_ratio } => Some(face_tensors_from_curvature(
                    &mesh,
                    &Topology::new(&mesh),
                    max_ratio,
                )),
                _ => None,
            };
            let prep = match &tensors {
                Some(t) => MarchPrep::with_tensors(&mesh, &Topology::new(&mesh), t),
                None => MarchPrep::new(&mesh, &Topology::new(&mesh)),
            };
            let metric = tensors
                .as_deref()
                .map_or(Metric::Weights(None), Metric::Faces);
            let mut work = MarchWork::new(mesh.num_vertices());
            let field = voronoi(&mut work, &mesh, &prep, &r.samples, metric, &Control::new())
                .expect("voronoi");
            for (v, &l) in field.labels.iter().enumerate() {
                let (p, s) = (
                    mesh.position(v as u32),
                    mesh.position(r.samples[l as usize]),
                );
                let dz = p[2] - s[2];
                let mut da = p[1].atan2(p[0]) - s[1].atan2(s[0]);
                if da > std::f64::consts::PI {
                    da -= std::f64::consts::TAU;
                } else if da < -std::f64::consts::PI {
                    da += std::f64::consts::TAU;
                }
                let e = &mut m[l as usize];
                e.0 += dz * dz;
                e.1 += da * da;
                e.2 += 1;
            }
            let mut ratios: Vec<f64> = (0..k)
                .filter(|&i| {
                    let z = mesh.position(r.samples[i])[2];
                    z > 1.5 && z < height - 1.5 && m[i].1 > 0.0
                })
                .map(|i| (m[i].0 / m[i].1).sqrt())
                .collect();
            ratios.sort_by(f64::total_cmp);
            ratios[ratios.len() / 2]
        };
        let uniform = ratio(Adaptation::Uniform);
        let aniso = ratio(Adaptation::Anisotropic { max_ratio: 3.0 });
        println!("median length/width: uniform {uniform:.3}, anisotropic {aniso:.3}");
        assert!((0.75..=1.33).contains(&uniform), "uniform {uniform}");
        assert!((2.2..=3.8).contains(&aniso), "anisotropic {aniso}");
    }

    /// On a sphere all directions curve alike: the anisotropic metric is
    /// isotropic there, and the remeshing keeps the genus.
    #[test]
    fn anisotropic_sphere_keeps_topology() {
        let mesh = icosphere(4, 1.0);
        let (r, rel) = run(&mesh, 500, Adaptation::Anisotropic { max_ratio: 3.0 });
        check_valid(&r);
        assert!(r.topology_kept, "{:?}", r.output_topology);
        assert!(rel < 0.02, "hausdorff {rel}");
    }

    #[test]
    fn principal_curvatures_of_a_cylinder() {
        let mesh = crate::numerics::mesh::shapes::prism(120, 60, 2.0, 6.0);
        let t = absolute_tensors(&mesh, &Topology::new(&mesh));
        // A vertex away from the rims: |II| = (1/R) θθᵀ, θ the tangent around.
        let v = 30 * 120 + 7;
        let p = mesh.position(v as u32);
        let theta = [-p[1] / 2.0, p[0] / 2.0, 0.0];
        let around = crate::numerics::mesh::fast_marching::tensor_form(&t[v], theta, theta);
        let along =
            crate::numerics::mesh::fast_marching::tensor_form(&t[v], [0., 0., 1.], [0., 0., 1.]);
        assert!((around - 0.5).abs() < 0.02, "around {around}");
        assert!(along.abs() < 0.02, "along {along}");
    }

    #[test]
    fn refuses_bad_input() {
        let mesh = icosphere(1, 1.0);
        let too_many = RemeshOptions {
            count: mesh.num_vertices() + 1,
            ..Default::default()
        };
        assert!(matches!(
            remesh(&mesh, &too_many, &Control::new()),
            Err(RemeshError::InvalidOption {
                option: "count",
                ..
            })
        ));
        let pos = vec![
            [0., 0., 0.],
            [1., 0., 0.],
            [0., 1., 0.],
            [0., 0., 1.],
            [1., 1., 1.],
        ];
        let faces = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        let bowtie = TriMesh::from_parts_unchecked(pos, faces);
        let opts = RemeshOptions {
            count: 4,
            ..Default::default()
        };
        assert!(matches!(
            remesh(&bowtie, &opts, &Control::new()),
            Err(RemeshError::NonManifold { .. })
        ));
    }

    #[test]
    fn a_raised_flag_stops_it() {
        let mesh = icosphere(3, 1.0);
        let flag = std::sync::atomic::AtomicBool::new(true);
        let control = Control::new().with_cancel(&flag);
        let options = RemeshOptions {
            count: 100,
            ..Default::default()
        };
        let r = remesh(&mesh, &options, &control);
        assert!(matches!(r, Err(RemeshError::Cancelled)), "{r:?}");
    }
}
