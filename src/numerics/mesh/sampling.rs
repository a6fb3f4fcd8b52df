//! Farthest-point sampling on a surface (Peyré & Cohen 2006) and the
//! geodesic Voronoi cells of the samples.
//!
//! Start from a vertex, then repeatedly add the vertex farthest from the
//! samples so far, until `count` samples are placed or every vertex lies
//! within `radius` of a sample. With fast marching or Dijkstra each new
//! sample costs one *local* march: the front only visits the vertices that
//! get closer to the new sample (its Voronoi cell), so sampling `k` points
//! costs about `O(n log n · log k)` on a well-spread set rather than `k`
//! full solves. With the heat method (or the exact method) each sample is a
//! full solve merged by minimum.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::fast_marching::{check_tensors, march_metric, MarchPrep, MarchWork, Metric};
use super::heat::HeatSolver;
use super::solve::{mesh_distance, MeshDistanceOptions, MeshMethod};
use super::sources::{check_weights, seeds, VertexGraph};
use super::{norm, sub, MeshDistance, MeshSolveError, SurfacePoint, Topology, TriMesh};
use crate::numerics::heap::IndexedHeap;
use crate::numerics::Control;

/// Options of [`farthest_point_sampling`].
#[derive(Debug, Clone, Copy)]
pub struct SamplingOptions {
    /// Stop after this many samples.
    pub count: Option<usize>,
    /// Stop once every reachable vertex is within this distance of a sample.
    pub radius: Option<f64>,
    /// First sample (default: the vertex farthest from vertex 0).
    pub first: Option<u32>,
    /// Distance method (fast marching by default).
    pub method: MeshMethod,
}

impl Default for SamplingOptions {
    fn default() -> Self {
        Self {
            count: Some(100),
            radius: None,
            first: None,
            method: MeshMethod::FastMarching,
        }
    }
}

/// Samples, their Voronoi cells and the distance to the nearest sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Sampling {
    /// Sample vertices, in the order they were chosen.
    pub samples: Vec<u32>,
    /// Distance to the nearest sample; labels index `samples`.
    pub field: MeshDistance,
    /// Largest finite distance to a sample at the end (the covering radius).
    pub covering_radius: f64,
}

/// Farthest-point sampling; see the module docs.
pub fn farthest_point_sampling(
    mesh: &TriMesh,
    topo: &Topology,
    options: &SamplingOptions,
    heat: Option<&HeatSolver>,
    control: &Control<'_>,
) -> Result<Sampling, MeshSolveError> {
    farthest_point_sampling_in(mesh, topo, options, Metric::Weights(None), heat, control)
}

/// [`farthest_point_sampling`] under a metric: per-vertex weights `W` (the
/// covering radius is then in `W`-lengths, so samples are denser where `W`
/// is large) or one tensor per face (cells stretched by the metric). Any
/// metric but `W = 1` needs [`MeshMethod::FastMarching`].
pub fn farthest_point_sampling_in(
    mesh: &TriMesh,
    topo: &Topology,
    options: &SamplingOptions,
    metric: Metric<'_>,
    heat: Option<&HeatSolver>,
    control: &Control<'_>,
) -> Result<Sampling, MeshSolveError> {
    let n = mesh.num_vertices();
    let plain = matches!(metric, Metric::Weights(None));
    if !plain && options.method != MeshMethod::FastMarching {
        return Err(MeshSolveError::InvalidOption {
            option: "metric",
            reason: "a metric other than W = 1 needs fast_marching".into(),
        });
    }
    match metric {
        Metric::Weights(w) => check_weights(mesh, w)?,
        Metric::Faces(t) => check_tensors(mesh, t)?,
    }
    if options.count.is_none() && options.radius.is_none() {
        return Err(MeshSolveError::InvalidOption {
            option: "count",
            reason: "give a count, a radius or both".into(),
        });
    }
    if options.count == Some(0) {
        return Err(MeshSolveError::InvalidOption {
            option: "count",
            reason: "must be >= 1".into(),
        });
    }
    if let Some(r) = options.radius {
        if !(r.is_finite() && r > 0.0) {
            return Err(MeshSolveError::InvalidOption {
                option: "radius",
                reason: "must be finite and > 0".into(),
            });
        }
    }
    let cap = options.count.unwrap_or(n).min(n);
    let first = match options.first {
        Some(v) if (v as usize) < n => v,
        Some(v) => {
            return Err(MeshSolveError::InvalidSource {
                index: 0,
                reason: format!("vertex {v} does not exist (the mesh has {n} vertices)"),
            })
        }
        None => {
            let d = super::dijkstra::dijkstra_distance(
                mesh,
                &[SurfacePoint::Vertex(0)],
                None,
                f64::INFINITY,
                control,
            )?;
            argmax(&d.distance).map_or(0, |(v, _)| v)
        }
    };
    let mut field = MeshDistance {
        distance: vec![f64::INFINITY; n],
        labels: vec![-1; n],
    };
    let prep = matches!(options.method, MeshMethod::FastMarching).then(|| match metric {
        Metric::Faces(t) => MarchPrep::with_tensors(mesh, topo, t),
        Metric::Weights(_) => MarchPrep::new(mesh, topo),
    });
    let graph = matches!(
        options.method,
        MeshMethod::Dijkstra | MeshMethod::FastMarching
    )
    .then(|| VertexGraph::new(mesh));
    // Each per-sample solve polls the caller's flags (deadline, client gone,
    // job cancel); progress is reported per sample below.
    let inner = control.cancel_only();
    let mut samples = Vec::new();
    let mut next = first;
    let mut work = prep.as_ref().map(|_| MarchWork::new(n));
    let mut dheap = graph.as_ref().map(|_| IndexedHeap::new(n));
    let mut queue = FarthestQueue::new(&field.distance);
    let mut changed: Vec<u32> = Vec::new();
    loop {
        if control.is_cancelled() {
            return Err(MeshSolveError::Cancelled);
        }
        let label = samples.len() as i32;
        samples.push(next);
        let src = [SurfacePoint::Vertex(next)];
        match (&prep, &graph) {
            (Some(prep), _) => {
                let mut s = seeds(mesh, &src, None)?;
                s[0].label = label;
                if let (Some(work), Some(graph)) = (work.as_mut(), graph.as_ref()) {
                    march_metric(
                        work,
                        mesh,
                        prep,
                        &s,
                        metric,
                        f64::INFINITY,
                        &mut field,
                        &inner,
                    )?;
                    queue.lowered_on(graph, work.changed(), &field.distance);
                }
            }
            (_, Some(graph)) => {
                if let Some(heap) = dheap.as_mut() {
                    changed.clear();
                    local_dijkstra(mesh, graph, heap, next, label, &mut field, &mut changed);
                    queue.lowered_on(graph, &changed, &field.distance);
                }
            }
            _ => {
                let d = mesh_distance(
                    mesh,
                    topo,
                    &src,
                    &MeshDistanceOptions {
                        method: options.method,
                        ..Default::default()
                    },
                    heat,
                    &inner,
                )?;
                changed.clear();
                for v in 0..n {
                    if d.distance[v] < field.distance[v] {
                        field.distance[v] = d.distance[v];
                        field.labels[v] = label;
                        changed.push(v as u32);
                    }
                }
                queue.lowered(&changed, &field.distance);
            }
        }
        control.report(samples.len() as f64 / cap as f64);
        let Some((v, d)) = queue.farthest(&field.distance) else {
            break;
        };
        if samples.len() >= cap || options.radius.is_some_and(|r| d <= r) || d <= 0.0 {
            break;
        }
        next = v;
    }
    let covering_radius = field
        .distance
        .iter()
        .filter(|x| x.is_finite())
        .fold(0.0f64, |a, &b| a.max(b));
    Ok(Sampling {
        samples,
        field,
        covering_radius,
    })
}

/// The vertex with the largest distance (`+inf` first: unreached components
/// are sampled before anything else; the lowest index among equals).
fn argmax(d: &[f64]) -> Option<(u32, f64)> {
    let mut best: Option<(u32, f64)> = None;
    for (v, &x) in d.iter().enumerate() {
        if !x.is_nan() && best.is_none_or(|b| x > b.1) {
            best = Some((v as u32, x));
        }
    }
    best
}

/// The bits of `d` as an integer with the order of `d` (IEEE 754 total order).
#[inline]
fn ordered(d: f64) -> i64 {
    let b = d.to_bits() as i64;
    b ^ (((b >> 63) as u64) >> 1) as i64
}

/// The farthest vertex of a distance field whose entries only decrease: a
/// lazy max-heap of `(distance, vertex)` in which a lowered vertex is pushed
/// again and an entry is dropped when popped if it no longer matches the
/// field. The answer is that of a scan (the largest distance,
/// `+inf` first, the lowest index among equals), in `O(log n)` amortised
/// per lowered vertex instead of `O(n)` per query.
///
/// # Examples
/// ```
/// use geodex::numerics::mesh::sampling::FarthestQueue;
/// let mut d = vec![f64::INFINITY; 4];
/// let mut q = FarthestQueue::new(&d);
/// assert_eq!(q.farthest(&d), Some((0, f64::INFINITY)));
/// d[0] = 0.0;
/// d[1] = 2.0;
/// d[2] = 3.0;
/// d[3] = 3.0;
/// q.lowered(&[0, 1, 2, 3], &d);
/// assert_eq!(q.farthest(&d), Some((2, 3.0)));
/// ```
#[derive(Debug, Clone, Default)]
pub struct FarthestQueue {
    heap: BinaryHeap<(i64, Reverse<u32>)>,
    /// Per-vertex stamp of [`FarthestQueue::lowered_on`] (tested this round).
    seen: Vec<u32>,
    round: u32,
    /// Vertex count (the heap is rebuilt when it holds twice as many
    /// entries: a smaller heap stays in cache, and a rebuild drops the stale
    /// entries without popping them one by one).
    n: usize,
}

impl FarthestQueue {
    /// A queue over every non-NaN entry of `distance`.
    pub fn new(distance: &[f64]) -> Self {
        let mut q = Self {
            heap: BinaryHeap::new(),
            seen: Vec::new(),
            round: 0,
            n: distance.len(),
        };
        q.rebuild(distance);
        q
    }

    fn rebuild(&mut self, distance: &[f64]) {
        let entries: Vec<(i64, Reverse<u32>)> = distance
            .iter()
            .enumerate()
            .filter(|(_, x)| !x.is_nan())
            .map(|(v, &x)| (ordered(x), Reverse(v as u32)))
            .collect();
        self.heap = BinaryHeap::from(entries);
    }

    /// Records that the entries of `vertices` in `distance` were lowered.
    pub fn lowered(&mut self, vertices: &[u32], distance: &[f64]) {
        if self.heap.len() + vertices.len() > 2 * self.n.max(16) {
            self.rebuild(distance);
            return;
        }
        for &v in vertices {
            let x = distance[v as usize];
            if !x.is_nan() {
                self.heap.push((ordered(x), Reverse(v)));
            }
        }
    }

    /// [`FarthestQueue::lowered`] on a mesh, pushing only the vertices that
    /// may have become weak local maxima of `distance` over `graph` (the
    /// lowered ones and their neighbours, each kept if no neighbour is
    /// larger): the largest entry is a weak local maximum, and a vertex
    /// becomes one only when it or a neighbour is lowered, so the answer is
    /// unchanged while the heap holds a few entries per front instead of
    /// every vertex the front lowered.
    pub fn lowered_on(&mut self, graph: &VertexGraph, vertices: &[u32], distance: &[f64]) {
        if self.seen.len() != distance.len() {
            self.seen = vec![0; distance.len()];
            self.round = 0;
        }
        self.round = self.round.wrapping_add(1);
        if self.round == 0 {
            self.seen.fill(0);
            self.round = 1;
        }
        let round = self.round;
        let local_max = |v: u32| {
            let x = distance[v as usize];
            graph.of(v).iter().all(|&u| distance[u as usize] <= x)
        };
        let mut pushed = 0usize;
        for &v in vertices {
            for &w in std::iter::once(&v).chain(graph.of(v)) {
                if self.seen[w as usize] == round {
                    continue;
                }
                self.seen[w as usize] = round;
                let x = distance[w as usize];
                if !x.is_nan() && local_max(w) {
                    self.heap.push((ordered(x), Reverse(w)));
                    pushed += 1;
                }
            }
        }
        if self.heap.len() > 2 * self.n.max(16) && pushed > 0 {
            self.rebuild(distance);
        }
    }

    /// The vertex with the largest entry of `distance` and that entry.
    pub fn farthest(&mut self, distance: &[f64]) -> Option<(u32, f64)> {
        while let Some(&(key, Reverse(v))) = self.heap.peek() {
            let x = distance[v as usize];
            if ordered(x) == key {
                return Some((v, x));
            }
            self.heap.pop();
        }
        None
    }
}

fn local_dijkstra(
    mesh: &TriMesh,
    graph: &VertexGraph,
    heap: &mut IndexedHeap,
    s: u32,
    label: i32,
    f: &mut MeshDistance,
    changed: &mut Vec<u32>,
) {
    heap.clear();
    f.distance[s as usize] = 0.0;
    f.labels[s as usize] = label;
    changed.push(s);
    heap.push(s, 0.0);
    while let Some((v, d)) = heap.pop() {
        let pv = mesh.position(v);
        for &u in graph.of(v) {
            let c = d + norm(sub(mesh.position(u), pv));
            if c < f.distance[u as usize] {
                f.distance[u as usize] = c;
                f.labels[u as usize] = label;
                changed.push(u);
                heap.push_or_decrease(u, c);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::shapes::icosphere;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    /// The queue answers like a scan after arbitrary decreases.
    #[test]
    fn farthest_queue_matches_a_scan() {
        let n = 500;
        let mut d = vec![f64::INFINITY; n];
        let mut q = FarthestQueue::new(&d);
        let mut state = 12345u64;
        for step in 0..5000 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = (state >> 33) as usize % n;
            let x = ((state >> 13) % 1000) as f64 / 10.0;
            if x < d[v] {
                d[v] = x;
                q.lowered(&[v as u32], &d);
            }
            if step % 7 == 0 {
                assert_eq!(q.farthest(&d), argmax(&d), "step {step}");
            }
        }
    }

    /// One sample (`count: 1`, first given) runs exactly one per-sample solve
    /// and then stops without polling again: the run can only end in
    /// `Cancelled` if that solve itself polled the caller's flag, raised 5 ms
    /// into it (the exact solve of a 10k-vertex sphere takes far longer). A
    /// fresh `Control::new()` there used to ignore the flag, freezing a pool
    /// thread for the whole solve.
    #[test]
    fn a_per_sample_solve_polls_the_callers_flag() {
        let mesh = icosphere(5, 1.0);
        let topo = Topology::new(&mesh);
        let flag = Arc::new(AtomicBool::new(false));
        let raise = Arc::clone(&flag);
        let raiser = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(5));
            raise.store(true, Ordering::Relaxed);
        });
        let options = SamplingOptions {
            count: Some(1),
            radius: None,
            first: Some(0),
            method: MeshMethod::Exact,
        };
        let control = Control::new().with_cancel(&flag);
        let r = farthest_point_sampling(&mesh, &topo, &options, None, &control);
        raiser.join().expect("raiser");
        assert!(matches!(r, Err(MeshSolveError::Cancelled)), "{r:?}");
    }

    /// Under `W = 3` on the half `x > 0.5` of the square, the covering
    /// radius is uniform in `W`-lengths, so that half holds about nine
    /// times as many samples per area: at least three quarters of them.
    #[test]
    fn weights_make_samples_denser() {
        let mesh = crate::numerics::mesh::shapes::flat_square(40, 1.0, 0.0);
        let topo = Topology::new(&mesh);
        let w: Vec<f64> = mesh
            .positions()
            .iter()
            .map(|p| if p[0] > 0.5 { 3.0 } else { 1.0 })
            .collect();
        let options = SamplingOptions {
            count: Some(60),
            ..Default::default()
        };
        let s = farthest_point_sampling_in(
            &mesh,
            &topo,
            &options,
            Metric::Weights(Some(&w)),
            None,
            &Control::new(),
        )
        .unwrap();
        let right = s
            .samples
            .iter()
            .filter(|&&v| mesh.position(v)[0] > 0.5)
            .count();
        assert!(right >= 45, "{right} of 60 on the heavy half");
        let dijkstra = SamplingOptions {
            method: MeshMethod::Dijkstra,
            ..options
        };
        assert!(farthest_point_sampling_in(
            &mesh,
            &topo,
            &dijkstra,
            Metric::Weights(Some(&w)),
            None,
            &Control::new()
        )
        .is_err());
    }
}
