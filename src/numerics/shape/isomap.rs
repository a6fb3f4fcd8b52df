//! Isomap (Tenenbaum, de Silva and Langford, Science 2000): the geodesic
//! distances of a point cloud, measured as shortest paths in its
//! k-nearest-neighbour graph, embedded by MDS.
//!
//! 1. The symmetric k-NN graph ([`knn_graph`], Euclidean edge lengths).
//! 2. Shortest-path rows by Dijkstra, in parallel: all pairs (`n × n`), or
//!    `m` farthest-point landmarks (`m × n`, L-Isomap, de Silva and
//!    Tenenbaum 2003) for large clouds.
//! 3. Classical MDS of the all-pairs matrix, or landmark MDS of the rows.
//!
//! The **residual variance** is `1 − ρ²`, `ρ` the linear correlation between
//! the graph distances and the Euclidean distances of the embedding over the
//! measured pairs (all `i < j`, or every landmark row): Tenenbaum's measure
//! of how much of the geodesic structure the embedding leaves out.

use ndarray::{Array2, ArrayView2};

use super::graph::graph_rows;
use super::knn::knn_graph;
use super::matrix::{symmetrize_block, Symmetry};
use super::mds::{classical_mds, landmark_mds, Embedding, PairStats};
use super::ShapeError;
use crate::numerics::Control;

/// Options of [`isomap`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsomapOptions {
    /// Neighbours per point (`k`, default 10).
    pub neighbours: usize,
    /// Embedding dimension (default 2).
    pub dimensions: usize,
    /// Landmarks for L-Isomap; `None` embeds all pairs.
    pub landmarks: Option<usize>,
}

impl Default for IsomapOptions {
    fn default() -> Self {
        Self {
            neighbours: 10,
            dimensions: 2,
            landmarks: None,
        }
    }
}

/// The result of [`isomap`].
#[derive(Debug, Clone, PartialEq)]
pub struct Isomap {
    /// The embedding (`n × dimensions`) and its eigenvalues.
    pub embedding: Embedding,
    /// `1 − ρ²` (see the module docs).
    pub residual_variance: f64,
    /// The landmark points (empty for all pairs).
    pub landmarks: Vec<u32>,
    /// Undirected edges of the neighbourhood graph.
    pub edges: usize,
}

/// Isomap of the rows of `points` (`n × D`).
pub fn isomap(
    points: ArrayView2<'_, f64>,
    options: &IsomapOptions,
    control: &Control<'_>,
) -> Result<Isomap, ShapeError> {
    let n = points.nrows();
    if options.dimensions == 0 || options.dimensions >= n.max(1) {
        return Err(ShapeError::InvalidOption {
            option: "dimensions",
            reason: format!(
                "must be between 1 and the number of points - 1 ({})",
                n.saturating_sub(1)
            ),
        });
    }
    let inner = control.cancel_only();
    let graph = knn_graph(points, options.neighbours, &inner)?;
    let (_, components) = graph.components();
    if components > 1 {
        return Err(ShapeError::Disconnected {
            what: "neighbour graph",
            components,
            hint: "raise the number of neighbours `k` (or remove outliers)",
        });
    }
    let edges = graph.targets.len() / 2;
    let (sources, landmarks): (Vec<u32>, Vec<u32>) = match options.landmarks {
        None => ((0..n as u32).collect(), Vec::new()),
        Some(m) => {
            if m <= options.dimensions {
                return Err(ShapeError::InvalidOption {
                    option: "landmarks",
                    reason: format!(
                        "at least dimensions + 1 = {} landmarks are needed",
                        options.dimensions + 1
                    ),
                });
            }
            let l = graph.farthest_points(m, &inner)?;
            (l.clone(), l)
        }
    };
    let mut rows = graph_rows(&graph, &sources, control)?;
    symmetrize_block(&mut rows, &sources, Symmetry::Average);
    let embedding = if landmarks.is_empty() {
        classical_mds(rows.view(), options.dimensions, &inner)?
    } else {
        let cols: Vec<usize> = landmarks.iter().map(|&l| l as usize).collect();
        landmark_mds(rows.view(), &cols, options.dimensions, &inner)?
    };
    let residual_variance =
        PairStats::of(rows.view(), &sources, embedding.coords.view()).residual_variance();
    Ok(Isomap {
        embedding,
        residual_variance,
        landmarks,
        edges,
    })
}

/// A swiss roll of `n` points (deterministic): `t = 1.5π (1 + 2u)`,
/// `(t cos t, h, t sin t)` with `u, h/21` uniform in `[0, 1]`, and its
/// unrolled coordinates `(s(t), h)` with `s(t) = ½ (t √(1 + t²) + asinh t)`
/// the arc length of the spiral. Used by tests and benchmarks.
pub fn swiss_roll(n: usize, seed: u64) -> (Array2<f64>, Array2<f64>) {
    let mut s = seed | 1;
    let mut rand = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut p = Array2::<f64>::zeros((n, 3));
    let mut flat = Array2::<f64>::zeros((n, 2));
    for i in 0..n {
        let t = 1.5 * std::f64::consts::PI * (1.0 + 2.0 * rand());
        let h = 21.0 * rand();
        p[[i, 0]] = t * t.cos();
        p[[i, 1]] = h;
        p[[i, 2]] = t * t.sin();
        flat[[i, 0]] = 0.5 * (t * (1.0 + t * t).sqrt() + t.asinh());
        flat[[i, 1]] = h;
    }
    (p, flat)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::shape::mds::euclidean_distances;

    /// Residual variance between the embedding's distances and the true
    /// unrolled rectangle's, over all pairs.
    fn against_truth(x: ArrayView2<'_, f64>, flat: &Array2<f64>) -> f64 {
        let truth = euclidean_distances(flat.view());
        let all: Vec<u32> = (0..flat.nrows() as u32).collect();
        PairStats::of(truth.view(), &all, x).residual_variance()
    }

    #[test]
    fn isomap_unrolls_a_swiss_roll() {
        let (p, flat) = swiss_roll(2000, 42);
        let r = isomap(p.view(), &IsomapOptions::default(), &Control::new()).unwrap();
        assert_eq!(r.embedding.coords.dim(), (2000, 2));
        let truth = against_truth(r.embedding.coords.view(), &flat);
        assert!(
            truth <= 0.05,
            "residual variance against the rectangle: {truth}"
        );
        assert!(
            r.residual_variance <= 0.05,
            "against the graph: {}",
            r.residual_variance
        );
        // The straight 3D distances do not unroll it (the test can fail).
        let pca = classical_mds(euclidean_distances(p.view()).view(), 2, &Control::new()).unwrap();
        assert!(against_truth(pca.coords.view(), &flat) > 0.2);
        // Landmark Isomap: nearly as good from 150 rows.
        let l = isomap(
            p.view(),
            &IsomapOptions {
                landmarks: Some(150),
                ..Default::default()
            },
            &Control::new(),
        )
        .unwrap();
        assert_eq!(l.landmarks.len(), 150);
        let lt = against_truth(l.embedding.coords.view(), &flat);
        assert!(lt <= 0.05, "landmark Isomap against the rectangle: {lt}");
    }

    #[test]
    fn a_disconnected_cloud_names_k() {
        // Two far clusters: the 3-NN graph cannot join them.
        let p = Array2::from_shape_fn((40, 2), |(i, j)| {
            if i < 20 {
                (i + j) as f64 * 0.1
            } else {
                1000.0 + (i * j) as f64 * 0.1
            }
        });
        match isomap(
            p.view(),
            &IsomapOptions {
                neighbours: 3,
                ..Default::default()
            },
            &Control::new(),
        ) {
            Err(ShapeError::Disconnected {
                components, hint, ..
            }) => {
                assert!(components >= 2);
                assert!(hint.contains("`k`"));
            }
            other => panic!("{other:?}"),
        }
    }
}
