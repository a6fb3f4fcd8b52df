//! Correspondence between two near-isometric meshes (the monograph's
//! §5.3): for every vertex `v` of `A`, a point of `B` (a face and
//! barycentric coordinates) whose geodesic distances to matched landmarks
//! are those of `v`, with a confidence.
//!
//! **Method: canonical forms, rigid alignment, then refinement by geodesic
//! distances to matched landmarks** (coarse to fine). Generalised MDS
//! (Bronstein, Bronstein and Kimmel) embeds `A` into `B` directly, but it
//! needs the all-pairs distances of `B` (or their interpolation over faces)
//! and a good start to avoid local minima; the canonical forms give that
//! start from landmark rows only, and the landmark distances of the last
//! step already reach the accuracy of the distance solver, so the GMDS step
//! would add cost without a measurable gain on near-isometric pairs.
//!
//! 1. **Canonical forms** ([`super::canonical`], Elad and Kimmel): `k`
//!    farthest-point landmarks on each mesh, their distance rows, landmark
//!    MDS into `R³` on principal axes. Isometric shapes have the same form
//!    up to a rigid motion and a reflection.
//! 2. **Rigid alignment, every flip**: ICP (nearest neighbours in `B`'s
//!    form, [`super::procrustes::align`] without reflection) from 56 starts:
//!    the 8 sign flips of the principal axes (the reflection ambiguity of
//!    MDS), each composed with rotations by `π/4`, `π/2`, `3π/4` about the
//!    first and the third axis (their variances may tie, as on a tube, where
//!    the axes are arbitrary in a plane). Starts that end at the same map
//!    (the anchors below land within 5 % of the form's diameter of each
//!    other) are merged, keeping the smallest ICP residual.
//! 3. **Distinct maps by geodesic distortion**: the first `q` landmarks of
//!    `A` (anchors, the extremities found first by farthest-point sampling)
//!    are carried to their nearest vertices `mᵢ` of `B` by each alignment,
//!    which is scored by the mean over pairs of `|d_A(aᵢ, aⱼ) − d_B(mᵢ, mⱼ)|`
//!    over the geodesic diameter of `A` (estimated as the largest landmark
//!    distance). Alignments are grouped: two are the same map when the
//!    images of the anchors are on average less than [`SEPARATION`] (10 %)
//!    of the diameter apart on `B` (geodesically), the jitter of nearest
//!    neighbours. The best-scored alignment of each of the (at most) 3 best
//!    groups is a contender.
//! 4. **Landmark matching, and the choice**: for each contender, every
//!    landmark `lᵢ` of `A` goes to the nearest vertex `mᵢ` of `B` through
//!    the alignment, then `rounds` times (default 2) each `mᵢ` is moved to
//!    the vertex `w` of `B` minimising `Σ_{j≠i} (d_A(lᵢ, lⱼ) − d_B(w, mⱼ))²`
//!    (leave-one-out: the other landmarks locate it, so independent errors
//!    average out). The contender with the smallest distortion over all
//!    landmark pairs wins. An intrinsic symmetry (a mirror image, a
//!    rotation) shows as a second, distinct contender that fits almost as
//!    well: the pair is reported **symmetric** when the best distinct
//!    alternative's distortion is at most `symmetry_ratio × best +
//!    symmetry_margin` (1.5 and 0.002 by default), with both values, so
//!    that a caller can tell a confident choice from a coin toss. (The
//!    scores of exact isometries are about 1e-4; those of their mirror
//!    images, on the asymmetric test shapes, above 3e-3.)
//! 5. **Refinement**: vertex `v` of `A` has the descriptor
//!    `δ_v = (d_A(v, lᵢ))ᵢ`; its match is the vertex `w` of `B` minimising
//!    `|δ_v − (d_B(w, mᵢ))ᵢ|²`, found by descent over `B`'s vertex graph
//!    from the best of the 8 nearest vertices to `v`'s aligned canonical
//!    position; then, over the faces around `w`, the point
//!    `λ₀ w₀ + λ₁ w₁ + λ₂ w₂` (barycentric `λ` in the simplex) minimising
//!    `|Σ_c λ_c D_B[:, w_c] − δ_v|²` (distance rows interpolated linearly
//!    over the face: a 2 × 2 least-squares problem, clamped to the simplex).
//!
//! **Confidence** `exp(−r/σ)` in `(0, 1]`, with `r = sqrt(mean_i (Σ_c λ_c
//! D_B[i, w_c] − δ_v[i])²)` the landmark-distance residual of the match and
//! `σ = 2 %` of `A`'s diameter: 1 for distances matched exactly, `1/e` for a
//! residual of 2 % of the diameter (the scale of the solver's own error on
//! coarse meshes).
//!
//! The vertex indices of the two meshes play no part: only their distances.
//! Both meshes must be connected (distances between components are
//! infinite); the caller compares their areas (an isometry keeps them).

use std::collections::HashMap;

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use super::knn::KdTree;
use super::matrix::{distance_rows, landmarks, Symmetry};
use super::mds::landmark_mds;
use super::procrustes::align;
use super::ShapeError;
use crate::numerics::mesh::{MeshMethod, Topology, TriMesh};
use crate::numerics::Control;

/// Options of [`correspond`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CorrespondOptions {
    /// Farthest-point landmarks on each mesh (at least 8). Default 60.
    pub landmarks: usize,
    /// Anchors scoring the alignments (the first landmarks of `A`, at
    /// least 4, at most `landmarks`). Default 12.
    pub anchors: usize,
    /// Leave-one-out landmark re-matching rounds. Default 2.
    pub rounds: usize,
    /// Distance method for every row. Default fast marching.
    pub method: MeshMethod,
    /// Symmetric when the second distinct distortion is at most
    /// `symmetry_ratio × best + symmetry_margin`. Default 1.5.
    pub symmetry_ratio: f64,
    /// See `symmetry_ratio`; a fraction of the diameter. Default 0.002.
    pub symmetry_margin: f64,
}

impl Default for CorrespondOptions {
    fn default() -> Self {
        Self {
            landmarks: 60,
            anchors: 12,
            rounds: 2,
            method: MeshMethod::FastMarching,
            symmetry_ratio: 1.5,
            symmetry_margin: 0.002,
        }
    }
}

/// A distinct rigid alignment of the canonical forms.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// ICP's root mean square nearest-neighbour distance, over the
    /// canonical diameter of `B`.
    pub icp_residual: f64,
    /// Mean anchor distortion over `A`'s diameter (step 3).
    pub distortion: f64,
    /// `−1` when the alignment reflects the canonical form, `+1` otherwise.
    pub determinant: f64,
    /// Mean geodesic distance on `B` between the images of the anchors by
    /// this map and by the chosen one, over `A`'s diameter.
    pub separation: f64,
    /// For the best map of each group (at most 3 groups): the mean
    /// distortion of all landmark pairs after re-matching (step 4), over
    /// `A`'s diameter; the smallest is chosen.
    pub refined: Option<f64>,
}

/// Least [`Candidate::separation`] of a map distinct from the best one.
pub const SEPARATION: f64 = 0.1;

/// A correspondence from `A` to `B`.
#[derive(Debug, Clone, PartialEq)]
pub struct Correspondence {
    /// Face of `B` holding the match of each vertex of `A`.
    pub face: Vec<u32>,
    /// Barycentric coordinates of the match in that face (sum 1, each ≥ 0).
    pub bary: Vec<[f64; 3]>,
    /// The vertex of `B` nearest the match (largest barycentric weight).
    pub vertex: Vec<u32>,
    /// `exp(−r/σ)` (see the module docs).
    pub confidence: Vec<f64>,
    /// Landmark-distance residual `r` of each match.
    pub residual: Vec<f64>,
    /// Landmarks of `A`.
    pub landmarks_a: Vec<u32>,
    /// Their matched vertices on `B`, after re-matching.
    pub landmarks_b: Vec<u32>,
    /// The distinct alignments, best (chosen) first.
    pub candidates: Vec<Candidate>,
    /// A second distinct alignment fits almost as well (step 3).
    pub symmetric: bool,
    /// The distortion of the best map distinct from the chosen one (its
    /// separation at least [`SEPARATION`]), if any.
    pub alternative: Option<f64>,
    /// Diameter of `A` estimated from its landmark rows.
    pub diameter: f64,
    /// `σ` of the confidence.
    pub confidence_scale: f64,
}

/// Rigid alignment of `A`'s canonical form: `x ↦ x · linear + shift`.
struct Fit {
    linear: Array2<f64>,
    shift: [f64; 3],
    rms: f64,
    anchors: Vec<u32>,
}

/// Matches every vertex of `a` to a point of `b` (see the module docs).
pub fn correspond(
    a: &TriMesh,
    ta: &Topology,
    b: &TriMesh,
    tb: &Topology,
    options: &CorrespondOptions,
    control: &Control<'_>,
) -> Result<Correspondence, ShapeError> {
    if options.landmarks < 8 {
        return Err(ShapeError::InvalidOption {
            option: "landmarks",
            reason: format!("at least 8 are needed, got {}", options.landmarks),
        });
    }
    if options.anchors < 4 || options.anchors > options.landmarks {
        return Err(ShapeError::InvalidOption {
            option: "anchors",
            reason: format!("must be between 4 and landmarks, got {}", options.anchors),
        });
    }
    if !(options.symmetry_ratio >= 1.0 && options.symmetry_ratio.is_finite()) {
        return Err(ShapeError::InvalidOption {
            option: "symmetry_ratio",
            reason: "must be finite and >= 1".into(),
        });
    }
    for t in [ta, tb] {
        if t.components > 1 {
            return Err(ShapeError::Disconnected {
                what: "mesh",
                components: t.components,
                hint: "correspond each component on its own (split the mesh, drop unused vertices)",
            });
        }
    }
    let inner = control.cancel_only();
    let cancelled = || {
        if control.is_cancelled() {
            Err(ShapeError::Cancelled)
        } else {
            Ok(())
        }
    };
    // 1. Landmark rows and canonical forms.
    let la = landmarks(a, ta, options.landmarks, &inner)?;
    let lb = landmarks(b, tb, options.landmarks, &inner)?;
    if la.len() < 8 || lb.len() < 8 {
        return Err(ShapeError::InvalidOption {
            option: "landmarks",
            reason: "each mesh needs at least 8 vertices".into(),
        });
    }
    let ra = distance_rows(a, ta, &la, options.method, None, Symmetry::Average, &inner)?;
    control.report(0.15);
    let rb = distance_rows(b, tb, &lb, options.method, None, Symmetry::Average, &inner)?;
    control.report(0.3);
    let cols = |l: &[u32]| l.iter().map(|&v| v as usize).collect::<Vec<_>>();
    let ca = landmark_mds(ra.rows.view(), &cols(&la), 3, &inner)?.coords;
    let cb = landmark_mds(rb.rows.view(), &cols(&lb), 3, &inner)?.coords;
    let diameter = ra.rows.iter().fold(0.0f64, |m, &x| m.max(x));
    if !(diameter > 0.0 && diameter.is_finite()) {
        return Err(ShapeError::Numerical("the first mesh has no extent".into()));
    }
    let cdiam = 2.0
        * cb.rows()
            .into_iter()
            .map(|r| r.dot(&r).sqrt())
            .fold(0.0f64, f64::max)
            .max(f64::MIN_POSITIVE);
    // 2. ICP from every start, on a subsample of A's form.
    let tree = KdTree::new(cb.view());
    let stride = (a.num_vertices() / 400).max(1);
    let sample: Vec<usize> = (0..a.num_vertices()).step_by(stride).collect();
    let pts = Array2::from_shape_fn((sample.len(), 3), |(i, c)| ca[[sample[i], c]]);
    let q = options.anchors.min(la.len());
    let anchor_pts = Array2::from_shape_fn((q, 3), |(i, c)| ca[[la[i] as usize, c]]);
    let mut fits: Vec<Fit> = Vec::new();
    for start in starts() {
        cancelled()?;
        let mut fit = icp(pts.view(), &tree, cb.view(), &start)?;
        fit.rms /= cdiam;
        fit.anchors = carry(anchor_pts.view(), &fit, &tree);
        fits.push(fit);
    }
    fits.sort_by(|x, y| x.rms.total_cmp(&y.rms));
    let mut distinct: Vec<Fit> = Vec::new();
    for f in fits {
        let same = distinct.iter().any(|d| {
            let mean = f
                .anchors
                .iter()
                .zip(&d.anchors)
                .map(|(&p, &r)| dist(cb.row(p as usize).as_slice(), cb.row(r as usize).as_slice()))
                .sum::<f64>()
                / q as f64;
            mean < 0.05 * cdiam
        });
        if !same && distinct.len() < 16 {
            distinct.push(f);
        }
    }
    control.report(0.4);
    // 3. Geodesic distortion of the anchors.
    let mut cache = RowCache::default();
    let needed: Vec<u32> = distinct.iter().flat_map(|f| f.anchors.clone()).collect();
    cache.fill(b, tb, &needed, options.method, &inner)?;
    let da = |i: usize, j: usize| ra.rows[[i, la[j] as usize]];
    let mut scored: Vec<(Fit, Candidate)> = distinct
        .into_iter()
        .map(|f| {
            let c = Candidate {
                icp_residual: f.rms,
                distortion: distortion(&f.anchors, &da, &cache) / diameter,
                determinant: det3(&f.linear).signum(),
                separation: 0.0,
                refined: None,
            };
            (f, c)
        })
        .collect();
    scored.sort_by(|x, y| x.1.distortion.total_cmp(&y.1.distortion));
    // Distinct maps: the best of each group of maps whose anchors land
    // within SEPARATION of each other; the best CONTENDERS are refined.
    let mut heads: Vec<usize> = Vec::new();
    for i in 0..scored.len() {
        let far = heads.iter().all(|&h| {
            separation(&scored[i].0.anchors, &scored[h].0.anchors, &cache) / diameter >= SEPARATION
        });
        if far && heads.len() < CONTENDERS {
            heads.push(i);
        }
    }
    control.report(0.45);
    // 4. Landmark matches of each contender, re-matched leave-one-out, and
    // the distortion of all landmark pairs.
    let k = la.len();
    let lpts = Array2::from_shape_fn((k, 3), |(i, c)| ca[[la[i] as usize, c]]);
    let mut refined: Vec<(usize, Vec<u32>, f64)> = Vec::new();
    for &h in &heads {
        cancelled()?;
        let mut m = carry(lpts.view(), &scored[h].0, &tree);
        cache.fill(b, tb, &m, options.method, &inner)?;
        for _ in 0..options.rounds {
            let next = rematch(&m, &cache, &da, b.num_vertices(), &inner);
            cancelled()?;
            if next == m {
                break;
            }
            m = next;
            cache.fill(b, tb, &m, options.method, &inner)?;
        }
        let d = distortion(&m, &da, &cache) / diameter;
        scored[h].1.refined = Some(d);
        refined.push((h, m, d));
    }
    refined.sort_by(|x, y| x.2.total_cmp(&y.2));
    let (chosen, m, best_d) = refined
        .first()
        .cloned()
        .ok_or_else(|| ShapeError::Numerical("no alignment".into()))?;
    let alternative = refined
        .iter()
        .skip(1)
        .find(|r| separation(&r.1, &m, &cache) / diameter >= SEPARATION)
        .map(|r| r.2);
    let symmetric =
        alternative.is_some_and(|d| d <= options.symmetry_ratio * best_d + options.symmetry_margin);
    for i in 0..scored.len() {
        let sep = separation(&scored[i].0.anchors, &scored[chosen].0.anchors, &cache) / diameter;
        scored[i].1.separation = sep;
    }
    // The chosen map first, then the other contenders, then the rest.
    let mut order: Vec<usize> = refined.iter().map(|r| r.0).collect();
    order.extend((0..scored.len()).filter(|i| !heads.contains(i)));
    let candidates: Vec<Candidate> = order.iter().map(|&i| scored[i].1.clone()).collect();
    let best = &scored[chosen].0;
    control.report(0.7);
    // 5. Per-vertex refinement.
    let rows: Vec<&[f64]> = m.iter().map(|&v| cache.row(v)).collect();
    let neighbours = vertex_neighbours(b, tb);
    let na = a.num_vertices();
    let sigma = 0.02 * diameter;
    let matches: Vec<(u32, [f64; 3], u32, f64)> = (0..na)
        .into_par_iter()
        .map(|v| {
            if inner.is_cancelled() {
                return (0, [1.0, 0.0, 0.0], 0, f64::INFINITY);
            }
            let target: Vec<f64> = (0..k).map(|i| ra.rows[[i, v]]).collect();
            let cost = |w: u32| -> f64 {
                rows.iter()
                    .zip(&target)
                    .map(|(r, t)| (r[w as usize] - t) * (r[w as usize] - t))
                    .sum()
            };
            let x = transform(ca.row(v).as_slice().unwrap_or(&[0.0; 3][..]), best);
            let mut w = tree
                .nearest(&x, 8, None)
                .into_iter()
                .map(|(i, _)| (cost(i), i))
                .min_by(|p, q| p.0.total_cmp(&q.0))
                .map_or(0, |p| p.1);
            let mut c = cost(w);
            loop {
                let step = neighbours[w as usize]
                    .iter()
                    .map(|&u| (cost(u), u))
                    .min_by(|p, q| p.0.total_cmp(&q.0));
                match step {
                    Some((cu, u)) if cu < c => {
                        c = cu;
                        w = u;
                    }
                    _ => break,
                }
            }
            let mut out = (0u32, [1.0, 0.0, 0.0], w, c);
            let mut bestc = f64::INFINITY;
            for &f in tb.faces_of(w) {
                let face = b.faces()[f as usize];
                let cols: [Vec<f64>; 3] =
                    face.map(|u| rows.iter().map(|r| r[u as usize]).collect());
                let (lam, cf) = simplex_fit(&cols, &target);
                if cf < bestc {
                    bestc = cf;
                    let vtx = (0..3)
                        .max_by(|&i, &j| lam[i].total_cmp(&lam[j]))
                        .map_or(face[0], |i| face[i]);
                    out = (f, lam, vtx, cf);
                }
            }
            out
        })
        .collect();
    cancelled()?;
    control.report(1.0);
    let residual: Vec<f64> = matches
        .iter()
        .map(|t| (t.3.max(0.0) / k as f64).sqrt())
        .collect();
    Ok(Correspondence {
        face: matches.iter().map(|t| t.0).collect(),
        bary: matches.iter().map(|t| t.1).collect(),
        vertex: matches.iter().map(|t| t.2).collect(),
        confidence: residual.iter().map(|r| (-r / sigma).exp()).collect(),
        residual,
        landmarks_a: la,
        landmarks_b: m,
        candidates,
        symmetric,
        alternative,
        diameter,
        confidence_scale: sigma,
    })
}

/// Most distinct maps refined in step 4.
const CONTENDERS: usize = 3;

/// Mean over pairs of `|d_A(lᵢ, lⱼ) − d_B(mᵢ, mⱼ)|`, with `d_A(i, j)` the
/// distance between the `i`-th and `j`-th landmarks of `A`.
fn distortion(m: &[u32], da: &(impl Fn(usize, usize) -> f64 + Sync), cache: &RowCache) -> f64 {
    let mut sum = 0.0;
    let mut pairs = 0usize;
    for i in 0..m.len() {
        for j in 0..i {
            sum += (da(i, j) - cache.between(m[i], m[j])).abs();
            pairs += 1;
        }
    }
    sum / pairs.max(1) as f64
}

/// Mean geodesic distance on `B` between `p[i]` and `r[i]`.
fn separation(p: &[u32], r: &[u32], cache: &RowCache) -> f64 {
    p.iter()
        .zip(r)
        .map(|(&x, &y)| cache.between(x, y))
        .sum::<f64>()
        / p.len().max(1) as f64
}

/// One leave-one-out round: each `mᵢ` moves to the vertex `w` of `B`
/// minimising `Σ_{j≠i} (d_A(lᵢ, lⱼ) − d_B(w, mⱼ))²`.
fn rematch(
    m: &[u32],
    cache: &RowCache,
    da: &(impl Fn(usize, usize) -> f64 + Sync),
    nb: usize,
    control: &Control<'_>,
) -> Vec<u32> {
    let k = m.len();
    let rows: Vec<&[f64]> = m.iter().map(|&v| cache.row(v)).collect();
    (0..k)
        .into_par_iter()
        .map(|i| {
            let mut top = (f64::INFINITY, m[i]);
            if control.is_cancelled() {
                return top.1;
            }
            for w in 0..nb {
                let mut s = 0.0;
                for j in (0..k).filter(|&j| j != i) {
                    let e = da(j, i) - rows[j].get(w).copied().unwrap_or(f64::INFINITY);
                    s += e * e;
                    if s >= top.0 {
                        break;
                    }
                }
                if s < top.0 {
                    top = (s, w as u32);
                }
            }
            top.1
        })
        .collect()
}

/// Distance rows of `B` from single vertices, solved once each.
#[derive(Default)]
struct RowCache {
    rows: HashMap<u32, Vec<f64>>,
}

impl RowCache {
    fn fill(
        &mut self,
        b: &TriMesh,
        tb: &Topology,
        sources: &[u32],
        method: MeshMethod,
        control: &Control<'_>,
    ) -> Result<(), ShapeError> {
        let mut missing: Vec<u32> = sources
            .iter()
            .copied()
            .filter(|s| !self.rows.contains_key(s))
            .collect();
        missing.sort_unstable();
        missing.dedup();
        if missing.is_empty() {
            return Ok(());
        }
        let r = distance_rows(b, tb, &missing, method, None, Symmetry::None, control)?;
        for (i, s) in missing.iter().enumerate() {
            self.rows.insert(*s, r.rows.row(i).to_vec());
        }
        Ok(())
    }

    fn row(&self, s: u32) -> &[f64] {
        self.rows.get(&s).map_or(&[] as &[f64], Vec::as_slice)
    }

    /// `(d(s, t) + d(t, s)) / 2`.
    fn between(&self, s: u32, t: u32) -> f64 {
        let x = self
            .row(s)
            .get(t as usize)
            .copied()
            .unwrap_or(f64::INFINITY);
        let y = self
            .row(t)
            .get(s as usize)
            .copied()
            .unwrap_or(f64::INFINITY);
        0.5 * (x + y)
    }
}

/// The 56 starting linear maps (row-vector convention): sign flips of the
/// axes, each after a rotation by `jπ/4` about axis 0 (j = 0..3) or axis 2
/// (j = 1..3).
fn starts() -> Vec<Array2<f64>> {
    let mut out = Vec::with_capacity(56);
    let turns = [(0, 0), (0, 1), (0, 2), (0, 3), (2, 1), (2, 2), (2, 3)];
    for s in 0..8u32 {
        let sign = Array2::from_shape_fn((3, 3), |(i, j)| {
            if i != j {
                0.0
            } else if s & (1 << i) != 0 {
                -1.0
            } else {
                1.0
            }
        });
        for (axis, j) in turns {
            let t = std::f64::consts::FRAC_PI_4 * j as f64;
            let (c, sn) = (t.cos(), t.sin());
            let (p, q) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut r = Array2::<f64>::eye(3);
            r[[p, p]] = c;
            r[[q, q]] = c;
            r[[p, q]] = -sn;
            r[[q, p]] = sn;
            out.push(r.dot(&sign));
        }
    }
    out
}

/// ICP of `pts · start` onto `B`'s form (proper rotations only).
fn icp(
    pts: ArrayView2<'_, f64>,
    tree: &KdTree<'_>,
    cb: ArrayView2<'_, f64>,
    start: &Array2<f64>,
) -> Result<Fit, ShapeError> {
    let p0 = pts.dot(start);
    let mut cur = p0.clone();
    let mut linear = Array2::<f64>::eye(3);
    let mut shift = ndarray::Array1::<f64>::zeros(3);
    let mut last = f64::INFINITY;
    let mut rms = f64::INFINITY;
    for _ in 0..40 {
        let mut targets = Array2::<f64>::zeros(cur.dim());
        let mut sq = 0.0;
        for (i, row) in cur.rows().into_iter().enumerate() {
            let x = [row[0], row[1], row[2]];
            let (j, d2) = tree
                .nearest(&x, 1, None)
                .first()
                .copied()
                .unwrap_or((0, 0.0));
            sq += d2;
            targets.row_mut(i).assign(&cb.row(j as usize));
        }
        rms = (sq / cur.nrows().max(1) as f64).sqrt();
        if last - rms <= 1e-9 * last.min(1e300) {
            break;
        }
        last = rms;
        let al = align(p0.view(), targets.view(), false)?;
        linear = al.rotation;
        shift = al.translation;
        cur = al.aligned;
    }
    Ok(Fit {
        linear: start.dot(&linear),
        shift: [shift[0], shift[1], shift[2]],
        rms,
        anchors: Vec::new(),
    })
}

fn transform(x: &[f64], fit: &Fit) -> [f64; 3] {
    let mut y = fit.shift;
    for (c, yc) in y.iter_mut().enumerate() {
        for (r, xr) in x.iter().enumerate().take(3) {
            *yc += xr * fit.linear[[r, c]];
        }
    }
    y
}

/// The nearest vertices of `B`'s form to the aligned rows of `pts`.
fn carry(pts: ArrayView2<'_, f64>, fit: &Fit, tree: &KdTree<'_>) -> Vec<u32> {
    pts.rows()
        .into_iter()
        .map(|r| {
            let x = transform(&[r[0], r[1], r[2]], fit);
            tree.nearest(&x, 1, None).first().map_or(0, |p| p.0)
        })
        .collect()
}

fn dist(x: Option<&[f64]>, y: Option<&[f64]>) -> f64 {
    match (x, y) {
        (Some(x), Some(y)) => x
            .iter()
            .zip(y)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt(),
        _ => f64::INFINITY,
    }
}

fn det3(m: &Array2<f64>) -> f64 {
    m[[0, 0]] * (m[[1, 1]] * m[[2, 2]] - m[[1, 2]] * m[[2, 1]])
        - m[[0, 1]] * (m[[1, 0]] * m[[2, 2]] - m[[1, 2]] * m[[2, 0]])
        + m[[0, 2]] * (m[[1, 0]] * m[[2, 1]] - m[[1, 1]] * m[[2, 0]])
}

/// The vertices sharing a face with each vertex.
fn vertex_neighbours(mesh: &TriMesh, topo: &Topology) -> Vec<Vec<u32>> {
    (0..mesh.num_vertices() as u32)
        .map(|v| {
            let mut n: Vec<u32> = topo
                .faces_of(v)
                .iter()
                .flat_map(|&f| mesh.faces()[f as usize])
                .filter(|&u| u != v)
                .collect();
            n.sort_unstable();
            n.dedup();
            n
        })
        .collect()
}

/// `min |Σ_c λ_c cols[c] − t|²` over the simplex (`λ ≥ 0`, `Σ λ = 1`): the
/// unconstrained minimum in `(λ₁, λ₂)` with `λ₀ = 1 − λ₁ − λ₂` if it lies
/// inside, otherwise the best clamped minimum along the three edges.
fn simplex_fit(cols: &[Vec<f64>; 3], t: &[f64]) -> ([f64; 3], f64) {
    let cost = |l: [f64; 3]| -> f64 {
        (0..t.len())
            .map(|i| {
                let e = l[0] * cols[0][i] + l[1] * cols[1][i] + l[2] * cols[2][i] - t[i];
                e * e
            })
            .sum()
    };
    // r = c0 − t, e1 = c1 − c0, e2 = c2 − c0: minimise |r + s e1 + u e2|².
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for i in 0..t.len() {
        let r = cols[0][i] - t[i];
        let e1 = cols[1][i] - cols[0][i];
        let e2 = cols[2][i] - cols[0][i];
        a11 += e1 * e1;
        a12 += e1 * e2;
        a22 += e2 * e2;
        b1 -= e1 * r;
        b2 -= e2 * r;
    }
    let det = a11 * a22 - a12 * a12;
    if det.abs() > 1e-14 * (a11 * a22).max(f64::MIN_POSITIVE) {
        let s = (b1 * a22 - b2 * a12) / det;
        let u = (a11 * b2 - a12 * b1) / det;
        if s >= 0.0 && u >= 0.0 && s + u <= 1.0 {
            let l = [1.0 - s - u, s, u];
            return (l, cost(l));
        }
    }
    // On the edge from vertex p to vertex q: λ_p = 1 − x, λ_q = x.
    let mut best = ([1.0, 0.0, 0.0], f64::INFINITY);
    for (p, q) in [(0, 1), (1, 2), (2, 0)] {
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..t.len() {
            let e = cols[q][i] - cols[p][i];
            num -= e * (cols[p][i] - t[i]);
            den += e * e;
        }
        let x = if den > 0.0 {
            (num / den).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let mut l = [0.0; 3];
        l[p] = 1.0 - x;
        l[q] = x;
        let c = cost(l);
        if c < best.1 {
            best = (l, c);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::mesh::shapes::flat_square;
    use std::sync::atomic::AtomicBool;

    #[test]
    fn the_simplex_fit_finds_inner_and_edge_minima() {
        let cols = [vec![0.0, 0.0], vec![1.0, 0.0], vec![0.0, 1.0]];
        let (l, c) = simplex_fit(&cols, &[0.25, 0.5]);
        assert!((l[1] - 0.25).abs() < 1e-12 && (l[2] - 0.5).abs() < 1e-12 && c < 1e-20);
        // Outside, beyond the edge from 1 to 2: the nearest point of it.
        let (l, c) = simplex_fit(&cols, &[1.0, 1.0]);
        assert!(
            (l[1] - 0.5).abs() < 1e-12 && (l[2] - 0.5).abs() < 1e-12,
            "{l:?}"
        );
        assert!((c - 0.5).abs() < 1e-12);
        assert!(l.iter().all(|&x| x >= 0.0));
    }

    #[test]
    fn the_starts_are_orthogonal_and_include_every_flip() {
        let s = starts();
        assert_eq!(s.len(), 56);
        let flips = s.iter().filter(|m| det3(m) < 0.0).count();
        assert_eq!(flips, 28);
        for m in &s {
            let e = m.t().dot(m) - Array2::<f64>::eye(3);
            assert!(e.iter().all(|x| x.abs() < 1e-12));
        }
    }

    /// A flat right trapezoid (no symmetry), and the same with its vertices
    /// shuffled and moved rigidly: the map must be found without indices.
    fn trapezoid(n: usize) -> TriMesh {
        let m = flat_square(n, 1.0, 0.0);
        let pos = m
            .positions()
            .iter()
            .map(|p| [2.0 * p[0], p[1] * (0.5 + 0.5 * p[0]), 0.0])
            .collect();
        TriMesh::new(pos, m.faces().to_vec()).unwrap()
    }

    #[test]
    fn a_shuffled_moved_copy_is_matched_without_its_indices() {
        let a = trapezoid(14);
        let n = a.num_vertices();
        // Permutation v -> (7 v + 3) mod n (n = 225 is coprime with 7).
        let perm: Vec<u32> = (0..n).map(|v| ((7 * v + 3) % n) as u32).collect();
        let mut pos = vec![[0.0; 3]; n];
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        for v in 0..n {
            let p = a.positions()[v];
            pos[perm[v] as usize] = [c * p[0] - s * p[1] + 3.0, s * p[0] + c * p[1], -p[1] + 1.0];
        }
        let faces = a
            .faces()
            .iter()
            .map(|f| f.map(|v| perm[v as usize]))
            .collect();
        let b = TriMesh::new(pos, faces).unwrap();
        let opts = CorrespondOptions {
            landmarks: 20,
            anchors: 8,
            ..Default::default()
        };
        let r = correspond(
            &a,
            &Topology::new(&a),
            &b,
            &Topology::new(&b),
            &opts,
            &Control::new(),
        )
        .unwrap();
        // Error of each match: the distance in A between the preimage of the
        // matched point and the vertex (flat: Euclidean = geodesic); the
        // diameter is 2.06.
        let mut inverse = vec![0usize; n];
        for (v, &p) in perm.iter().enumerate() {
            inverse[p as usize] = v;
        }
        let errors: Vec<f64> = (0..n)
            .map(|v| {
                let face = b.faces()[r.face[v] as usize];
                let mut q = [0.0; 2];
                for (c, &u) in face.iter().enumerate() {
                    let pu = a.positions()[inverse[u as usize]];
                    q[0] += r.bary[v][c] * pu[0];
                    q[1] += r.bary[v][c] * pu[1];
                }
                let p = a.positions()[v];
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
            })
            .collect();
        // A smoke test on a coarse mesh (an edge is 7 % of the diameter, 20
        // landmarks): 192 of 225 measured; the accuracy tests on finer
        // meshes are in tests/correspondence.rs.
        let near = errors.iter().filter(|&&e| e <= 0.05 * 2.06).count();
        assert!(
            near as f64 >= 0.8 * n as f64,
            "{near} of {n}: {:?}",
            r.candidates
        );
        for (l, w) in r.bary.iter().zip(&r.confidence) {
            assert!((l.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            assert!(l.iter().all(|&x| x >= 0.0));
            assert!((0.0..=1.0).contains(w));
        }
    }

    #[test]
    fn a_raised_flag_stops_it_and_bad_options_are_named() {
        let a = trapezoid(6);
        let t = Topology::new(&a);
        let flag = AtomicBool::new(true);
        let e = correspond(
            &a,
            &t,
            &a,
            &t,
            &CorrespondOptions {
                landmarks: 10,
                anchors: 4,
                ..Default::default()
            },
            &Control::new().with_cancel(&flag),
        );
        assert_eq!(e, Err(ShapeError::Cancelled));
        let e = correspond(
            &a,
            &t,
            &a,
            &t,
            &CorrespondOptions {
                landmarks: 4,
                ..Default::default()
            },
            &Control::new(),
        );
        assert!(matches!(
            e,
            Err(ShapeError::InvalidOption {
                option: "landmarks",
                ..
            })
        ));
    }
}
