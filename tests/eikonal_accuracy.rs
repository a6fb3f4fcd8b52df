//! Accuracy of the isotropic eikonal solvers against closed-form solutions
//! (`geodex::numerics::exact`). Every test names its exact solution and
//! asserts max and mean error bounds measured on the cells that the solver
//! reached (point coordinates in index units, physical = index × spacing).
//!
//! Print the measured figures with
//! `cargo test --release --test eikonal_accuracy -- --nocapture`.

use geodex::numerics::eikonal::EikonalOutput;
use geodex::numerics::exact;
use geodex::numerics::metric::{CostValues, Interpretation};
use geodex::numerics::{
    solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Order, Source,
};

/// Builds a problem on `shape` with `spacing`, cost `w(physical position)` and sources.
fn problem(
    shape: &[usize],
    spacing: &[f64],
    w: impl Fn(&[f64]) -> f64,
    sources: Vec<Source>,
) -> EikonalProblem<'static> {
    let grid = Grid::new(shape, spacing).unwrap();
    let values: Vec<f64> = (0..grid.len())
        .map(|i| {
            let idx = grid.unravel(i);
            let x: Vec<f64> = idx[3 - shape.len()..]
                .iter()
                .zip(spacing)
                .map(|(&c, &h)| c as f64 * h)
                .collect();
            w(&x)
        })
        .collect();
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

fn run(p: &EikonalProblem<'_>, o: &EikonalOptions) -> EikonalOutput {
    solve(p, o, &Control::new()).unwrap()
}

/// (max, mean) of |U − exact| over the finite cells; exact takes the physical position.
fn errors(
    p: &EikonalProblem<'_>,
    out: &EikonalOutput,
    exact: impl Fn(&[f64]) -> f64,
) -> (f64, f64) {
    let grid = &p.grid;
    let nd = grid.ndim();
    let h = grid.spacing().to_vec();
    let (mut max, mut sum, mut count) = (0.0f64, 0.0, 0usize);
    for (i, &u) in out.distance.iter().enumerate() {
        if !u.is_finite() {
            continue;
        }
        let idx = grid.unravel(i);
        let x: Vec<f64> = idx[3 - nd..]
            .iter()
            .zip(&h)
            .map(|(&c, &h)| c as f64 * h)
            .collect();
        let e = (u - exact(&x)).abs();
        max = max.max(e);
        sum += e;
        count += 1;
    }
    assert!(count > 0);
    (max, sum / count as f64)
}

fn opts(order: Order, factoring: bool) -> EikonalOptions {
    EikonalOptions::DEFAULT
        .with_order(order)
        .with_factoring(factoring)
}

/// Observed orders log2(e_k / e_{k+1}) for resolutions doubling.
fn orders(e: &[f64]) -> Vec<f64> {
    e.windows(2).map(|w| (w[0] / w[1]).log2()).collect()
}

/// Point source in [0,1]^d at an off-grid physical point; returns (max, mean) per resolution.
fn point_source_errors(
    d: usize,
    sizes: &[usize],
    w: &dyn Fn(f64) -> f64,
    exact_r: &dyn Fn(f64) -> f64,
    o: &EikonalOptions,
) -> Vec<(f64, f64)> {
    let c = [0.51, 0.493, 0.507];
    sizes
        .iter()
        .map(|&n| {
            let h = 1.0 / (n - 1) as f64;
            let src: Vec<f64> = c[..d].iter().map(|x| x / h).collect();
            let p = problem(
                &vec![n; d],
                &vec![h; d],
                |x| w(dist(x, &c[..d])),
                vec![Source::Point(src)],
            );
            let out = run(&p, o);
            errors(&p, &out, |x| exact_r(dist(x, &c[..d])))
        })
        .collect()
}

fn dist(x: &[f64], c: &[f64]) -> f64 {
    x.iter()
        .zip(c)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn point_source_unit_cost_first_order_converges_at_order_one() {
    // Exact: U(x) = |x − p| (exact::point_source with w = 1).
    for (d, sizes) in [(2, vec![33, 65, 129]), (3, vec![17, 33, 65])] {
        let e = point_source_errors(d, &sizes, &|_| 1.0, &|r| r, &opts(Order::First, false));
        let max: Vec<f64> = e.iter().map(|e| e.0).collect();
        let mean: Vec<f64> = e.iter().map(|e| e.1).collect();
        println!("{d}D order 1 unfactored, N={sizes:?}: max {max:?} mean {mean:?} orders max {:.2?} mean {:.2?}", orders(&max), orders(&mean));
    }
}

#[test]
fn poincare_half_plane() {
    // Exact: exact::poincare, W = 1/y on [−0.5, 0.5] × [1, 2], source (0, 1.5).
    for (n, order, fact) in [
        (100, Order::Second, true),
        (100, Order::First, false),
        (100, Order::Second, false),
        (100, Order::First, true),
    ] {
        let h = 1.0 / (n - 1) as f64;
        let grid_w = |x: &[f64]| 1.0 / (1.0 + x[1]);
        let p = problem(
            &[n, n],
            &[h, h],
            grid_w,
            vec![Source::Point(vec![0.5 / h, 0.5 / h])],
        );
        let out = run(&p, &opts(order, fact));
        let (max, mean) = errors(&p, &out, |x| {
            exact::poincare(x[0] - 0.5, x[1] + 1.0, 0.0, 1.5)
        });
        println!("poincare {n} {order:?} factoring {fact}: max {max:.3e} mean {mean:.3e}");
    }
}
