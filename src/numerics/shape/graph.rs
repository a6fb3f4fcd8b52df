//! Weighted undirected graphs in CSR form and their shortest-path distance
//! rows (Dijkstra), computed many sources at a time in parallel.
//!
//! `d(s, v) = min over paths s = v₀ … v_m = v of Σ w(v_{i-1}, v_i)`, solved
//! per source with an indexed binary heap in `O(E log V)`. The k-nearest-
//! neighbour graph of a point cloud (Isomap) and the edge graph of a mesh
//! (the Dijkstra baseline) are both such graphs.

use ndarray::{Array2, Axis};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

use super::ShapeError;
use crate::numerics::heap::IndexedHeap;
use crate::numerics::Control;

/// A weighted undirected graph: the neighbours of `v` are
/// `targets[offsets[v]..offsets[v + 1]]` with the edge lengths in `weights`.
#[derive(Debug, Clone, PartialEq)]
pub struct Graph {
    /// Row offsets (`n + 1`).
    pub offsets: Vec<u32>,
    /// Neighbour of each entry.
    pub targets: Vec<u32>,
    /// Length of each entry's edge (finite, >= 0).
    pub weights: Vec<f64>,
}

impl Graph {
    /// The graph with the undirected edges `(a, b, w)`: each edge is stored
    /// both ways, and of repeated edges the shortest is kept.
    pub fn from_edges(n: usize, edges: &[(u32, u32, f64)]) -> Self {
        let mut pairs: Vec<(u32, u32, f64)> = Vec::with_capacity(2 * edges.len());
        for &(a, b, w) in edges {
            if a != b {
                pairs.push((a, b, w));
                pairs.push((b, a, w));
            }
        }
        pairs.sort_unstable_by(|x, y| (x.0, x.1).cmp(&(y.0, y.1)).then(x.2.total_cmp(&y.2)));
        pairs.dedup_by_key(|p| (p.0, p.1));
        let mut offsets = vec![0u32; n + 1];
        for &(a, _, _) in &pairs {
            offsets[a as usize + 1] += 1;
        }
        for v in 0..n {
            offsets[v + 1] += offsets[v];
        }
        Self {
            offsets,
            targets: pairs.iter().map(|p| p.1).collect(),
            weights: pairs.iter().map(|p| p.2).collect(),
        }
    }

    /// Number of vertices.
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// True for the graph without vertices.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The neighbours of `v` and the lengths of the edges to them.
    #[inline]
    pub fn of(&self, v: u32) -> (&[u32], &[f64]) {
        let (a, b) = (
            self.offsets[v as usize] as usize,
            self.offsets[v as usize + 1] as usize,
        );
        (&self.targets[a..b], &self.weights[a..b])
    }

    /// Connected component of every vertex (`0..count`) and their count.
    pub fn components(&self) -> (Vec<u32>, usize) {
        let n = self.len();
        let mut comp = vec![u32::MAX; n];
        let mut count = 0u32;
        let mut stack = Vec::new();
        for s in 0..n {
            if comp[s] != u32::MAX {
                continue;
            }
            comp[s] = count;
            stack.push(s as u32);
            while let Some(v) = stack.pop() {
                for &u in self.of(v).0 {
                    if comp[u as usize] == u32::MAX {
                        comp[u as usize] = count;
                        stack.push(u);
                    }
                }
            }
            count += 1;
        }
        (comp, count as usize)
    }

    /// Single-source shortest-path distances into `out` (`+inf` where
    /// unreachable). Polls `control` every 4096 settled vertices.
    pub fn dijkstra_into(
        &self,
        source: u32,
        out: &mut [f64],
        control: &Control<'_>,
    ) -> Result<(), ShapeError> {
        out.fill(f64::INFINITY);
        let mut heap = IndexedHeap::new(self.len());
        out[source as usize] = 0.0;
        heap.push(source, 0.0);
        let mut count = 0usize;
        while let Some((v, d)) = heap.pop() {
            count += 1;
            if count.is_multiple_of(4096) && control.is_cancelled() {
                return Err(ShapeError::Cancelled);
            }
            let (t, w) = self.of(v);
            for (&u, &l) in t.iter().zip(w) {
                let c = d + l;
                if c < out[u as usize] {
                    out[u as usize] = c;
                    heap.push_or_decrease(u, c);
                }
            }
        }
        Ok(())
    }

    /// Farthest-point landmarks: the vertex farthest from vertex 0 first,
    /// then repeatedly the vertex farthest from the landmarks so far. Each
    /// new landmark runs a *local* Dijkstra that only visits the vertices it
    /// brings closer (its Voronoi cell), so `k` landmarks cost far less than
    /// `k` full solves. Stops early when every vertex is a landmark.
    pub fn farthest_points(
        &self,
        count: usize,
        control: &Control<'_>,
    ) -> Result<Vec<u32>, ShapeError> {
        let n = self.len();
        if n == 0 || count == 0 {
            return Ok(Vec::new());
        }
        let mut field = vec![f64::INFINITY; n];
        self.dijkstra_into(0, &mut field, control)?;
        let mut next = argmax(&field);
        field.fill(f64::INFINITY);
        let mut out = Vec::with_capacity(count.min(n));
        let mut heap = IndexedHeap::new(n);
        while out.len() < count.min(n) {
            if control.is_cancelled() {
                return Err(ShapeError::Cancelled);
            }
            out.push(next);
            field[next as usize] = 0.0;
            heap.push(next, 0.0);
            while let Some((v, d)) = heap.pop() {
                let (t, w) = self.of(v);
                for (&u, &l) in t.iter().zip(w) {
                    let c = d + l;
                    if c < field[u as usize] {
                        field[u as usize] = c;
                        heap.push_or_decrease(u, c);
                    }
                }
            }
            control.report(out.len() as f64 / count as f64);
            next = argmax(&field);
            if field[next as usize] <= 0.0 {
                break;
            }
        }
        Ok(out)
    }
}

/// The vertex with the largest value (`+inf` first).
pub(crate) fn argmax(d: &[f64]) -> u32 {
    let mut best = (0u32, f64::NEG_INFINITY);
    for (v, &x) in d.iter().enumerate() {
        if x > best.1 {
            best = (v as u32, x);
        }
    }
    best.0
}

/// Runs `solve(source, row)` for every source in parallel on the caller's
/// rayon pool, one row of the `k × n` result each, with `control` polled
/// before every row and progress reported as the fraction of rows done.
pub(crate) fn par_rows<F>(
    sources: &[u32],
    n: usize,
    control: &Control<'_>,
    solve: F,
) -> Result<Array2<f64>, ShapeError>
where
    F: Fn(u32, &mut [f64]) -> Result<(), ShapeError> + Sync,
{
    let mut rows = Array2::<f64>::from_elem((sources.len(), n), f64::INFINITY);
    let done = AtomicUsize::new(0);
    let k = sources.len().max(1) as f64;
    rows.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(sources.par_iter())
        .try_for_each(|(mut row, &s)| {
            if control.is_cancelled() {
                return Err(ShapeError::Cancelled);
            }
            match row.as_slice_mut() {
                Some(slice) => solve(s, slice)?,
                None => {
                    let mut tmp = vec![f64::INFINITY; n];
                    solve(s, &mut tmp)?;
                    row.iter_mut().zip(tmp).for_each(|(a, b)| *a = b);
                }
            }
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            control.report(d as f64 / k);
            Ok(())
        })?;
    Ok(rows)
}

/// Shortest-path distance rows from `sources` (`k × n`), in parallel.
pub fn graph_rows(
    graph: &Graph,
    sources: &[u32],
    control: &Control<'_>,
) -> Result<Array2<f64>, ShapeError> {
    let n = graph.len();
    if let Some(&s) = sources.iter().find(|&&s| s as usize >= n) {
        return Err(ShapeError::InvalidOption {
            option: "sources",
            reason: format!("vertex {s} does not exist (the graph has {n} vertices)"),
        });
    }
    let inner = control.cancel_only();
    par_rows(sources, n, control, |s, row| {
        graph.dijkstra_into(s, row, &inner)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_graph_distances_and_components() {
        // 0 - 1 - 2 - 3 with lengths 1, 2, 3; vertex 4 alone; a duplicate longer edge is dropped.
        let g = Graph::from_edges(5, &[(0, 1, 1.0), (1, 2, 2.0), (2, 3, 3.0), (1, 0, 5.0)]);
        assert_eq!(g.of(0), (&[1u32][..], &[1.0][..]));
        let (comp, count) = g.components();
        assert_eq!(count, 2);
        assert_eq!(comp[4], 1);
        let rows = graph_rows(&g, &[0, 3], &Control::new()).unwrap();
        assert_eq!(
            rows.row(0).to_vec(),
            vec![0.0, 1.0, 3.0, 6.0, f64::INFINITY]
        );
        assert_eq!(
            rows.row(1).to_vec(),
            vec![6.0, 5.0, 3.0, 0.0, f64::INFINITY]
        );
        // Farthest points: 3 is farthest from 0, then 0; the isolated vertex is infinitely far.
        let fp = g.farthest_points(3, &Control::new()).unwrap();
        assert_eq!(fp[0], 4);
        assert!(graph_rows(&g, &[7], &Control::new()).is_err());
    }

    #[test]
    fn a_raised_flag_stops_the_rows() {
        let edges: Vec<(u32, u32, f64)> = (0..9999).map(|i| (i, i + 1, 1.0)).collect();
        let g = Graph::from_edges(10_000, &edges);
        let flag = std::sync::atomic::AtomicBool::new(true);
        let r = graph_rows(&g, &[0, 1, 2], &Control::new().with_cancel(&flag));
        assert_eq!(r, Err(ShapeError::Cancelled));
    }
}
