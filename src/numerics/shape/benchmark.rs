//! A retrieval benchmark of articulated shapes: classes of closed surfaces
//! with limbs (stars with 3 to 6 arms, a T, a Y, a snake, a stick figure, a
//! quadruped, a hand, a table), each in many poses, with noise and
//! remeshing. It is generated in code, so a test and a benchmark can share
//! it, and the same seed gives the same meshes.
//!
//! **Construction.** A class is an ellipsoidal body with limbs, each limb a
//! unit direction `d`, a length `L` and a cap angle `α`. A pose starts from
//! the icosphere of `level` subdivisions (a closed genus-0 mesh); a vertex
//! of unit direction `u` whose angle `θ` to the nearest limb direction is
//! below `α` is carried onto that limb's tube: with `s = 1 − θ/α`, along
//! the axis to `t = L s` at radius `ρ` (rounded to 0 over the last 15 % of
//! the limb, the tip), in the direction of `u` across the axis, blended
//! with the body over `s < ¼` so that the surface stays continuous; the
//! other vertices lie on the ellipsoid. Every vertex keeps its neighbours,
//! so the result is a closed genus-0 surface.
//!
//! **Poses.** Each limb bends at its middle joint by an angle of up to
//! `max_bend` about a random axis across the limb, smoothly over a window of
//! one tube radius (the distal part turns rigidly: geodesic distances change
//! only near the joint, as in an articulated body). Then the pose is turned
//! by a random rotation, scaled by a random factor in `[0.5, 2]` and moved.
//!
//! **Noise and remeshing.** The pose is remeshed
//! ([`crate::numerics::meshing::surface::remesh`], uniform, geodesic
//! farthest points and one Lloyd step) to a vertex count drawn in
//! `[min_vertices, max_vertices]`, so two poses never share a
//! triangulation, and every vertex is then jittered by up to `noise` times
//! the mean edge length along each axis.

use crate::numerics::mesh::shapes::icosphere;
use crate::numerics::mesh::TriMesh;
use crate::numerics::meshing::surface::{remesh, Adaptation, RemeshError, RemeshOptions, Sampling};
use crate::numerics::Control;

/// A class of articulated shapes.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeClass {
    /// Its name (`star3`, `hand`, …).
    pub name: &'static str,
    /// Semi-axes of the ellipsoidal body.
    pub body: [f64; 3],
    /// The limbs: unit direction from the body's centre, length.
    pub limbs: Vec<([f64; 3], f64)>,
    /// Angle (radians) of the cap of the sphere that becomes each limb.
    pub cap: f64,
}

/// Settings of [`benchmark_shape`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchmarkOptions {
    /// Subdivisions of the icosphere a pose is built on (3: 642 vertices,
    /// 4: 2562).
    pub level: u32,
    /// Largest bend of a joint, radians.
    pub max_bend: f64,
    /// Fewest vertices after remeshing.
    pub min_vertices: usize,
    /// Most vertices after remeshing.
    pub max_vertices: usize,
    /// Vertex jitter, a fraction of the mean edge length.
    pub noise: f64,
    /// Seed of every random choice.
    pub seed: u64,
}

impl Default for BenchmarkOptions {
    fn default() -> Self {
        Self {
            level: 4,
            max_bend: 1.0,
            min_vertices: 400,
            max_vertices: 700,
            noise: 0.1,
            seed: 1,
        }
    }
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

/// The direction at polar angle `polar` from +z and azimuth `azimuth`.
fn dir(polar_deg: f64, azimuth_deg: f64) -> [f64; 3] {
    let (p, a) = (polar_deg.to_radians(), azimuth_deg.to_radians());
    [p.sin() * a.cos(), p.sin() * a.sin(), p.cos()]
}

/// `k` limbs of length `l` evenly spread in the plane z = 0.
fn star(k: usize, l: f64) -> Vec<([f64; 3], f64)> {
    (0..k)
        .map(|i| (dir(90.0, 360.0 * i as f64 / k as f64), l))
        .collect()
}

/// The classes of the benchmark (eleven).
pub fn classes() -> Vec<ShapeClass> {
    let c = |name, body, limbs, cap_deg: f64| ShapeClass {
        name,
        body,
        limbs,
        cap: cap_deg.to_radians(),
    };
    vec![
        c("star3", [1.0, 1.0, 0.8], star(3, 1.6), 30.0),
        c("star4", [1.0, 1.0, 0.8], star(4, 1.6), 28.0),
        c("star5", [1.0, 1.0, 0.8], star(5, 1.5), 25.0),
        c("star6", [1.0, 1.0, 0.8], star(6, 1.4), 22.0),
        c(
            "T",
            [1.0, 1.0, 1.0],
            vec![
                (dir(90.0, 0.0), 2.2),
                (dir(90.0, 180.0), 2.2),
                (dir(180.0, 0.0), 0.8),
            ],
            30.0,
        ),
        c(
            "Y",
            [1.0, 1.0, 1.0],
            vec![
                (dir(35.0, 0.0), 0.9),
                (dir(35.0, 180.0), 0.9),
                (dir(180.0, 0.0), 2.6),
            ],
            22.0,
        ),
        c(
            "snake",
            [0.8, 0.8, 0.8],
            vec![(dir(0.0, 0.0), 3.5), (dir(180.0, 0.0), 3.5)],
            40.0,
        ),
        c(
            "stick_figure",
            [0.9, 0.6, 1.3],
            vec![
                (dir(0.0, 0.0), 0.5),
                (dir(90.0, 0.0), 1.5),
                (dir(90.0, 180.0), 1.5),
                (dir(160.0, 0.0), 2.0),
                (dir(160.0, 180.0), 2.0),
            ],
            18.0,
        ),
        c(
            "quadruped",
            [1.6, 0.8, 0.8],
            vec![
                (unit([0.5, 0.6, -0.62]), 1.3),
                (unit([0.5, -0.6, -0.62]), 1.3),
                (unit([-0.5, 0.6, -0.62]), 1.3),
                (unit([-0.5, -0.6, -0.62]), 1.3),
                (unit([1.0, 0.0, 0.6]), 1.2),
                (unit([-1.0, 0.0, 0.3]), 2.0),
            ],
            20.0,
        ),
        c(
            "hand",
            [1.2, 0.5, 1.0],
            vec![
                (dir(0.0, 0.0), 1.2),
                (dir(32.0, 0.0), 1.1),
                (dir(32.0, 180.0), 1.0),
                (dir(64.0, 180.0), 0.7),
                (dir(85.0, 0.0), 0.8),
                (dir(180.0, 0.0), 0.6),
            ],
            14.0,
        ),
        c(
            "table",
            [1.6, 1.6, 0.35],
            vec![
                (unit([0.6, 0.6, -0.52]), 1.4),
                (unit([0.6, -0.6, -0.52]), 1.4),
                (unit([-0.6, 0.6, -0.52]), 1.4),
                (unit([-0.6, -0.6, -0.52]), 1.4),
            ],
            16.0,
        ),
    ]
}

/// A small deterministic generator (xorshift64*), `[0, 1)`.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// Seeded (any seed, 0 included).
    pub fn new(seed: u64) -> Self {
        Rng(seed
            .wrapping_mul(0x9e37_79b9_7f4a_7c15)
            .wrapping_add(0x2545_f491_4f6c_dd1d)
            | 1)
    }

    /// The next number in `[0, 1)`.
    pub fn next_f64(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[a, b)`.
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next_f64()
    }

    /// A uniform unit vector.
    pub fn direction(&mut self) -> [f64; 3] {
        let z = self.range(-1.0, 1.0);
        let a = self.range(0.0, std::f64::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        [r * a.cos(), r * a.sin(), z]
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn axpy(a: f64, x: [f64; 3], y: [f64; 3]) -> [f64; 3] {
    [a * x[0] + y[0], a * x[1] + y[1], a * x[2] + y[2]]
}

/// Rotation of `p` by `angle` about the unit `axis` (Rodrigues).
fn rotate(p: [f64; 3], axis: [f64; 3], angle: f64) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let k = cross(axis, p);
    let kd = dot(axis, p) * (1.0 - c);
    [
        p[0] * c + k[0] * s + axis[0] * kd,
        p[1] * c + k[1] * s + axis[1] * kd,
        p[2] * c + k[2] * s + axis[2] * kd,
    ]
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// A unit vector across `d`.
fn across(d: [f64; 3], r: [f64; 3]) -> [f64; 3] {
    let v = axpy(-dot(r, d), d, r);
    let n = dot(v, v).sqrt();
    if n > 1e-9 {
        [v[0] / n, v[1] / n, v[2] / n]
    } else {
        let alt = if d[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        unit(cross(d, alt))
    }
}

/// The pose of `class` on the icosphere of `level` with one bend per limb
/// (`bends[j]`: angle, then the axis across limb `j`), before any rigid
/// motion, remeshing or noise (see the module docs).
pub fn pose(class: &ShapeClass, level: u32, bends: &[(f64, [f64; 3])]) -> TriMesh {
    let sphere = icosphere(level, 1.0);
    let [a, b, c] = class.body;
    let ellipsoid = |u: [f64; 3]| [a * u[0], b * u[1], c * u[2]];
    let positions: Vec<[f64; 3]> = sphere
        .positions()
        .iter()
        .map(|&u| {
            let body = ellipsoid(u);
            let nearest = class
                .limbs
                .iter()
                .enumerate()
                .map(|(j, (d, _))| (j, dot(u, *d)))
                .max_by(|x, y| x.1.total_cmp(&y.1));
            let Some((j, cos)) = nearest else {
                return body;
            };
            let theta = cos.clamp(-1.0, 1.0).acos();
            if theta >= class.cap {
                return body;
            }
            let (d, length) = class.limbs[j];
            let s = 1.0 - theta / class.cap;
            // The tube leaves the body at the ellipsoid's point along d,
            // with the radius of the cap's rim there.
            let root = axpy(-0.1, d, ellipsoid(d));
            let radius = 0.75 * class.cap.sin() * a.min(b).min(c);
            let t = length * s;
            let tip = 0.85;
            let r = if s > tip {
                let x = (s - tip) / (1.0 - tip);
                radius * (1.0 - x * x).max(0.0).sqrt()
            } else {
                radius
            };
            let v = across(d, u);
            let tube = axpy(r, v, axpy(t, d, root));
            let w = smoothstep(s / 0.25);
            let mut p = [
                (1.0 - w) * body[0] + w * tube[0],
                (1.0 - w) * body[1] + w * tube[1],
                (1.0 - w) * body[2] + w * tube[2],
            ];
            if let Some(&(angle, axis)) = bends.get(j) {
                let joint = axpy(0.5 * length, d, root);
                let psi = angle * smoothstep((t - 0.5 * length + radius) / (2.0 * radius));
                let local = axpy(-1.0, joint, p);
                p = axpy(1.0, joint, rotate(local, across(d, axis), psi));
            }
            p
        })
        .collect();
    TriMesh::from_parts_unchecked(positions, sphere.faces().to_vec())
}

/// Pose `index` of class `class` (see the module docs): the same
/// `(class, index, options)` always gives the same mesh.
pub fn benchmark_shape(
    class: &ShapeClass,
    class_index: usize,
    index: usize,
    options: &BenchmarkOptions,
    control: &Control<'_>,
) -> Result<TriMesh, RemeshError> {
    let mut rng = Rng::new(
        options.seed ^ ((class_index as u64) << 32) ^ (index as u64).wrapping_mul(0x1000_0001),
    );
    let bends: Vec<(f64, [f64; 3])> = class
        .limbs
        .iter()
        .map(|_| {
            (
                rng.range(-options.max_bend, options.max_bend),
                rng.direction(),
            )
        })
        .collect();
    let posed = pose(class, options.level, &bends);
    let span = options.max_vertices.saturating_sub(options.min_vertices) as f64;
    let count = (options.min_vertices as f64 + rng.range(0.0, span + 1.0)).floor() as usize;
    let count = count.min(posed.num_vertices());
    let remeshed = remesh(
        &posed,
        &RemeshOptions {
            count,
            adaptation: Adaptation::Uniform,
            lloyd_iterations: Some(1),
            max_repairs: 8,
            smoothing_iterations: Some(0),
            // Exact: the benchmark's shapes stay those it was measured on.
            sampling: Sampling::Exact,
        },
        control,
    )?
    .mesh;
    let h = remeshed.mean_edge_length();
    let axis = rng.direction();
    let angle = rng.range(0.0, std::f64::consts::TAU);
    let scale = 2f64.powf(rng.range(-1.0, 1.0));
    let shift = [
        rng.range(-5.0, 5.0),
        rng.range(-5.0, 5.0),
        rng.range(-5.0, 5.0),
    ];
    let positions: Vec<[f64; 3]> = remeshed
        .positions()
        .iter()
        .map(|&p| {
            let jitter = [
                options.noise * h * rng.range(-1.0, 1.0),
                options.noise * h * rng.range(-1.0, 1.0),
                options.noise * h * rng.range(-1.0, 1.0),
            ];
            let q = rotate(axpy(1.0, jitter, p), axis, angle);
            [
                scale * q[0] + shift[0],
                scale * q[1] + shift[1],
                scale * q[2] + shift[2],
            ]
        })
        .collect();
    Ok(TriMesh::from_parts_unchecked(
        positions,
        remeshed.faces().to_vec(),
    ))
}

/// Retrieval scores of a distance matrix over labelled shapes, as the
/// Princeton Shape Benchmark defines them (Shilane et al. 2004). Each shape
/// queries all the others, ranked by increasing distance (ties by index);
/// with `C` the size of its class:
///
/// * nearest neighbour: the first result is of its class;
/// * first tier: the fraction of the `C − 1` others of its class in the
///   first `C − 1` results; second tier: in the first `2(C − 1)`;
/// * DCG: `Σᵢ Gᵢ / log₂(i)` (`G₁` for `i = 1`), `Gᵢ = 1` when the `i`-th
///   result is of its class, divided by the same sum for the ideal ranking.
///
/// Each score is the mean over the queries (shapes alone in their class
/// are skipped), in `[0, 1]`, 1 for perfect retrieval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetrievalScores {
    /// Nearest-neighbour accuracy.
    pub nearest_neighbour: f64,
    /// First tier.
    pub first_tier: f64,
    /// Second tier.
    pub second_tier: f64,
    /// Normalised discounted cumulative gain.
    pub dcg: f64,
    /// Queries scored.
    pub queries: usize,
}

/// The [`RetrievalScores`] of the `n × n` matrix `distance` (row `q`: the
/// distances from shape `q`) with `labels[q]` the class of shape `q`.
pub fn retrieval_scores(distance: &[Vec<f64>], labels: &[usize]) -> RetrievalScores {
    let n = labels.len();
    let (mut nn, mut ft, mut st, mut dcg, mut queries) = (0.0, 0.0, 0.0, 0.0, 0usize);
    for q in 0..n {
        let c = labels.iter().filter(|&&l| l == labels[q]).count();
        if c < 2 || distance.get(q).is_none_or(|r| r.len() != n) {
            continue;
        }
        let mut order: Vec<usize> = (0..n).filter(|&j| j != q).collect();
        order.sort_by(|&a, &b| distance[q][a].total_cmp(&distance[q][b]).then(a.cmp(&b)));
        let hit: Vec<bool> = order.iter().map(|&j| labels[j] == labels[q]).collect();
        let rel = (c - 1) as f64;
        nn += f64::from(u8::from(hit[0]));
        ft += hit.iter().take(c - 1).filter(|&&h| h).count() as f64 / rel;
        st += hit.iter().take(2 * (c - 1)).filter(|&&h| h).count() as f64 / rel;
        let gain = |i: usize| {
            if i == 0 {
                1.0
            } else {
                1.0 / ((i + 1) as f64).log2()
            }
        };
        let got: f64 = hit
            .iter()
            .enumerate()
            .filter(|(_, h)| **h)
            .map(|(i, _)| gain(i))
            .sum();
        let ideal: f64 = (0..c - 1).map(gain).sum();
        dcg += got / ideal;
        queries += 1;
    }
    let m = queries.max(1) as f64;
    RetrievalScores {
        nearest_neighbour: nn / m,
        first_tier: ft / m,
        second_tier: st / m,
        dcg: dcg / m,
        queries,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::Topology;

    #[test]
    fn poses_are_closed_connected_surfaces_with_new_triangulations() {
        let options = BenchmarkOptions {
            level: 3,
            min_vertices: 200,
            max_vertices: 300,
            ..Default::default()
        };
        let classes = classes();
        assert!(classes.len() >= 10);
        for (ci, class) in classes.iter().enumerate().take(3) {
            let a = benchmark_shape(class, ci, 0, &options, &Control::new()).unwrap();
            let b = benchmark_shape(class, ci, 1, &options, &Control::new()).unwrap();
            for m in [&a, &b] {
                let t = Topology::new(m);
                assert_eq!(t.components, 1, "{}", class.name);
                assert!(
                    (200..=330).contains(&m.num_vertices()),
                    "{}",
                    m.num_vertices()
                );
            }
            assert_ne!(a.faces(), b.faces());
            // Deterministic.
            let again = benchmark_shape(class, ci, 0, &options, &Control::new()).unwrap();
            assert_eq!(again, a);
        }
    }

    #[test]
    fn scores_of_perfect_and_inverted_rankings() {
        let labels = [0, 0, 0, 1, 1, 1];
        let perfect: Vec<Vec<f64>> = (0..6)
            .map(|i| {
                (0..6)
                    .map(|j| if labels[i] == labels[j] { 0.1 } else { 1.0 })
                    .collect()
            })
            .collect();
        let s = retrieval_scores(&perfect, &labels);
        assert_eq!(
            (s.nearest_neighbour, s.first_tier, s.second_tier, s.dcg),
            (1.0, 1.0, 1.0, 1.0)
        );
        assert_eq!(s.queries, 6);
        let inverted: Vec<Vec<f64>> = perfect
            .iter()
            .map(|r| r.iter().map(|x| 1.0 / x).collect())
            .collect();
        let s = retrieval_scores(&inverted, &labels);
        assert_eq!((s.nearest_neighbour, s.first_tier), (0.0, 0.0));
        assert_eq!(s.second_tier, 0.5);
        assert!(s.dcg < 0.5);
    }
}
