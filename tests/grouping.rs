//! Perceptual grouping by minimal paths (`numerics::grouping`): key points
//! sampled along three noisy circles and a spiral, with clutter, grouped
//! through a cost drawn on the curves (and through a constant cost); the
//! anisotropic grouping on two nearby parallel curves, where the isotropic
//! one mixes them.

use geodex::numerics::grouping::{group, GroupingOptions, GroupingOutput, GroupingProblem};
use geodex::numerics::metric::{CostValues, Interpretation};
use geodex::numerics::{Control, Grid, IsotropicCost};
use std::borrow::Cow;
use std::f64::consts::TAU;

/// A small seeded generator (splitmix64): the scenes are reproducible.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

const N: usize = 200;

/// A curve as a dense polyline (index coordinates) and whether it is closed.
struct Curve {
    dense: Vec<[f64; 2]>,
    closed: bool,
}

/// Three noisy circles (radius perturbed by two random low harmonics) and
/// an Archimedean spiral of turn gap `gap`.
fn curves(rng: &mut Rng, gap: f64) -> Vec<Curve> {
    let mut out = Vec::new();
    for (c, r0) in [
        ([50.0, 50.0], 30.0),
        ([50.0, 148.0], 34.0),
        ([148.0, 50.0], 30.0),
    ] {
        let (a2, p2, a3, p3) = (
            rng.uniform(1.0, 2.5),
            rng.uniform(0.0, TAU),
            rng.uniform(0.5, 1.5),
            rng.uniform(0.0, TAU),
        );
        let dense = (0..2000)
            .map(|k| {
                let t = TAU * k as f64 / 2000.0;
                let r = r0 + a2 * (2.0 * t + p2).sin() + a3 * (3.0 * t + p3).sin();
                [c[0] + r * t.cos(), c[1] + r * t.sin()]
            })
            .collect();
        out.push(Curve {
            dense,
            closed: true,
        });
    }
    let c = [148.0, 148.0];
    let turns = 2.5;
    let dense = (0..4000)
        .map(|k| {
            let t = turns * TAU * k as f64 / 4000.0;
            let r = 6.0 + gap * t / TAU;
            [c[0] + r * t.cos(), c[1] + r * t.sin()]
        })
        .collect();
    out.push(Curve {
        dense,
        closed: false,
    });
    out
}

/// Key points along a curve every `spacing × U(0.8, 1.2)` of arc length,
/// jittered by up to `jitter` cells per axis; their tangent angles.
fn sample(rng: &mut Rng, curve: &Curve, spacing: f64, jitter: f64) -> Vec<([f64; 2], f64)> {
    let d = &curve.dense;
    let mut out = Vec::new();
    let mut next = rng.uniform(0.0, 0.5 * spacing);
    let mut s = 0.0;
    let total: f64 = d.windows(2).map(|w| dist(w[0], w[1])).sum();
    let end = if curve.closed {
        total - 0.7 * spacing
    } else {
        total
    };
    for w in d.windows(2) {
        let step = dist(w[0], w[1]);
        if s + step >= next && next <= end {
            let t = [w[1][0] - w[0][0], w[1][1] - w[0][1]];
            let p = [
                w[0][0] + rng.uniform(-jitter, jitter),
                w[0][1] + rng.uniform(-jitter, jitter),
            ];
            out.push((p, t[1].atan2(t[0])));
            next += spacing * rng.uniform(0.8, 1.2);
        }
        s += step;
    }
    out
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// A cost `low` within `radius` of the drawn curves and 1 elsewhere.
fn drawn_cost(curves: &[Curve], low: f64, radius: f64) -> Vec<f64> {
    let mut w = vec![1.0; N * N];
    for c in curves {
        for p in &c.dense {
            let r = radius.ceil() as isize;
            for a in -r..=r {
                for b in -r..=r {
                    let (i, j) = (p[0].round() as isize + a, p[1].round() as isize + b);
                    if i < 0 || j < 0 || i >= N as isize || j >= N as isize {
                        continue;
                    }
                    if dist([i as f64, j as f64], *p) <= radius {
                        w[i as usize * N + j as usize] = low;
                    }
                }
            }
        }
    }
    w
}

/// Clutter points at least `away` from every curve and from each other.
fn clutter(rng: &mut Rng, curves: &[Curve], count: usize, away: f64) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = Vec::new();
    let mut tries = 0;
    while out.len() < count && tries < 100_000 {
        tries += 1;
        let p = [
            rng.uniform(2.0, N as f64 - 3.0),
            rng.uniform(2.0, N as f64 - 3.0),
        ];
        let near_curve = curves
            .iter()
            .any(|c| c.dense.iter().step_by(4).any(|q| dist(*q, p) < away));
        if !near_curve && out.iter().all(|q| dist(*q, p) >= away) {
            out.push(p);
        }
    }
    assert_eq!(out.len(), count, "could not place the clutter");
    out
}

/// The scene: key points with their curve (`None` for clutter) and angles.
struct Scene {
    points: Vec<[f64; 2]>,
    angles: Vec<f64>,
    owner: Vec<Option<usize>>,
    closed: Vec<bool>,
}

fn scene(
    rng: &mut Rng,
    curves: &[Curve],
    spacing: f64,
    jitter: f64,
    clutter_pts: Vec<[f64; 2]>,
) -> Scene {
    let mut s = Scene {
        points: Vec::new(),
        angles: Vec::new(),
        owner: Vec::new(),
        closed: curves.iter().map(|c| c.closed).collect(),
    };
    for (k, c) in curves.iter().enumerate() {
        for (p, a) in sample(rng, c, spacing, jitter) {
            s.points.push(p);
            s.angles.push(a);
            s.owner.push(Some(k));
        }
    }
    for p in clutter_pts {
        s.points.push(p);
        s.angles.push(rng.uniform(0.0, TAU));
        s.owner.push(None);
    }
    s
}

/// Asserts the grouping of the scene: every contour holds the points of one
/// curve only (clutter aside), every curve's points are in one contour,
/// closed curves are closed contours and open ones open, and at least 90 %
/// of the clutter is left out. Returns the fraction of clutter left out.
fn check_grouping(s: &Scene, out: &GroupingOutput, what: &str) -> f64 {
    let curves = s.closed.len();
    let mut contour_of = vec![None; s.points.len()];
    for (c, contour) in out.contours.iter().enumerate() {
        let owners: std::collections::BTreeSet<usize> = contour
            .key_points
            .iter()
            .filter_map(|&p| s.owner[p])
            .collect();
        assert!(
            owners.len() <= 1,
            "{what}: contour {c} mixes curves {owners:?}: {:?}",
            contour.key_points
        );
        for &p in &contour.key_points {
            contour_of[p] = Some(c);
        }
    }
    for k in 0..curves {
        let members: Vec<usize> = (0..s.points.len())
            .filter(|&p| s.owner[p] == Some(k))
            .collect();
        let contour = contour_of[members[0]];
        assert!(
            contour.is_some() && members.iter().all(|&p| contour_of[p] == contour),
            "{what}: curve {k} ({} points) is split or left out: {:?}",
            members.len(),
            members.iter().map(|&p| contour_of[p]).collect::<Vec<_>>()
        );
        let contour = &out.contours[contour.unwrap_or(0)];
        assert_eq!(
            contour.closed, s.closed[k],
            "{what}: curve {k} closed = {} but its contour closed = {}",
            s.closed[k], contour.closed
        );
        let poly = contour.polyline.as_ref().expect("a chain has a polyline");
        assert!(poly.len() > members.len());
        if contour.closed {
            assert_eq!(poly.first(), poly.last());
        }
    }
    let clutter: Vec<usize> = (0..s.points.len())
        .filter(|&p| s.owner[p].is_none())
        .collect();
    let left_out = clutter.iter().filter(|&&p| contour_of[p].is_none()).count();
    let fraction = if clutter.is_empty() {
        1.0
    } else {
        left_out as f64 / clutter.len() as f64
    };
    assert!(
        fraction >= 0.9,
        "{what}: only {left_out} of {} clutter points left out",
        clutter.len()
    );
    fraction
}

fn solve(grid: &Grid, cost: IsotropicCost<'_>, s: &Scene, oriented: bool) -> GroupingOutput {
    let problem = GroupingProblem {
        grid: grid.clone(),
        cost,
        key_points: s.points.clone(),
        orientations: oriented.then(|| s.angles.clone()),
    };
    group(&problem, &GroupingOptions::default(), &Control::new()).expect("grouping")
}

/// Curves drawn as a cheap tube (W = 0.05 within 1.5 cells, 1 elsewhere),
/// key points every ~9 cells jittered by up to 0.7 cells, 25 clutter
/// points at least 6 cells from the curves.
#[test]
fn circles_and_spiral_through_a_drawn_cost() {
    let mut rng = Rng(0x5EED_0001);
    let cs = curves(&mut rng, 13.0);
    let clutter_pts = clutter(&mut rng, &cs, 25, 6.0);
    let s = scene(&mut rng, &cs, 9.0, 0.7, clutter_pts);
    let grid = Grid::unit(&[N, N]).unwrap();
    let w = drawn_cost(&cs, 0.05, 1.5);
    let cost = IsotropicCost::new(
        &grid,
        CostValues::F64(Cow::Borrowed(&w)),
        Interpretation::Cost,
        None,
    )
    .unwrap();
    let out = solve(&grid, cost, &s, false);
    let left = check_grouping(&s, &out, "drawn cost");
    assert_eq!(out.path_failures, 0);
    println!(
        "drawn cost: {} key points, {} links ({} kept), {} contours, clutter left out {:.0} %, typical {:.3}",
        s.points.len(),
        out.links.len(),
        out.links.iter().filter(|l| l.kept).count(),
        out.contours.len(),
        100.0 * left,
        out.typical_cost
    );
    // Every kept link's cost is the geodesic distance: the integrated path
    // length agrees with U_i + U_j at the saddle.
    for l in out.links.iter().filter(|l| l.kept) {
        let len = l.path_length.unwrap();
        assert!(
            (len - l.cost).abs() <= 0.25 * l.cost + 0.3,
            "link {:?}: path length {len} vs saddle cost {}",
            l.pair,
            l.cost
        );
    }
}

/// A constant cost: grouping by proximity alone, which works when the
/// points along a curve are closer to each other than to anything else:
/// spacing ~6, spiral gap 16, clutter at least 20 cells from curves and
/// from each other.
#[test]
fn circles_and_spiral_through_a_constant_cost() {
    let mut rng = Rng(0x5EED_0002);
    let cs = curves(&mut rng, 16.0);
    let clutter_pts = clutter(&mut rng, &cs, 12, 20.0);
    let s = scene(&mut rng, &cs, 6.0, 0.5, clutter_pts);
    let grid = Grid::unit(&[N, N]).unwrap();
    let out = solve(&grid, IsotropicCost::constant(1.0).unwrap(), &s, false);
    let left = check_grouping(&s, &out, "constant cost");
    println!(
        "constant cost: {} key points, {} contours, clutter left out {:.0} %",
        s.points.len(),
        out.contours.len(),
        100.0 * left
    );
}

/// Two nearby parallel sinusoids, points every 10 cells along each, the
/// second curve 7 cells away and staggered by 5: in a constant cost a
/// point's nearest neighbours are across (8.6) rather than along (10), so
/// the isotropic grouping mixes the curves; with the tangents as
/// orientations the metric is 4 times cheaper along them and each curve is
/// one open contour.
#[test]
fn orientations_separate_nearby_parallel_curves() {
    let (n0, n1) = (60, 160);
    let grid = Grid::unit(&[n0, n1]).unwrap();
    let y = |x: f64, off: f64| 26.0 + off + 4.0 * (x / 18.0).sin();
    let dy = |x: f64| 4.0 / 18.0 * (x / 18.0).cos();
    let mut s = Scene {
        points: Vec::new(),
        angles: Vec::new(),
        owner: Vec::new(),
        closed: vec![false, false],
    };
    for (k, (off, shift)) in [(0.0, 0.0), (7.0, 5.0)].into_iter().enumerate() {
        for m in 0..14 {
            let x = 10.0 + shift + 10.0 * m as f64;
            s.points.push([y(x, off), x]);
            // Tangent (d row, d col) = (y'(x), 1): angle from axis 0 towards axis 1.
            s.angles.push(1f64.atan2(dy(x)));
            s.owner.push(Some(k));
        }
    }
    let iso = solve(&grid, IsotropicCost::constant(1.0).unwrap(), &s, false);
    let mixed = iso.contours.iter().any(|c| {
        let owners: std::collections::BTreeSet<usize> =
            c.key_points.iter().filter_map(|&p| s.owner[p]).collect();
        owners.len() > 1
    });
    assert!(
        mixed,
        "the isotropic grouping was expected to mix the two curves: {:?}",
        iso.contours
    );
    let aniso = solve(&grid, IsotropicCost::constant(1.0).unwrap(), &s, true);
    check_grouping(&s, &aniso, "anisotropic");
    // The Riemannian descent may stall on a link against the boundary of
    // its cell (then that half is a straight segment): at most one here.
    assert!(
        aniso.path_failures <= 1,
        "{} straight halves",
        aniso.path_failures
    );
    assert_eq!(aniso.contours.len(), 2);
    // Chains in order along each curve.
    for c in &aniso.contours {
        let mut k = c.key_points.clone();
        if k[0] > k[k.len() - 1] {
            k.reverse();
        }
        assert!(k.windows(2).all(|w| w[1] == w[0] + 1), "{:?}", c.key_points);
    }
    println!(
        "parallel curves: isotropic {} contours (mixed), anisotropic {} contours, spread {:?}, {} straight halves",
        iso.contours.len(),
        aniso.contours.len(),
        aniso.spread,
        aniso.path_failures
    );
}
