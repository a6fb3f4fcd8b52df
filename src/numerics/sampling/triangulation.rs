//! Validity of a planar triangulation: the checker every meshing result and
//! test goes through (geodesic Delaunay, image meshing; domain meshing will
//! reuse it).
//!
//! A list of triangles `T` over points `p_v ∈ R²` is a *valid triangulation*
//! of the union of its triangles when
//!
//! 1. every triangle is non-degenerate and positively oriented:
//!    `det(p_b − p_a, p_c − p_a) > ε ℓ²` (`ℓ` its longest edge, `ε = 1e-9`),
//!    the orientation being counter-clockwise in the (axis 0, axis 1) plane;
//! 2. it is edge-manifold with a consistent orientation: an undirected edge
//!    lies in one or two triangles, and in two only as `(a, b)` in one and
//!    `(b, a)` in the other;
//! 3. it is vertex-manifold: the triangles around a vertex form one fan (a
//!    single chain, or a single closed cycle for an interior vertex);
//! 4. no two triangles overlap: their interiors are disjoint (separating-axis
//!    test on the six edge normals, with a tolerance of `1e-9` of the
//!    longest edge so that shared edges and vertices do not count).
//!
//! Conditions 1-3 are combinatorial and `O(|T|)`; condition 4 buckets the
//! triangles by bounding box and tests only pairs sharing a bucket, `O(|T|)`
//! on a triangulation of well-spread points.

use std::collections::HashMap;

/// Relative tolerance of the degeneracy and overlap tests.
const EPS: f64 = 1e-9;

/// One way a list of triangles fails to be a valid triangulation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Defect {
    /// Triangle `triangle` has (nearly) zero area.
    Degenerate {
        /// Index of the triangle.
        triangle: usize,
    },
    /// Triangle `triangle` is clockwise (negative orientation).
    Flipped {
        /// Index of the triangle.
        triangle: usize,
    },
    /// Edge `edge` lies in more than two triangles, or twice in the same direction.
    NonManifoldEdge {
        /// Its two vertices, smaller first.
        edge: [u32; 2],
    },
    /// The triangles around `vertex` form more than one fan.
    NonManifoldVertex {
        /// The vertex.
        vertex: u32,
    },
    /// The interiors of two triangles intersect.
    Overlap {
        /// Their indices, smaller first.
        triangles: [usize; 2],
    },
    /// A triangle names a vertex that does not exist.
    BadIndex {
        /// Index of the triangle.
        triangle: usize,
    },
}

/// Every defect of `triangles` over `points` (empty: a valid triangulation);
/// see the module docs for the four conditions.
///
/// # Examples
/// ```
/// use geodex::numerics::sampling::triangulation::{check_planar, Defect};
/// let p = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]];
/// assert!(check_planar(&p, &[[0, 1, 2], [1, 3, 2]]).is_empty());
/// assert_eq!(check_planar(&p, &[[0, 2, 1]]), vec![Defect::Flipped { triangle: 0 }]);
/// ```
pub fn check_planar(points: &[[f64; 2]], triangles: &[[u32; 3]]) -> Vec<Defect> {
    let mut defects = Vec::new();
    let n = points.len();
    let mut good: Vec<usize> = Vec::with_capacity(triangles.len());
    for (t, tri) in triangles.iter().enumerate() {
        if tri.iter().any(|&v| v as usize >= n)
            || tri[0] == tri[1]
            || tri[1] == tri[2]
            || tri[0] == tri[2]
        {
            defects.push(Defect::BadIndex { triangle: t });
            continue;
        }
        let [a, b, c] = tri.map(|v| points[v as usize]);
        let d = orient(a, b, c);
        let l2 = longest_edge2(a, b, c);
        if d.abs() <= EPS * l2 {
            defects.push(Defect::Degenerate { triangle: t });
        } else if d < 0.0 {
            defects.push(Defect::Flipped { triangle: t });
        } else {
            good.push(t);
        }
    }
    combinatorial(triangles, &good, &mut defects);
    overlaps(points, triangles, &good, &mut defects);
    defects
}

/// Twice the signed area of `(a, b, c)`.
pub fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn longest_edge2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let d2 = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
    d2(a, b).max(d2(b, c)).max(d2(c, a))
}

/// Conditions 2 and 3 over the triangles `good` (indices into `triangles`).
fn combinatorial(triangles: &[[u32; 3]], good: &[usize], defects: &mut Vec<Defect>) {
    // Directed edge -> how many times it is used; undirected -> count.
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    let mut undirected: HashMap<(u32, u32), u32> = HashMap::new();
    // Around each vertex v: the link edges (a -> b) of its triangles (v, a, b).
    let mut links: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
    for &t in good {
        let tri = triangles[t];
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *directed.entry((a, b)).or_insert(0) += 1;
            *undirected.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            links.entry(tri[k]).or_default().push((b, tri[(k + 2) % 3]));
        }
    }
    let mut bad_edges: Vec<[u32; 2]> = undirected
        .iter()
        .filter(|(&(a, b), &c)| {
            c > 2
                || directed.get(&(a, b)).copied().unwrap_or(0) > 1
                || directed.get(&(b, a)).copied().unwrap_or(0) > 1
        })
        .map(|(&(a, b), _)| [a, b])
        .collect();
    bad_edges.sort_unstable();
    defects.extend(
        bad_edges
            .into_iter()
            .map(|edge| Defect::NonManifoldEdge { edge }),
    );
    let mut bad_vertices: Vec<u32> = links
        .iter()
        .filter(|(_, link)| !is_one_fan(link))
        .map(|(&v, _)| v)
        .collect();
    bad_vertices.sort_unstable();
    defects.extend(
        bad_vertices
            .into_iter()
            .map(|vertex| Defect::NonManifoldVertex { vertex }),
    );
}

/// Whether the link edges `a -> b` form one chain or one cycle.
fn is_one_fan(link: &[(u32, u32)]) -> bool {
    let mut next: HashMap<u32, u32> = HashMap::with_capacity(link.len());
    let mut has_prev: HashMap<u32, bool> = HashMap::with_capacity(link.len());
    for &(a, b) in link {
        if next.insert(a, b).is_some() {
            return false;
        }
        has_prev.insert(b, true);
    }
    let starts: Vec<u32> = next
        .keys()
        .copied()
        .filter(|a| !has_prev.contains_key(a))
        .collect();
    let start = match starts.as_slice() {
        [] => link[0].0,
        [s] => *s,
        _ => return false,
    };
    // Walk from the start: it must visit every link edge once.
    let mut at = start;
    let mut steps = 0;
    while let Some(&b) = next.get(&at) {
        steps += 1;
        if steps > link.len() {
            return false;
        }
        at = b;
        if at == start {
            break;
        }
    }
    steps == link.len()
}

/// Condition 4 over the triangles `good`.
fn overlaps(
    points: &[[f64; 2]],
    triangles: &[[u32; 3]],
    good: &[usize],
    defects: &mut Vec<Defect>,
) {
    if good.len() < 2 {
        return;
    }
    let corners = |t: usize| triangles[t].map(|v| points[v as usize]);
    let bbox = |t: usize| {
        let c = corners(t);
        let lo = [
            c[0][0].min(c[1][0]).min(c[2][0]),
            c[0][1].min(c[1][1]).min(c[2][1]),
        ];
        let hi = [
            c[0][0].max(c[1][0]).max(c[2][0]),
            c[0][1].max(c[1][1]).max(c[2][1]),
        ];
        (lo, hi)
    };
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let mut size = 0.0;
    for &t in good {
        let (l, h) = bbox(t);
        lo = [lo[0].min(l[0]), lo[1].min(l[1])];
        hi = [hi[0].max(h[0]), hi[1].max(h[1])];
        size += (h[0] - l[0]).max(h[1] - l[1]);
    }
    let cell = (size / good.len() as f64).max(1e-12);
    let dims = [0, 1].map(|k| (((hi[k] - lo[k]) / cell) as usize + 1).min(4096));
    let bucket = |x: f64, k: usize| (((x - lo[k]) / cell) as usize).min(dims[k] - 1);
    let mut buckets: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for &t in good {
        let (l, h) = bbox(t);
        for i in bucket(l[0], 0)..=bucket(h[0], 0) {
            for j in bucket(l[1], 1)..=bucket(h[1], 1) {
                buckets.entry((i, j)).or_default().push(t);
            }
        }
    }
    let mut found: Vec<[usize; 2]> = Vec::new();
    for (&(i, j), list) in &buckets {
        for (x, &s) in list.iter().enumerate() {
            for &t in &list[x + 1..] {
                let ((ls, hs), (lt, ht)) = (bbox(s), bbox(t));
                // Test each pair once: in the first bucket of their common box.
                let first = (bucket(ls[0].max(lt[0]), 0), bucket(ls[1].max(lt[1]), 1));
                if first != (i, j)
                    || hs[0] < lt[0]
                    || ht[0] < ls[0]
                    || hs[1] < lt[1]
                    || ht[1] < ls[1]
                {
                    continue;
                }
                if interiors_intersect(corners(s), corners(t)) {
                    found.push([s.min(t), s.max(t)]);
                }
            }
        }
    }
    found.sort_unstable();
    defects.extend(
        found
            .into_iter()
            .map(|triangles| Defect::Overlap { triangles }),
    );
}

/// Separating-axis test: the interiors intersect unless the projections on
/// one of the six edge normals are disjoint or only touch (within `EPS` of
/// the longest edge).
fn interiors_intersect(s: [[f64; 2]; 3], t: [[f64; 2]; 3]) -> bool {
    let scale = longest_edge2(s[0], s[1], s[2])
        .max(longest_edge2(t[0], t[1], t[2]))
        .sqrt();
    for tri in [s, t] {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let normal = [b[1] - a[1], a[0] - b[0]];
            let len = normal[0].hypot(normal[1]);
            if len == 0.0 {
                continue;
            }
            let project = |p: [f64; 2]| (p[0] * normal[0] + p[1] * normal[1]) / len;
            let (mut l1, mut h1, mut l2, mut h2) = (
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            );
            for p in s {
                l1 = l1.min(project(p));
                h1 = h1.max(project(p));
            }
            for p in t {
                l2 = l2.min(project(p));
                h2 = h2.max(project(p));
            }
            if h1.min(h2) - l1.max(l2) <= EPS * scale {
                return false;
            }
        }
    }
    true
}
