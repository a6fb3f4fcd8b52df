//! The anisotropic solver against exact solutions (issue 7's bounds).

use geodex::numerics::anisotropic::height_map::height_map_metric;
use geodex::numerics::anisotropic::{
    eigen_tensor, solve, TensorField, TensorOptions, TensorProblem,
};
use geodex::numerics::{
    Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Order, Source,
};

/// `U` of a constant metric `m` from `p` (index coordinates) at `x`, spacing `h`.
fn exact_const(m: &[f64], h: f64, p: [f64; 2], x: [f64; 2]) -> f64 {
    let z = [(x[0] - p[0]) * h, (x[1] - p[1]) * h];
    (m[0] * z[0] * z[0] + 2.0 * m[1] * z[0] * z[1] + m[2] * z[1] * z[1]).sqrt()
}

/// Relative max error of the constant-metric solve on an `n × n` grid of
/// `[0, 1]²`, source at the centre (off-grid for even `n`), ratio `mu`, `e1` at `deg`.
fn constant_case(n: usize, mu: f64, deg: f64, options: &TensorOptions) -> f64 {
    let h = 1.0 / (n - 1) as f64;
    let grid = Grid::new(&[n, n], &[h, h]).unwrap();
    let t = deg.to_radians();
    let m = eigen_tensor(2, &[1.0, mu * mu], &[t.cos(), t.sin()]).unwrap();
    let metric = TensorField::constant(&grid, &m).unwrap();
    let c = (n - 1) as f64 / 2.0;
    let p = [c, c];
    let problem = TensorProblem {
        grid,
        metric,
        sources: vec![Source::Point(p.to_vec())],
    };
    let out = solve(&problem, options, &Control::new()).unwrap().output;
    let mut worst: f64 = 0.0;
    for i in 0..n {
        for j in 0..n {
            let e = exact_const(&m, h, p, [i as f64, j as f64]);
            // Outside a fixed physical (Euclidean) ball of radius 0.1 around
            // the source, so that the error falls under refinement: near the
            // source the discrete solution is the same in index units at
            // every resolution.
            let r = h * ((i as f64 - c).powi(2) + (j as f64 - c).powi(2)).sqrt();
            if r < 0.1 {
                continue;
            }
            worst = worst.max((out.distance[[i, j]] - e).abs() / e);
        }
    }
    worst
}

#[test]
fn constant_metrics_meet_the_issue_bounds_and_converge() {
    let o = TensorOptions::DEFAULT;
    for &mu in &[1.0, 10.0, 100.0] {
        for &deg in &[0.0, 30.0, 45.0] {
            let coarse = constant_case(128, mu, deg, &o);
            let fine = constant_case(256, mu, deg, &o);
            let finest = if mu > 1.0 {
                constant_case(512, mu, deg, &o)
            } else {
                fine
            };
            println!("mu {mu:>5} deg {deg:>4}: rel max err 128² {coarse:.3e}  256² {fine:.3e}  512² {finest:.3e}");
            // The issue's bounds: 2 % at ratio 10 and 5 % at ratio 100 at
            // 512² (measured: at most 6.7e-4 and 2.2e-3, both at 30°).
            let bound = match mu as u32 {
                1 => 1e-9,
                10 => 0.02,
                _ => 0.05,
            };
            assert!(finest <= bound, "mu {mu} deg {deg}: {finest} > {bound}");
            // Falls under refinement (or is already at rounding level).
            assert!(
                fine <= coarse * 1.001 + 1e-8,
                "mu {mu} deg {deg}: {fine} > {coarse}"
            );
        }
    }
}

/// Mirebeau's pull-back test: `M = Jfᵀ D Jf`, `f(x, y) = (x, y + 0.5 sin πx)`,
/// `D = diag(0.25, 1)`, on `[-1, 1] × [-0.5, 0.5]` with `n` cells across
/// (cell centres, so the source at the origin is between cells).
fn pullback_case(n: usize, options: &TensorOptions) -> (f64, f64) {
    let (n0, n1) = (n, n / 2);
    let h = 2.0 / n as f64;
    let grid = Grid::new(&[n0, n1], &[h, h]).unwrap();
    let coord = |i: usize, j: usize| (-1.0 + (i as f64 + 0.5) * h, -0.5 + (j as f64 + 0.5) * h);
    let pi = std::f64::consts::PI;
    let metric = TensorField::from_fn(&grid, |k| {
        let (i, j) = (k / n1, k % n1);
        let (x, _) = coord(i, j);
        let c = 0.5 * pi * (pi * x).cos();
        Ok(vec![0.25 + c * c, c, 1.0])
    })
    .unwrap();
    let src = vec![(n0 as f64 - 1.0) / 2.0, (n1 as f64 - 1.0) / 2.0];
    let problem = TensorProblem {
        grid,
        metric,
        sources: vec![Source::Point(src)],
    };
    let out = solve(&problem, options, &Control::new()).unwrap().output;
    let (mut linf, mut l1, mut count) = (0.0f64, 0.0, 0usize);
    for i in 0..n0 {
        for j in 0..n1 {
            let (x, y) = coord(i, j);
            if (x - y).abs() >= 1.0 {
                continue;
            }
            let fy = y + 0.5 * (pi * x).sin();
            let exact = (0.25 * x * x + fy * fy).sqrt();
            let e = (out.distance[[i, j]] - exact).abs();
            linf = linf.max(e);
            l1 += e;
            count += 1;
        }
    }
    (linf, l1 / count as f64)
}

#[test]
fn pullback_metric_matches_hfm_at_order_two() {
    let (coarse, _) = pullback_case(100, &TensorOptions::DEFAULT);
    let (fine, mean) = pullback_case(200, &TensorOptions::DEFAULT);
    let (first, _) = pullback_case(200, &TensorOptions::DEFAULT.with_order(Order::First));
    let order = (coarse / fine).log2();
    println!("pull-back: L∞ 100 {coarse:.3e}, 200 {fine:.3e} (mean {mean:.3e}), order {order:.2}; first order at 200: {first:.3e}");
    // The issue's bound (HFM: 1.63e-3 with order 2 at 200 cells); measured
    // 4.4e-4, observed order 2.06 (1.66e-3 and 0.95 before the edge cells
    // completed their stencils).
    assert!(fine <= 1.6e-3, "{fine}");
    assert!(order >= 1.8, "observed order {order}");
    assert!(first > 5.0 * fine);
}

#[test]
fn height_maps_tilted_plane_and_hemisphere() {
    // Tilted plane h = 0.7 x − 1.3 y: the constant metric Id + ∇h∇hᵀ.
    let n = 65;
    let hs = 1.0 / (n - 1) as f64;
    let grid = Grid::new(&[n, n], &[hs, hs]).unwrap();
    let (a, b) = (0.7, -1.3);
    let heights: Vec<f64> = (0..n * n)
        .map(|k| a * (k / n) as f64 * hs + b * (k % n) as f64 * hs)
        .collect();
    let field = height_map_metric(&grid, &heights, &[1.0], 0.0, &Control::new()).unwrap();
    let m = [1.0 + a * a, a * b, 1.0 + b * b];
    let constant = TensorField::constant(&grid, &m).unwrap();
    let src = vec![Source::Point(vec![20.3, 40.6])];
    let run = |metric: TensorField| {
        let p = TensorProblem {
            grid: grid.clone(),
            metric,
            sources: src.clone(),
        };
        solve(&p, &TensorOptions::DEFAULT, &Control::new())
            .unwrap()
            .output
            .distance
    };
    let (u1, u2) = (run(field), run(constant));
    let mut diff: f64 = 0.0;
    let mut err: f64 = 0.0;
    for i in 0..n {
        for j in 0..n {
            diff = diff.max((u1[[i, j]] - u2[[i, j]]).abs());
            let e = exact_const(&m, hs, [20.3, 40.6], [i as f64, j as f64]);
            if e > 0.05 {
                err = err.max((u1[[i, j]] - e).abs() / e);
            }
        }
    }
    println!("tilted plane: |height map − constant| {diff:.2e}, rel err {err:.2e}");
    assert!(diff < 1e-10, "{diff}");
    assert!(err < 0.01, "{err}");

    // Hemisphere of radius 1 over [-1, 1]², walls beyond r = 0.95.
    let n = 201;
    let hs = 2.0 / (n - 1) as f64;
    let grid = Grid::new(&[n, n], &[hs, hs]).unwrap();
    let xy = |k: usize| (-1.0 + (k / n) as f64 * hs, -1.0 + (k % n) as f64 * hs);
    let heights: Vec<f64> = (0..n * n)
        .map(|k| {
            let (x, y) = xy(k);
            (1.0 - (x * x + y * y).min(0.97 * 0.97)).sqrt()
        })
        .collect();
    let walls: Vec<bool> = (0..n * n)
        .map(|k| {
            let (x, y) = xy(k);
            x * x + y * y > 0.95 * 0.95
        })
        .collect();
    let metric = height_map_metric(&grid, &heights, &[1.0], 0.0, &Control::new())
        .unwrap()
        .with_walls(&grid, walls)
        .unwrap();
    for (sx, sy) in [(0.0, 0.0), (0.3, -0.2)] {
        let p = TensorProblem {
            grid: grid.clone(),
            metric: metric.clone(),
            sources: vec![Source::Point(vec![(sx + 1.0) / hs, (sy + 1.0) / hs])],
        };
        let u = solve(&p, &TensorOptions::DEFAULT, &Control::new())
            .unwrap()
            .output
            .distance;
        let sz = (1.0f64 - sx * sx - sy * sy).sqrt();
        let mut err: f64 = 0.0;
        for k in 0..n * n {
            let (x, y) = xy(k);
            if x * x + y * y > 0.7 * 0.7 {
                continue;
            }
            let z = (1.0 - x * x - y * y).sqrt();
            let exact = (x * sx + y * sy + z * sz).clamp(-1.0, 1.0).acos();
            if exact > 0.05 {
                err = err.max((u[[k / n, k % n]] - exact).abs() / exact);
            }
        }
        println!("hemisphere from ({sx}, {sy}): rel max err {err:.3e} (r <= 0.7)");
        assert!(err < 0.01, "{err}");
    }
}

#[test]
fn a_one_cell_wall_with_a_gap_does_not_leak_at_anisotropy_40() {
    let n = 121;
    let grid = Grid::unit(&[n, n]).unwrap();
    let mu: f64 = 40.0;
    let m = eigen_tensor(2, &[1.0, mu * mu], &[1.0, 1.0]).unwrap();
    let gap = 100..=104usize;
    let walls: Vec<bool> = (0..n * n)
        .map(|k| k / n == 60 && !gap.contains(&(k % n)))
        .collect();
    let metric = TensorField::constant(&grid, &m)
        .unwrap()
        .with_walls(&grid, walls)
        .unwrap();
    let s = [40.0, 30.0];
    let p = TensorProblem {
        grid,
        metric,
        sources: vec![Source::Point(s.to_vec())],
    };
    let out = solve(&p, &TensorOptions::DEFAULT, &Control::new()).unwrap();
    println!("stencil width {}", out.stencil.max_offset);
    let u = out.output.distance;
    let norm =
        |z: [f64; 2]| (m[0] * z[0] * z[0] + 2.0 * m[1] * z[0] * z[1] + m[2] * z[1] * z[1]).sqrt();
    let (mut worst_low, mut worst_high, mut mean, mut count) = (0.0f64, 0.0f64, 0.0, 0);
    for i in 62..n {
        for j in 0..n {
            let x = [i as f64, j as f64];
            let detour = (0..=400)
                .map(|t| {
                    let g = [60.0, 99.5 + 5.0 * t as f64 / 400.0];
                    norm([g[0] - s[0], g[1] - s[1]]) + norm([x[0] - g[0], x[1] - g[1]])
                })
                .fold(f64::INFINITY, f64::min);
            let rel = (u[[i, j]] - detour) / detour;
            worst_low = worst_low.min(rel);
            worst_high = worst_high.max(rel);
            mean += rel.abs();
            count += 1;
        }
    }
    let mean = mean / count as f64;
    println!("wall: rel err behind the wall in [{worst_low:.3e}, {worst_high:.3e}], mean {mean:.3e}; direct (80, 70) {:.1} vs U {:.1}",
        norm([40.0, 40.0]), u[[80, 70]]);
    // A leak would give the direct distance, 50 times smaller than the detour.
    assert!(worst_low > -0.01, "{worst_low}");
    assert!(worst_high < 0.08 && mean < 0.03, "{worst_high} {mean}");
    assert!(u[[80, 70]] > 40.0 * norm([40.0, 40.0]));
}

#[test]
fn isotropic_tensors_reproduce_the_isotropic_engine() {
    // Poincaré half-plane W = 1/y on [-0.5, 0.5] × [1, 2], 101², source (0, 1.5).
    let n = 101;
    let h = 1.0 / (n - 1) as f64;
    let grid = Grid::new(&[n, n], &[h, h]).unwrap();
    let w: Vec<f64> = (0..n * n)
        .map(|k| 1.0 / (1.0 + (k % n) as f64 * h))
        .collect();
    let src = vec![Source::Point(vec![50.0, 50.0])];
    let iso = geodex::numerics::solve(
        &EikonalProblem {
            grid: grid.clone(),
            cost: IsotropicCost::new(
                &grid,
                geodex::numerics::metric::CostValues::F64(w.clone().into()),
                Default::default(),
                None,
            )
            .unwrap(),
            sources: src.clone(),
        },
        &EikonalOptions::DEFAULT,
        &Control::new(),
    )
    .unwrap()
    .distance;
    let metric =
        TensorField::from_components(&grid, w.iter().flat_map(|v| [v * v, 0.0, v * v]).collect())
            .unwrap();
    let aniso = solve(
        &TensorProblem {
            grid,
            metric,
            sources: src,
        },
        &TensorOptions::DEFAULT,
        &Control::new(),
    )
    .unwrap()
    .output
    .distance;
    let (mut e_iso, mut e_an, mut diff) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (-0.5 + i as f64 * h, 1.0 + j as f64 * h);
            let exact = geodex::numerics::exact::poincare(x, y, 0.0, 1.5);
            e_iso = e_iso.max((iso[[i, j]] - exact).abs());
            e_an = e_an.max((aniso[[i, j]] - exact).abs());
            diff = diff.max((iso[[i, j]] - aniso[[i, j]]).abs());
        }
    }
    println!("poincaré: L∞ isotropic {e_iso:.3e}, tensor {e_an:.3e}, difference {diff:.3e}");
    assert!(
        e_an <= 1.5 * e_iso + 1e-6 && diff <= 1e-4,
        "{e_an} {e_iso} {diff}"
    );
}
