//! Accuracy and behaviour of the isotropic eikonal solvers (fast marching and
//! fast sweeping) against closed-form solutions from
//! `geodex::numerics::exact`. Every accuracy test names its exact solution
//! and asserts max and mean error bounds over the cells the solver reached.
//! Coordinates: index units, axis 0 first; physical = index × spacing.
//!
//! Print the measured figures with
//! `cargo test --release --test eikonal_accuracy -- --nocapture`.

use std::sync::atomic::AtomicBool;
use std::sync::Mutex;

use geodex::numerics::eikonal::{EikonalOutput, InitialFront};
use geodex::numerics::exact;
use geodex::numerics::metric::{CostValues, Interpretation};
use geodex::numerics::{
    solve, Control, EikonalError, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Method,
    Order, Source, StopReason, StopRules,
};
use proptest::prelude::*;

/// A problem on `shape` / `spacing` with cost `w(physical position)` (`+inf` = wall).
fn problem(
    shape: &[usize],
    spacing: &[f64],
    w: impl Fn(&[f64]) -> f64,
    sources: Vec<Source>,
) -> EikonalProblem<'static> {
    let grid = Grid::new(shape, spacing).unwrap();
    let values: Vec<f64> = (0..grid.len()).map(|i| w(&position(&grid, i))).collect();
    let cost = IsotropicCost::new(
        &grid,
        CostValues::F64(values.into()),
        Interpretation::Cost,
        None,
    )
    .unwrap();
    EikonalProblem {
        grid,
        cost,
        sources,
    }
}

/// Physical position of linear index `i` (caller's axes).
fn position(grid: &Grid, i: usize) -> Vec<f64> {
    let idx = grid.unravel(i);
    idx[3 - grid.ndim()..]
        .iter()
        .zip(grid.spacing())
        .map(|(&c, &h)| c as f64 * h)
        .collect()
}

fn run(p: &EikonalProblem<'_>, o: &EikonalOptions) -> EikonalOutput {
    solve(p, o, &Control::new()).unwrap()
}

/// (max, mean) of |U − exact(x)| over the cells with a finite U.
fn errors(
    p: &EikonalProblem<'_>,
    out: &EikonalOutput,
    exact: impl Fn(&[f64]) -> f64,
) -> (f64, f64) {
    let (mut max, mut sum, mut count) = (0.0f64, 0.0, 0usize);
    for (i, &u) in out.distance.iter().enumerate() {
        assert!(!u.is_nan());
        if u.is_finite() {
            let e = (u - exact(&position(&p.grid, i))).abs();
            max = max.max(e);
            sum += e;
            count += 1;
        }
    }
    assert!(count > 0);
    (max, sum / count as f64)
}

fn opts(order: Order, factoring: bool) -> EikonalOptions {
    EikonalOptions::DEFAULT
        .with_order(order)
        .with_factoring(factoring)
}

fn sci(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.3e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Observed orders `log2(e_k / e_{k+1})` for resolutions that double.
fn orders(e: &[f64]) -> Vec<f64> {
    e.windows(2).map(|w| (w[0] / w[1]).log2()).collect()
}

fn dist(x: &[f64], c: &[f64]) -> f64 {
    x.iter()
        .zip(c)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt()
}

/// The source of the convergence studies: the middle of `[0, 1]^d` moved
/// off-grid by a fixed fraction of a cell, so that every resolution sees the
/// same sub-cell geometry (otherwise the error constant changes with the
/// offset and the observed orders are noise). Index coordinates for `n` points.
fn centre(d: usize, n: usize) -> Vec<f64> {
    let off = [0.3, -0.2, 0.15];
    (0..d).map(|k| (n - 1) as f64 / 2.0 + off[k]).collect()
}

/// A radial cost `W(r)` around [`centre`] on `[0, 1]^d` with `n` points per
/// axis; returns (max, mean) errors against `exact_r(r)`. `radius_phys`,
/// when given, initialises the cells within that physical radius exactly.
fn radial_errors(
    d: usize,
    n: usize,
    w: &dyn Fn(f64) -> f64,
    exact_r: &dyn Fn(f64) -> f64,
    o: &EikonalOptions,
    radius_phys: Option<f64>,
) -> (f64, f64) {
    let h = 1.0 / (n - 1) as f64;
    let src = centre(d, n);
    let c: &[f64] = &src.iter().map(|x| x * h).collect::<Vec<_>>();
    let p = problem(
        &vec![n; d],
        &vec![h; d],
        |x| w(dist(x, c)),
        vec![Source::Point(src)],
    );
    let mut o = o.clone();
    if let Some(r) = radius_phys {
        o.source_radius = r / h;
    }
    let out = run(&p, &o);
    errors(&p, &out, |x| exact_r(dist(x, c)))
}

fn study(
    name: &str,
    d: usize,
    sizes: &[usize],
    w: &dyn Fn(f64) -> f64,
    exact_r: &dyn Fn(f64) -> f64,
    o: &EikonalOptions,
    radius_phys: Option<f64>,
) -> (Vec<f64>, Vec<f64>) {
    let e: Vec<(f64, f64)> = sizes
        .iter()
        .map(|&n| radial_errors(d, n, w, exact_r, o, radius_phys))
        .collect();
    let max: Vec<f64> = e.iter().map(|e| e.0).collect();
    let mean: Vec<f64> = e.iter().map(|e| e.1).collect();
    println!(
        "{name} {d}D N={sizes:?}: max {} mean {}; orders max {:.2?} mean {:.2?}",
        sci(&max),
        sci(&mean),
        orders(&max),
        orders(&mean)
    );
    (orders(&max), orders(&mean))
}

const SIZES_2D: [usize; 3] = [33, 65, 129];
const SIZES_3D: [usize; 3] = [17, 33, 65];

/// Radial test cost `W = 1 + ε sin(ω r)`, exact `U = r + (ε/ω)(1 − cos ω r)`
/// (radial, increasing, so the rays from the source are the geodesics).
const EPS: f64 = 0.3;
const OMEGA: f64 = 8.0;
fn radial_w(r: f64) -> f64 {
    1.0 + EPS * (OMEGA * r).sin()
}
fn radial_u(r: f64) -> f64 {
    r + EPS / OMEGA * (1.0 - (OMEGA * r).cos())
}

#[test]
fn first_order_converges_at_order_one() {
    // Exact: U = |x − p| (exact::point_source, W = 1), unfactored, with the
    // cells within a fixed physical radius 0.1 of p initialised exactly (the
    // classical way to remove the source singularity from a first-order
    // scheme); and the radial cost above with factoring.
    for (d, sizes) in [(2, SIZES_2D), (3, SIZES_3D)] {
        let unit = |x: f64| exact::point_source(&[x], &[0.0], 1.0);
        let (om, oa) = study(
            "order 1, unit cost, unfactored, ball r=0.1",
            d,
            &sizes,
            &|_| 1.0,
            &unit,
            &opts(Order::First, false),
            Some(0.1),
        );
        assert!(om.iter().chain(&oa).all(|&o| o >= 0.9), "{om:?} {oa:?}");
        // Factored first order (not the default pairing): O(h) in theory but
        // erratic at these sizes (observed orders 0.44 to 1.9, 3D worst), so
        // this only bounds the error; the convergence claim is the one above.
        let (_, _) = study(
            "order 1, radial cost, factored",
            d,
            &sizes,
            &radial_w,
            &radial_u,
            &opts(Order::First, true),
            None,
        );
        let finest = radial_errors(
            d,
            sizes[2],
            &radial_w,
            &radial_u,
            &opts(Order::First, true),
            None,
        );
        assert!(finest.0 < 5e-3 && finest.1 < 2e-3, "{finest:?}");
    }
}

#[test]
fn first_order_without_factoring_near_a_point_source_is_h_log_h() {
    // Exact: U = |x − p|. With only the 1.5-cell ball initialised, the
    // source singularity limits the first-order scheme to O(h log 1/h):
    // observed orders about 0.7 at these sizes (h log h predicts 0.74 for
    // 33 → 65). This documents the behaviour rather than a target.
    for (d, sizes) in [(2, SIZES_2D), (3, SIZES_3D)] {
        let (om, oa) = study(
            "order 1, unit cost, unfactored, 1.5-cell ball",
            d,
            &sizes,
            &|_| 1.0,
            &|r| r,
            &opts(Order::First, false),
            None,
        );
        assert!(om.iter().chain(&oa).all(|&o| o >= 0.5), "{om:?} {oa:?}");
    }
}

#[test]
fn second_order_with_factoring_converges_at_order_two() {
    // Exact: U = r + (ε/ω)(1 − cos ω r) for W = 1 + ε sin(ω r) (radial).
    for (d, sizes) in [(2, SIZES_2D), (3, SIZES_3D)] {
        let (om, oa) = study(
            "order 2, radial cost, factored",
            d,
            &sizes,
            &radial_w,
            &radial_u,
            &opts(Order::Second, true),
            None,
        );
        assert!(om.iter().chain(&oa).all(|&o| o >= 1.8), "{om:?} {oa:?}");
    }
}

#[test]
fn factored_scheme_is_exact_for_a_constant_cost() {
    // Exact: U = W |x − p| (exact::point_source), W = 2, off-grid and
    // on-grid sources, anisotropic spacing; both orders, both methods.
    for (d, n) in [(2, 65), (3, 35)] {
        let h = [0.7, 1.3, 1.0];
        for src in [[30.3, 17.8, 9.6], [20.0, 7.0, 11.0]] {
            let s = &src[3 - d..];
            let hh = &h[..d];
            let ps: Vec<f64> = s.iter().zip(hh).map(|(a, b)| a * b).collect();
            let p = problem(&vec![n; d], hh, |_| 2.0, vec![Source::Point(s.to_vec())]);
            for order in [Order::First, Order::Second] {
                for method in [Method::FastMarching, Method::FastSweeping] {
                    let out = run(&p, &opts(order, true).with_method(method));
                    let (max, mean) = errors(&p, &out, |x| exact::point_source(x, &ps, 2.0));
                    println!("factored constant cost {d}D {order:?} {method:?} source {s:?}: max {max:.2e} mean {mean:.2e}");
                    assert!(max <= 1e-12 && mean <= 1e-13, "{max} {mean}");
                }
            }
        }
    }
}

#[test]
fn diagonal_bias_on_a_small_grid() {
    // Exact: U[k, k] = √2 k for a unit-cost point source at [0, 0] (default options).
    let p = problem(
        &[5, 5],
        &[1.0, 1.0],
        |_| 1.0,
        vec![Source::Point(vec![0.0, 0.0])],
    );
    let out = run(&p, &EikonalOptions::DEFAULT);
    let (mut max, mut sum) = (0.0f64, 0.0);
    for k in 0..5 {
        let e = (out.distance[[k, k]] - 2f64.sqrt() * k as f64).abs();
        max = max.max(e);
        sum += e;
    }
    println!("diagonal bias 5x5: max {max:.2e} mean {:.2e}", sum / 5.0);
    assert!(max < 0.05 && sum / 5.0 < 0.05);
    // Without factoring, first order: the classical bias is visible but bounded.
    let out = run(&p, &opts(Order::First, false));
    let e = (out.distance[[4, 4]] - 4.0 * 2f64.sqrt()).abs();
    println!("diagonal bias 5x5, order 1 unfactored, at [4,4]: {e:.3e}");
    assert!(e < 0.5);
}

/// The Poincaré half-plane on a 100 × 100 grid of [−0.5, 0.5] × [1, 2]
/// (axis 0 = x, axis 1 = y), source (0, 1.5) = index (49.5, 49.5), off-grid.
fn poincare_errors(n: usize, o: &EikonalOptions) -> (f64, f64) {
    let h = 1.0 / (n - 1) as f64;
    let p = problem(
        &[n, n],
        &[h, h],
        |x| 1.0 / (1.0 + x[1]),
        vec![Source::Point(vec![0.5 / h, 0.5 / h])],
    );
    let out = run(&p, o);
    // Exact: exact::poincare, U = arcosh(1 + ((x−x0)² + (y−y0)²) / (2 y y0)).
    errors(&p, &out, |x| {
        exact::poincare(x[0] - 0.5, x[1] + 1.0, 0.0, 1.5)
    })
}

#[test]
fn poincare_half_plane() {
    // Reference figures (HFM, second order): L∞ 3.12e-4, mean 7.42e-5.
    let (max, mean) = poincare_errors(100, &opts(Order::Second, true));
    println!("Poincaré 100², order 2 factored: max {max:.3e} mean {mean:.3e}");
    assert!(max <= 3e-4 && mean <= 7e-5);
    let (max, mean) = poincare_errors(100, &opts(Order::First, false));
    println!("Poincaré 100², order 1 unfactored: max {max:.3e} mean {mean:.3e}");
    assert!(max <= 3e-2 && mean <= 1e-2);
    let (max, mean) = poincare_errors(100, &opts(Order::Second, false));
    println!("Poincaré 100², order 2 unfactored: max {max:.3e} mean {mean:.3e}");
    assert!(max <= 1e-2 && mean <= 5e-3);
}

#[test]
fn two_sources_split_along_the_bisector() {
    // Exact: under a unit cost the Voronoi boundary of p and q is the
    // perpendicular bisector; U = min(|x − p|, |x − q|).
    let n = 81;
    let (p, q) = ([20.3, 30.7], [55.6, 48.2]);
    let pr = problem(
        &[n, n],
        &[1.0, 1.0],
        |_| 1.0,
        vec![Source::Point(p.to_vec()), Source::Point(q.to_vec())],
    );
    for order in [Order::First, Order::Second] {
        let out = run(&pr, &opts(order, true));
        let (mut worst, mut wrong) = (0.0f64, 0usize);
        for (i, &l) in out.labels.iter().enumerate() {
            let x = position(&pr.grid, i);
            let (dp, dq) = (dist(&x, &p), dist(&x, &q));
            let expected = if dp < dq { 0 } else { 1 };
            if l != expected {
                wrong += 1;
                // Distance to the bisector: |dp² − dq²| / (2 |p − q|).
                worst = worst.max((dp * dp - dq * dq).abs() / (2.0 * dist(&p, &q)));
            }
        }
        let (max, mean) = errors(&pr, &out, |x| dist(x, &p).min(dist(x, &q)));
        println!("two sources {order:?}: {wrong} cells on the wrong side, farthest {worst:.2} cells from the bisector; U max {max:.2e} mean {mean:.2e}");
        assert!(worst < 1.0);
        // The fronts meet along the bisector where U has a kink: the local
        // error there is O(h) (about 0.3 cell); elsewhere factoring is exact.
        assert!(max < 0.4 && mean < 0.01);
    }
}

#[test]
fn disk_obstacle_at_512() {
    // Exact: exact::disk_obstacle (tangent + arc + tangent in the shadow).
    let n = 512;
    let h = 1.0 / (n - 1) as f64;
    let (c, r, s) = ([0.5, 0.5], 0.2, [0.5, 0.15]);
    let p = problem(
        &[n, n],
        &[h, h],
        |x| {
            if dist(x, &c) < r {
                f64::INFINITY
            } else {
                1.0
            }
        },
        vec![Source::Point(vec![s[0] / h, s[1] / h])],
    );
    for (order, method) in [
        (Order::Second, Method::FastMarching),
        (Order::First, Method::FastMarching),
    ] {
        let out = run(&p, &opts(order, true).with_method(method));
        let (max, mean) = errors(&p, &out, |x| exact::disk_obstacle([x[0], x[1]], s, c, r));
        println!("disk obstacle 512² {order:?}: max {max:.3e} mean {mean:.3e} (domain size 1)");
        // Below 1 % of the domain at order 2 (2 % at order 1): the staircase
        // boundary of the disk costs O(h) near the obstacle at either order.
        let bound = if order == Order::Second { 0.01 } else { 0.02 };
        assert!(max < bound && mean < 2e-3);
        // Walls keep +inf and −1.
        for (i, &u) in out.distance.iter().enumerate() {
            if p.cost.is_wall(i) {
                assert_eq!(u, f64::INFINITY);
                assert_eq!(out.labels.as_slice().unwrap()[i], -1);
            }
        }
    }
}

#[test]
fn sweeping_agrees_with_marching() {
    // Same discrete scheme: at order 1 (unfactored) both converge to the
    // unique solution of the upwind equations; at order 2 + factoring the
    // two iterations use different neighbour sets, so they agree to the
    // discretisation error. Cost: the radial cost plus a wall with a gap,
    // so that sweeping needs several rounds.
    let n = 65;
    let h = 1.0 / (n - 1) as f64;
    let p = problem(
        &[n, n],
        &[h, h],
        |x| {
            if (x[0] - 0.7).abs() < 0.02 && x[1] > 0.3 {
                f64::INFINITY
            } else {
                radial_w(dist(x, &[0.51, 0.493]))
            }
        },
        vec![Source::Point(vec![0.51 / h, 0.493 / h])],
    );
    for (order, fact, bound) in [(Order::First, false, 1e-9), (Order::Second, true, 2e-3)] {
        let fm = run(&p, &opts(order, fact));
        let fs = run(&p, &opts(order, fact).with_method(Method::FastSweeping));
        assert_eq!(fs.stop, StopReason::Completed);
        let sweeps = fs.sweeps.unwrap();
        let mut max = 0.0f64;
        let mut sum = 0.0;
        for (a, b) in fm.distance.iter().zip(fs.distance.iter()) {
            assert_eq!(a.is_finite(), b.is_finite());
            if a.is_finite() {
                max = max.max((a - b).abs());
                sum += (a - b).abs();
            }
        }
        let mean = sum / fm.distance.len() as f64;
        let same_label = fm.labels.iter().zip(fs.labels.iter()).all(|(a, b)| a == b);
        println!("sweeping vs marching {order:?} factoring {fact}: max {max:.2e} mean {mean:.2e}, {sweeps} sweeps");
        assert!(max <= bound && mean <= bound / 4.0, "{max} {mean}");
        assert!(same_label);
        assert!(sweeps >= 8 && sweeps.is_multiple_of(4));
    }
}

#[test]
fn sweeping_reports_its_sweep_limit() {
    // A wall with a gap makes the characteristics turn, so one round is not enough.
    let p = problem(
        &[40, 40],
        &[1.0, 1.0],
        |x| {
            if x[0] == 20.0 && x[1] < 35.0 {
                f64::INFINITY
            } else {
                1.0
            }
        },
        vec![Source::Point(vec![5.0, 5.0])],
    );
    let mut o = opts(Order::First, false).with_method(Method::FastSweeping);
    o.max_sweeps = 1;
    let out = run(&p, &o);
    assert_eq!(out.stop, StopReason::SweepLimit);
    assert_eq!(out.sweeps, Some(4));
    o.max_sweeps = 100;
    let out = run(&p, &o);
    assert_eq!(out.stop, StopReason::Completed);
    // Exact behind the wall's end (grid path around (20, 35)): finite and
    // at least the straight-line distance.
    let u = out.distance[[30, 5]];
    assert!(u.is_finite() && u >= dist(&[30.0, 5.0], &[5.0, 5.0]) + 10.0);
}

#[test]
fn stop_rules_and_order_record() {
    let n = 60;
    let p = problem(
        &[n, n],
        &[1.0, 1.0],
        |_| 1.0,
        vec![Source::Point(vec![10.0, 10.0])],
    );
    let full = run(&p, &EikonalOptions::DEFAULT);
    let check_ball = |out: &EikonalOutput, bound: f64| {
        for (i, (&u, &f)) in out.distance.iter().zip(full.distance.iter()).enumerate() {
            if u.is_finite() {
                assert_eq!(u, f);
                assert!(u <= bound);
                assert!(out.labels.as_slice().unwrap()[i] == 0);
            } else {
                assert_eq!(out.labels.as_slice().unwrap()[i], -1);
            }
        }
    };

    // max_distance: a geodesic ball.
    let o = EikonalOptions::DEFAULT.with_stop(StopRules {
        max_distance: Some(20.0),
        ..Default::default()
    });
    let out = run(&p, &o);
    assert_eq!(out.stop, StopReason::MaxDistance);
    check_ball(&out, 20.0);
    let inside = full.distance.iter().filter(|&&u| u <= 20.0).count();
    assert_eq!(out.frozen, inside);
    let fs = run(&p, &o.clone().with_method(Method::FastSweeping));
    assert_eq!(fs.stop, StopReason::MaxDistance);
    assert!(fs.distance.iter().all(|&u| u <= 20.0 || u == f64::INFINITY));

    // targets: stops once the target's nearest cell is frozen.
    let o = EikonalOptions::DEFAULT.with_stop(StopRules {
        targets: vec![vec![40.2, 39.9]],
        ..Default::default()
    });
    let out = run(&p, &o);
    assert_eq!(out.stop, StopReason::TargetsReached);
    let ut = out.distance[[40, 40]];
    assert_eq!(ut, full.distance[[40, 40]]);
    check_ball(&out, ut);
    assert!(out.frozen < n * n);
    let bad = EikonalOptions::DEFAULT.with_stop(StopRules {
        targets: vec![vec![0.0, 70.0]],
        ..Default::default()
    });
    assert!(matches!(
        solve(&p, &bad, &Control::new()),
        Err(EikonalError::Target { index: 0, .. })
    ));

    // max_frozen and the freezing order.
    let mut o = EikonalOptions::DEFAULT
        .with_order(Order::First)
        .with_factoring(false)
        .with_stop(StopRules {
            max_frozen: Some(500),
            ..Default::default()
        });
    o.record_order = true;
    let out = run(&p, &o);
    assert_eq!(out.stop, StopReason::MaxFrozen);
    assert_eq!(out.frozen, 500);
    assert_eq!(out.distance.iter().filter(|u| u.is_finite()).count(), 500);
    let ranks = out.frozen_order.as_ref().unwrap();
    let mut by_rank = vec![f64::NAN; 500];
    for (&r, &u) in ranks.iter().zip(out.distance.iter()) {
        if r >= 0 {
            assert!(by_rank[r as usize].is_nan(), "rank {r} used twice");
            by_rank[r as usize] = u;
        } else {
            assert_eq!(u, f64::INFINITY);
        }
    }
    // First-order unfactored fast marching freezes in increasing U.
    assert!(by_rank.windows(2).all(|w| w[0] <= w[1]));
}

#[test]
fn cancel_and_progress() {
    let p = problem(
        &[50, 50],
        &[1.0, 1.0],
        |_| 1.0,
        vec![Source::Point(vec![1.0, 1.0])],
    );
    let flag = AtomicBool::new(true);
    for method in [Method::FastMarching, Method::FastSweeping] {
        let control = Control::new().with_cancel(&flag);
        let r = solve(&p, &EikonalOptions::DEFAULT.with_method(method), &control);
        assert!(matches!(r, Err(EikonalError::Cancelled)));
    }
    let seen = Mutex::new(Vec::new());
    let sink = |f: f64| seen.lock().unwrap().push(f);
    let control = Control::new().with_progress(&sink);
    solve(&p, &EikonalOptions::DEFAULT, &control).unwrap();
    let seen = seen.into_inner().unwrap();
    assert_eq!(seen.last(), Some(&1.0));
    assert!(seen.windows(2).all(|w| w[0] <= w[1]));
}

#[test]
fn a_closed_wall_leaves_the_other_side_unreachable() {
    // Exact: +inf beyond the wall, the free-space distance before it.
    for method in [Method::FastMarching, Method::FastSweeping] {
        let p = problem(
            &[12, 30, 30],
            &[1.0, 1.0, 1.0],
            |x| if x[2] == 15.0 { f64::INFINITY } else { 1.0 },
            vec![Source::Point(vec![6.0, 10.0, 5.0])],
        );
        let out = run(&p, &EikonalOptions::DEFAULT.with_method(method));
        for (i, (&u, &l)) in out.distance.iter().zip(out.labels.iter()).enumerate() {
            let x = position(&p.grid, i);
            if x[2] >= 15.0 {
                assert_eq!((u, l), (f64::INFINITY, -1));
            } else {
                assert_eq!(l, 0);
                assert!((u - dist(&x, &[6.0, 10.0, 5.0])).abs() < 1e-12);
            }
        }
    }
}

/// Cells reachable from the seeds through axis neighbours that are not walls.
fn reachable(p: &EikonalProblem<'_>, seeds: &[usize]) -> Vec<bool> {
    let grid = &p.grid;
    let s = grid.shape3();
    let st = grid.strides3();
    let mut seen = vec![false; grid.len()];
    let mut stack: Vec<usize> = seeds.to_vec();
    for &i in seeds {
        seen[i] = true;
    }
    while let Some(i) = stack.pop() {
        let idx = grid.unravel(i);
        for k in 0..3 {
            for up in [false, true] {
                let j = if up && idx[k] + 1 < s[k] {
                    i + st[k]
                } else if !up && idx[k] > 0 {
                    i - st[k]
                } else {
                    continue;
                };
                if !seen[j] && !p.cost.is_wall(j) {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
    }
    seen
}

/// True if the cells with label `l` form one connected set (axis neighbours,
/// or the full 3 × 3 × 3 neighbourhood when `cube`).
fn connected(grid: &Grid, labels: &[i32], l: i32, cube: bool) -> bool {
    let cells: Vec<usize> = (0..labels.len()).filter(|&i| labels[i] == l).collect();
    let Some(&start) = cells.first() else {
        return true;
    };
    let s = grid.shape3();
    let mut seen = vec![false; labels.len()];
    seen[start] = true;
    let mut stack = vec![start];
    let mut count = 1;
    while let Some(i) = stack.pop() {
        let idx = grid.unravel(i);
        for d0 in -1i64..=1 {
            for d1 in -1i64..=1 {
                for d2 in -1i64..=1 {
                    let nz = [d0, d1, d2].iter().filter(|&&d| d != 0).count();
                    if nz == 0 || (!cube && nz > 1) {
                        continue;
                    }
                    let q = [idx[0] as i64 + d0, idx[1] as i64 + d1, idx[2] as i64 + d2];
                    if (0..3).any(|k| q[k] < 0 || q[k] >= s[k] as i64) {
                        continue;
                    }
                    let j = grid.linear(q.map(|v| v as usize));
                    if !seen[j] && labels[j] == l {
                        seen[j] = true;
                        count += 1;
                        stack.push(j);
                    }
                }
            }
        }
    }
    count == cells.len()
}

fn random_case() -> impl Strategy<Value = (Vec<usize>, Vec<f64>, Vec<bool>, Vec<Vec<usize>>)> {
    prop_oneof![
        (3usize..14, 3usize..14).prop_map(|(a, b)| vec![a, b]),
        (2usize..7, 2usize..7, 2usize..7).prop_map(|(a, b, c)| vec![a, b, c]),
    ]
    .prop_flat_map(|shape| {
        let n: usize = shape.iter().product();
        let d = shape.len();
        let cell = shape.iter().map(|&s| 0..s).collect::<Vec<_>>();
        (
            Just(shape),
            proptest::collection::vec(0.2f64..5.0, n),
            proptest::collection::vec(proptest::bool::weighted(0.15), n),
            proptest::collection::vec(cell, 1..4),
        )
            .prop_map(move |(s, w, walls, src)| {
                let _ = d;
                (s, w, walls, src)
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Invariants on random costs with random walls, for both orders, with and
    /// without factoring, both methods.
    #[test]
    fn invariants_on_random_costs(case in random_case(), radius in prop_oneof![Just(0.0), Just(1.5)]) {
        let (shape, w, walls, srcs) = case;
        let grid = Grid::unit(&shape).unwrap();
        let mut srcs = srcs;
        srcs.sort();
        srcs.dedup();
        let mut values: Vec<f64> = w.clone();
        for (i, v) in values.iter_mut().enumerate() {
            if walls[i] { *v = f64::INFINITY; }
        }
        for s in &srcs {
            let i = grid.linear(grid.index3(s).unwrap());
            values[i] = w[i];
        }
        let wmax = w.iter().cloned().fold(0.0, f64::max);
        let p = EikonalProblem {
            cost: IsotropicCost::new(&grid, CostValues::F64(values.into()), Interpretation::Cost, None).unwrap(),
            grid,
            sources: srcs.iter().map(|s| Source::Point(s.iter().map(|&c| c as f64).collect())).collect(),
        };
        let grid = &p.grid;
        for (order, fact, method) in [
            (Order::First, false, Method::FastMarching),
            (Order::First, true, Method::FastMarching),
            (Order::Second, false, Method::FastMarching),
            (Order::Second, true, Method::FastMarching),
            (Order::First, false, Method::FastSweeping),
            (Order::Second, true, Method::FastSweeping),
        ] {
            let mut o = opts(order, fact).with_method(method);
            o.source_radius = radius;
            let out = run(&p, &o);
            let front = InitialFront::build(&p, radius, &Control::new()).unwrap();
            let seeds: Vec<usize> = front.cells.iter().map(|c| c.index).collect();
            let reach = reachable(&p, &seeds);
            let u = out.distance.as_slice().unwrap();
            let l = out.labels.as_slice().unwrap();
            for s in &srcs {
                prop_assert_eq!(u[grid.linear(grid.index3(s).unwrap())], 0.0);
            }
            for i in 0..u.len() {
                prop_assert!(!u[i].is_nan());
                prop_assert!(u[i] >= 0.0);
                prop_assert_eq!(u[i].is_finite(), reach[i], "cell {} reach", i);
                prop_assert_eq!(l[i] >= 0, reach[i]);
            }
            // Lipschitz: U(x) ≤ U(y) + max W · h for axis neighbours, x not a
            // seed (seeds hold the source's local cone W(p)|x − p|).
            let tol = if order == Order::First && !fact { 1e-12 } else { 0.1 * wmax };
            let st = grid.strides3();
            let sh = grid.shape3();
            for i in 0..u.len() {
                let idx = grid.unravel(i);
                for k in 0..3 {
                    if idx[k] + 1 < sh[k] {
                        let j = i + st[k];
                        for (x, y) in [(i, j), (j, i)] {
                            if u[x].is_finite() && u[y].is_finite() && !seeds.contains(&x) {
                                prop_assert!(u[x] <= u[y] + wmax + tol,
                                    "{order:?} {fact} {method:?} {:?}: U jump {} > {}", out.stop, u[x] - u[y], wmax);
                            }
                        }
                    }
                }
            }
            for s in 0..srcs.len() {
                prop_assert!(connected(grid, l, s as i32, radius > 0.0), "label {} not connected: {order:?} {fact} {method:?} radius {radius} sources {srcs:?} labels {l:?}", s);
            }
        }
    }
}

#[test]
fn all_four_solvers_agree_within_their_documented_errors() {
    // Exact solution: the radial cost W = 1 + 0.3 sin(8 r) around the source
    // gives U = r + (0.3/8)(1 − cos 8r) (straight rays). Each solver is
    // checked against it with its own documented error, and the solvers
    // against each other: fast marching and fast sweeping solve the same
    // discrete equations at order 1; Dijkstra overestimates by at most its
    // metrication error (2.79 % with 16 neighbours in 2D, 12.8 % with 26 in
    // 3D, see the Dijkstra module) and never underestimates the continuous distance by more than the
    // cost's variation along one edge.
    for (shape, c) in [
        (vec![65usize, 65], vec![0.51, 0.493]),
        (vec![25usize, 25, 25], vec![0.51, 0.493, 0.47]),
    ] {
        let n = shape[0];
        let d = shape.len();
        let h = 1.0 / (n - 1) as f64;
        let src: Vec<f64> = c.iter().map(|x| x / h).collect();
        let p = problem(
            &shape,
            &vec![h; d],
            |x| radial_w(dist(x, &c)),
            vec![Source::Point(src)],
        );
        let exact_u = |x: &[f64]| radial_u(dist(x, &c));
        let fm1 = run(&p, &opts(Order::First, false));
        let fm2 = run(&p, &opts(Order::Second, true));
        let fs1 = run(
            &p,
            &opts(Order::First, false).with_method(Method::FastSweeping),
        );
        let fs2 = run(
            &p,
            &opts(Order::Second, true).with_method(Method::FastSweeping),
        );
        let dj = run(
            &p,
            &EikonalOptions::DEFAULT
                .with_method(Method::Dijkstra)
                .with_connectivity(geodex::numerics::Connectivity::Extended),
        );
        let (e_fm1, _) = errors(&p, &fm1, exact_u);
        let (e_fm2, _) = errors(&p, &fm2, exact_u);
        let (e_fs1, _) = errors(&p, &fs1, exact_u);
        let (e_fs2, _) = errors(&p, &fs2, exact_u);
        println!(
            "{d}D n={n}: max error fm1 {e_fm1:.2e} fm2 {e_fm2:.2e} fs1 {e_fs1:.2e} fs2 {e_fs2:.2e}"
        );
        // First order: O(h log h) near the source, a few cells' worth at most.
        assert!(e_fm1 <= 3.0 * h && e_fs1 <= 3.0 * h, "{e_fm1} {e_fs1}");
        // Second order with factoring: a fraction of a cell (0.04 h in 2D at
        // n = 65, 0.11 h in 3D at the coarse n = 25).
        assert!(e_fm2 <= 0.2 * h && e_fs2 <= 0.2 * h, "{e_fm2} {e_fs2}");
        let metrication = if d == 2 { 0.0279 } else { 0.1281 };
        let mut worst_over = 0.0f64;
        for (i, (((a1, a2), b1), g)) in fm1
            .distance
            .iter()
            .zip(fm2.distance.iter())
            .zip(fs1.distance.iter())
            .zip(dj.distance.iter())
            .enumerate()
        {
            assert!(a1.is_finite() && a2.is_finite() && b1.is_finite() && g.is_finite());
            assert!((a1 - b1).abs() <= 1e-9, "cell {i}: fm1 {a1} fs1 {b1}");
            assert!((a1 - a2).abs() <= 3.0 * h, "cell {i}: fm1 {a1} fm2 {a2}");
            let u = exact_u(&position(&p.grid, i));
            // Graph paths are longer than the geodesic up to metrication,
            // plus up to one cell where the path leaves the seed ball (it
            // starts at a seed cell, not at the off-grid point); the
            // trapezoid rule on the varying cost may undercut by a little.
            assert!(*g >= u - 0.3 * h, "cell {i}: dijkstra {g} below exact {u}");
            assert!(
                *g <= u * (1.0 + metrication) + h,
                "cell {i}: dijkstra {g} exact {u}"
            );
            if u > 10.0 * h {
                worst_over = worst_over.max(g / u - 1.0);
            }
        }
        println!("{d}D dijkstra worst relative overestimate {worst_over:.3}");
        // The graph error is real, not zero: the bound above is not vacuous.
        assert!(worst_over > 0.005, "{worst_over}");
    }
}
