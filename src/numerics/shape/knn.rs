//! k-nearest neighbours of a point cloud with a kd-tree, and the
//! neighbourhood graph Isomap measures geodesics on.
//!
//! The tree splits at the median of the axis of largest spread until a leaf
//! holds at most [`LEAF`] points; a query descends to the nearest leaf first
//! and visits a sibling only when the splitting plane is closer than the
//! current k-th neighbour (`O(log n)` per query in low dimension). Points are
//! rows of an `n × D` array, any `D >= 1`. A hand-written tree rather than a
//! crate: about a hundred lines, no generic dimension parameter to fix at
//! compile time (Isomap inputs have any `D`), and nothing else needs one.
//!
//! The graph joins `i` and `j` when either is among the other's `k` nearest
//! neighbours (the symmetric union, as scikit-learn's `Isomap` does), with
//! the Euclidean length as weight.

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::graph::Graph;
use super::ShapeError;
use crate::numerics::Control;

/// Most points in a leaf.
const LEAF: usize = 16;

#[derive(Debug, Clone)]
enum Node {
    Leaf {
        start: u32,
        end: u32,
    },
    Split {
        axis: u32,
        value: f64,
        left: u32,
        right: u32,
    },
}

/// A kd-tree over the rows of a point array.
#[derive(Debug, Clone)]
pub struct KdTree<'a> {
    points: ArrayView2<'a, f64>,
    order: Vec<u32>,
    nodes: Vec<Node>,
}

impl<'a> KdTree<'a> {
    /// Builds the tree in `O(n log n)`.
    pub fn new(points: ArrayView2<'a, f64>) -> Self {
        let n = points.nrows();
        let mut tree = Self {
            points,
            order: (0..n as u32).collect(),
            nodes: Vec::new(),
        };
        if n > 0 {
            tree.build(0, n);
        }
        tree
    }

    fn build(&mut self, start: usize, end: usize) -> u32 {
        let id = self.nodes.len() as u32;
        if end - start <= LEAF {
            self.nodes.push(Node::Leaf {
                start: start as u32,
                end: end as u32,
            });
            return id;
        }
        let dims = self.points.ncols();
        let mut axis = 0;
        let mut spread = -1.0;
        for a in 0..dims {
            let (lo, hi) = self.order[start..end].iter().fold(
                (f64::INFINITY, f64::NEG_INFINITY),
                |(lo, hi), &i| {
                    let x = self.points[(i as usize, a)];
                    (lo.min(x), hi.max(x))
                },
            );
            if hi - lo > spread {
                spread = hi - lo;
                axis = a;
            }
        }
        let mid = start + (end - start) / 2;
        let pts = self.points;
        self.order[start..end].select_nth_unstable_by(mid - start, |&i, &j| {
            pts[(i as usize, axis)].total_cmp(&pts[(j as usize, axis)])
        });
        let value = pts[(self.order[mid] as usize, axis)];
        self.nodes.push(Node::Leaf { start: 0, end: 0 });
        let left = self.build(start, mid);
        let right = self.build(mid, end);
        self.nodes[id as usize] = Node::Split {
            axis: axis as u32,
            value,
            left,
            right,
        };
        id
    }

    /// The `k` nearest rows to `query` other than `skip`, as `(index,
    /// squared distance)` sorted by distance (ties by index).
    pub fn nearest(&self, query: &[f64], k: usize, skip: Option<u32>) -> Vec<(u32, f64)> {
        let mut best: Vec<(u32, f64)> = Vec::with_capacity(k + 1);
        if k > 0 && !self.nodes.is_empty() {
            self.search(0, query, k, skip, &mut best);
        }
        best
    }

    fn search(
        &self,
        node: u32,
        q: &[f64],
        k: usize,
        skip: Option<u32>,
        best: &mut Vec<(u32, f64)>,
    ) {
        match self.nodes[node as usize] {
            Node::Leaf { start, end } => {
                for &i in &self.order[start as usize..end as usize] {
                    if Some(i) == skip {
                        continue;
                    }
                    let d2: f64 = self
                        .points
                        .row(i as usize)
                        .iter()
                        .zip(q)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum();
                    if best.len() == k && !less(d2, i, best[k - 1]) {
                        continue;
                    }
                    let pos = best.partition_point(|&b| less(b.1, b.0, (i, d2)));
                    best.insert(pos, (i, d2));
                    best.truncate(k);
                }
            }
            Node::Split {
                axis,
                value,
                left,
                right,
            } => {
                let diff = q[axis as usize] - value;
                let (near, far) = if diff < 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.search(near, q, k, skip, best);
                if best.len() < k || diff * diff <= best[k - 1].1 {
                    self.search(far, q, k, skip, best);
                }
            }
        }
    }
}

/// Strict order on `(squared distance, index)`.
#[inline]
fn less(d2: f64, i: u32, b: (u32, f64)) -> bool {
    d2 < b.1 || (d2 == b.1 && i < b.0)
}

/// The symmetric k-nearest-neighbour graph of the rows of `points`
/// (Euclidean edge lengths), built with one kd-tree and parallel queries.
pub fn knn_graph(
    points: ArrayView2<'_, f64>,
    k: usize,
    control: &Control<'_>,
) -> Result<Graph, ShapeError> {
    let n = points.nrows();
    if k == 0 || k >= n {
        return Err(ShapeError::InvalidOption {
            option: "k",
            reason: format!(
                "must be between 1 and the number of points - 1 ({})",
                n.saturating_sub(1)
            ),
        });
    }
    if let Some(i) = points.iter().position(|x| !x.is_finite()) {
        return Err(ShapeError::InvalidOption {
            option: "points",
            reason: format!(
                "point {} has a non-finite coordinate",
                i / points.ncols().max(1)
            ),
        });
    }
    let tree = KdTree::new(points);
    let lists: Vec<Vec<(u32, f64)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if i % 1024 == 0 && control.is_cancelled() {
                return Vec::new();
            }
            let q: Vec<f64> = points.row(i).to_vec();
            tree.nearest(&q, k, Some(i as u32))
        })
        .collect();
    if control.is_cancelled() {
        return Err(ShapeError::Cancelled);
    }
    let edges: Vec<(u32, u32, f64)> = lists
        .iter()
        .enumerate()
        .flat_map(|(i, l)| l.iter().map(move |&(j, d2)| (i as u32, j, d2.sqrt())))
        .collect();
    Ok(Graph::from_edges(n, &edges))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    fn cloud(n: usize, d: usize) -> Array2<f64> {
        let mut s = 0x2545_f491_4f6c_dd1d_u64;
        Array2::from_shape_fn((n, d), |_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        })
    }

    #[test]
    fn kd_tree_matches_brute_force() {
        for d in [1, 3, 5] {
            let p = cloud(700, d);
            let tree = KdTree::new(p.view());
            for i in (0..700).step_by(37) {
                let q = p.row(i).to_vec();
                let got = tree.nearest(&q, 7, Some(i as u32));
                let mut all: Vec<(u32, f64)> = (0..700u32)
                    .filter(|&j| j as usize != i)
                    .map(|j| {
                        let d2 = p
                            .row(j as usize)
                            .iter()
                            .zip(&q)
                            .map(|(a, b)| (a - b) * (a - b))
                            .sum();
                        (j, d2)
                    })
                    .collect();
                all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                all.truncate(7);
                assert_eq!(got, all, "d = {d}, point {i}");
            }
        }
    }

    #[test]
    fn graph_is_symmetric_and_k_is_checked() {
        let p = cloud(300, 2);
        let g = knn_graph(p.view(), 5, &Control::new()).unwrap();
        for v in 0..300u32 {
            let (t, w) = g.of(v);
            assert!(t.len() >= 5);
            for (&u, &l) in t.iter().zip(w) {
                let (tu, wu) = g.of(u);
                let back = tu.iter().position(|&x| x == v).expect("symmetric");
                assert_eq!(wu[back], l);
            }
        }
        assert!(knn_graph(p.view(), 0, &Control::new()).is_err());
        assert!(knn_graph(p.view(), 300, &Control::new()).is_err());
    }
}
