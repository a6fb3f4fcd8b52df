//! The graph of a one-cell-thin 2D skeleton: nodes where branches end or
//! meet, and the branches between them as polylines (8-connectivity).
//!
//! A skeleton cell with exactly two skeleton neighbours is inside a branch;
//! any other cell (one neighbour: an end point; three or more: a junction;
//! none: an isolated cell) is a node cell, and 8-adjacent node cells with
//! more than two neighbours each form one node (a junction cluster), placed
//! at the mean of its cells with the largest radius among them. A branch is
//! walked from a node cell through the branch cells until it reaches a node
//! cell; its length is `Σ |h ⊙ (p_{k+1} − p_k)|` over its cell centres `p_k`
//! (physical units). A closed loop without any node cell gets one node at its
//! first cell (C order), and one branch from that node to itself.

use std::collections::HashSet;

/// A node of the skeleton graph: an end point, a junction (a cluster of
/// adjacent junction cells counts once), or one cell of a closed loop.
#[derive(Debug, Clone, PartialEq)]
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
#[derive(Debug, Clone, PartialEq)]
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
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SkeletonGraph {
    /// Nodes.
    pub nodes: Vec<SkeletonNode>,
    /// Branches.
    pub edges: Vec<SkeletonEdge>,
}

/// No node: a branch cell, or a cell not reached yet.
const NONE: usize = usize::MAX;

/// The graph of a one-cell-thin 2D skeleton (8-connectivity): `mask` marks
/// the skeleton cells and `radius` gives the radius function, both on the
/// grid of shape `shape` (C order) and spacing `h`.
///
/// # Examples
/// ```
/// use geodex::numerics::skeleton::graph_2d;
/// // A straight skeleton of 5 cells along axis 1: two end nodes, one branch.
/// let mut mask = vec![false; 3 * 7];
/// (1..6).for_each(|j| mask[7 + j] = true);
/// let g = graph_2d(&mask, &[1.0; 21], [3, 7], [1.0, 0.5]);
/// assert_eq!((g.nodes.len(), g.edges.len()), (2, 1));
/// assert_eq!(g.edges[0].length, 2.0);
/// ```
pub fn graph_2d(mask: &[bool], radius: &[f64], shape: [usize; 2], h: [f64; 2]) -> SkeletonGraph {
    let mut builder = GraphBuilder {
        cells: Cells {
            mask,
            radius,
            shape,
            h,
        },
        node_of: vec![NONE; mask.len()],
        visited: vec![false; mask.len()],
        graph: SkeletonGraph::default(),
    };
    let cells: Vec<usize> = (0..mask.len()).filter(|&c| mask[c]).collect();
    builder.cluster_nodes(&cells);
    builder.walk_branches(&cells);
    builder.cut_loops(&cells);
    builder.graph
}

/// The skeleton cells on their grid.
struct Cells<'a> {
    mask: &'a [bool],
    radius: &'a [f64],
    shape: [usize; 2],
    h: [f64; 2],
}

impl Cells<'_> {
    /// The skeleton cells among the 8 neighbours of `c`, in row order.
    fn neighbours(&self, c: usize) -> Vec<usize> {
        let [n0, n1] = self.shape;
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
                    if self.mask[k] {
                        v.push(k);
                    }
                }
            }
        }
        v
    }

    /// Whether `c` is a node cell (not exactly two skeleton neighbours).
    fn is_node_cell(&self, c: usize) -> bool {
        self.neighbours(c).len() != 2
    }

    /// The centre of `c` in index coordinates.
    fn point(&self, c: usize) -> [f64; 2] {
        let n1 = self.shape[1];
        [(c / n1) as f64, (c % n1) as f64]
    }

    /// The physical distance between the centres of `a` and `b`.
    fn step(&self, a: usize, b: usize) -> f64 {
        let (p, q) = (self.point(a), self.point(b));
        (((p[0] - q[0]) * self.h[0]).powi(2) + ((p[1] - q[1]) * self.h[1]).powi(2)).sqrt()
    }
}

/// The graph under construction.
struct GraphBuilder<'a> {
    cells: Cells<'a>,
    /// The node of each node cell, [`NONE`] elsewhere.
    node_of: Vec<usize>,
    /// The branch cells already walked.
    visited: Vec<bool>,
    graph: SkeletonGraph,
}

impl GraphBuilder<'_> {
    /// One node per cluster of node cells (see the module docs), in the
    /// order of their first cell.
    fn cluster_nodes(&mut self, cells: &[usize]) {
        for &c in cells {
            if self.node_of[c] != NONE || !self.cells.is_node_cell(c) {
                continue;
            }
            let id = self.graph.nodes.len();
            let mut stack = vec![c];
            self.node_of[c] = id;
            let mut members = Vec::new();
            while let Some(x) = stack.pop() {
                members.push(x);
                for y in self.cells.neighbours(x) {
                    if self.node_of[y] == NONE
                        && self.cells.is_node_cell(y)
                        && self.cells.neighbours(y).len() > 2
                        && self.cells.neighbours(x).len() > 2
                    {
                        self.node_of[y] = id;
                        stack.push(y);
                    }
                }
            }
            let k = members.len() as f64;
            let point = members.iter().fold([0.0, 0.0], |acc, &m| {
                let p = self.cells.point(m);
                [acc[0] + p[0] / k, acc[1] + p[1] / k]
            });
            let r = members
                .iter()
                .map(|&m| self.cells.radius[m])
                .fold(0.0, f64::max);
            self.graph.nodes.push(SkeletonNode {
                id,
                point,
                radius: r,
                degree: 0,
            });
        }
    }

    /// The branches that leave every node cell: a direct one to each
    /// adjacent cell of another node (once per pair of nodes), and a walk
    /// along each branch cell not visited yet.
    fn walk_branches(&mut self, cells: &[usize]) {
        let mut done_pairs = HashSet::new();
        for &c in cells {
            let n = self.node_of[c];
            if n == NONE {
                continue;
            }
            for y in self.cells.neighbours(c) {
                let m = self.node_of[y];
                if m == n {
                    continue;
                }
                if m != NONE {
                    // Two node clusters side by side: one short branch.
                    if done_pairs.insert((n.min(m), n.max(m))) {
                        let points = vec![self.cells.point(c), self.cells.point(y)];
                        let radius = vec![self.cells.radius[c], self.cells.radius[y]];
                        let length = self.cells.step(c, y);
                        self.add_edge(n, m, points, radius, length);
                    }
                    continue;
                }
                if self.visited[y] {
                    continue;
                }
                self.walk(n, c, y);
            }
        }
    }

    /// Closed loops without any node: cut each at its first cell, which
    /// becomes a node with a branch from itself to itself.
    fn cut_loops(&mut self, cells: &[usize]) {
        for &c in cells {
            if self.visited[c] || self.node_of[c] != NONE {
                continue;
            }
            let id = self.graph.nodes.len();
            self.node_of[c] = id;
            self.graph.nodes.push(SkeletonNode {
                id,
                point: self.cells.point(c),
                radius: self.cells.radius[c],
                degree: 0,
            });
            if let Some(y) = self.cells.neighbours(c).into_iter().next() {
                self.walk(id, c, y);
            }
        }
    }

    /// Walks the branch that leaves node `start_node` from its cell `from`
    /// through `first`, until a node cell, and adds it (a walk that ends
    /// nowhere adds nothing).
    fn walk(&mut self, start_node: usize, from: usize, first: usize) {
        let cells = &self.cells;
        let mut points = vec![cells.point(from), cells.point(first)];
        let mut radii = vec![cells.radius[from], cells.radius[first]];
        let mut length = cells.step(from, first);
        let (mut prev, mut cur) = (from, first);
        while self.node_of[cur] == NONE {
            self.visited[cur] = true;
            let next = cells
                .neighbours(cur)
                .into_iter()
                .find(|&n| n != prev && (self.node_of[n] != NONE || !self.visited[n]));
            let Some(n) = next else {
                break;
            };
            length += cells.step(cur, n);
            points.push(cells.point(n));
            radii.push(cells.radius[n]);
            prev = cur;
            cur = n;
        }
        let target = self.node_of[cur];
        if target != NONE {
            self.add_edge(start_node, target, points, radii, length);
        }
    }

    /// Adds the branch `source → target` and counts it in both degrees.
    fn add_edge(
        &mut self,
        source: usize,
        target: usize,
        points: Vec<[f64; 2]>,
        radius: Vec<f64>,
        length: f64,
    ) {
        self.graph.nodes[source].degree += 1;
        self.graph.nodes[target].degree += 1;
        self.graph.edges.push(SkeletonEdge {
            source,
            target,
            points,
            radius,
            length,
        });
    }
}
