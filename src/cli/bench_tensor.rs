//! The anisotropic cases of `geodex bench` (issue 7): the tensor engine on a
//! smooth field of anisotropy up to 10 (HFM's `Riemann2` 1001² and
//! `Riemann3` 101³ settings), and side by side with the isotropic engine on
//! the same isotropic field.
//!
//! * `tensor2d-N`: on `[0, 1]²`, `M(x) = λ1 e1e1ᵀ + λ2 e2e2ᵀ` with
//!   `λ1 = 1`, `sqrt(λ2/λ1) = μ(x) = 1 + 4.5 (1 + sin 2πx sin 2πy)` ∈ [1, 10]
//!   and `e1` at the angle `θ = π (x + y²)`; source at the centre; no exact solution.
//! * `tensor3d-N`: on `[0, 1]³`, a needle field `λ2 Id + (λ1 − λ2) e1e1ᵀ`
//!   with the same `μ(x, y)` and `e1 = (cos θ, sin θ cos φ, sin θ sin φ)`,
//!   `θ = π x`, `φ = π (y + z)`.
//! * `smoothiso2d-N` (isotropic engine) and `tensoriso2d-N` (tensor engine on
//!   `W² Id`): `W = 1 + 0.5 sin 2πx cos 2πy`.

use std::time::Instant;

use crate::numerics::anisotropic::{
    eigen_tensor, solve as solve_tensor, TensorField, TensorOptions, TensorProblem,
};
use crate::numerics::eikonal::Order;
use crate::numerics::metric::{CostValues, Interpretation};
use crate::numerics::{
    solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source,
};

/// Which anisotropic benchmark problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TensorKind {
    /// Smooth 2D field, anisotropy up to 10.
    Aniso2,
    /// Smooth 3D needle field, anisotropy up to 10.
    Aniso3,
    /// Isotropic smooth cost, isotropic engine.
    SmoothIso2,
    /// The same cost as a tensor `W² Id`, tensor engine.
    TensorIso2,
}

/// What one solve measured.
pub struct TensorMeasured {
    /// Best wall time (stencils + marching for the tensor engine).
    pub seconds: f64,
    /// Cells frozen.
    pub frozen: usize,
    /// Largest distance difference with the isotropic engine (`tensoriso2d`).
    pub max_difference: Option<f64>,
}

fn mu(x: f64, y: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    1.0 + 4.5 * (1.0 + (tau * x).sin() * (tau * y).sin())
}

fn iso_cost(x: f64, y: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    1.0 + 0.5 * (tau * x).sin() * (tau * y).cos()
}

fn field(kind: TensorKind, grid: &Grid) -> Result<TensorField, String> {
    let shape = grid.shape3();
    let h = grid.spacing3();
    let pi = std::f64::consts::PI;
    let pos = |i: usize| {
        let c = grid.unravel(i);
        [c[0] as f64 * h[0], c[1] as f64 * h[1], c[2] as f64 * h[2]]
    };
    let _ = shape;
    TensorField::from_fn(grid, |i| {
        let p = pos(i);
        match kind {
            TensorKind::Aniso2 => {
                let (x, y) = (p[1], p[2]);
                let m = mu(x, y);
                let t = pi * (x + y * y);
                eigen_tensor(2, &[1.0, m * m], &[t.cos(), t.sin()])
            }
            TensorKind::Aniso3 => {
                let (x, y, z) = (p[0], p[1], p[2]);
                let m = mu(x, y);
                let (t, f) = (pi * x, pi * (y + z));
                eigen_tensor(
                    3,
                    &[1.0, m * m],
                    &[t.cos(), t.sin() * f.cos(), t.sin() * f.sin()],
                )
            }
            TensorKind::SmoothIso2 | TensorKind::TensorIso2 => {
                let w = iso_cost(p[1], p[2]);
                Ok(vec![w * w, 0.0, w * w])
            }
        }
    })
    .map_err(|e| e.to_string())
}

/// Solves one case `repeat` times and keeps the best time.
pub fn measure(
    kind: TensorKind,
    n: usize,
    order: Order,
    repeat: u32,
) -> Result<TensorMeasured, String> {
    let dims = if kind == TensorKind::Aniso3 { 3 } else { 2 };
    let h = 1.0 / (n - 1) as f64;
    let grid = Grid::new(&vec![n; dims], &vec![h; dims]).map_err(|e| e.to_string())?;
    let centre = vec![(n - 1) as f64 / 2.0; dims];
    let sources = vec![Source::Point(centre)];
    let mut best = f64::INFINITY;
    if kind == TensorKind::SmoothIso2 {
        let w: Vec<f64> = (0..grid.len())
            .map(|i| {
                let c = grid.unravel(i);
                iso_cost(c[1] as f64 * h, c[2] as f64 * h)
            })
            .collect();
        let cost = IsotropicCost::new(&grid, CostValues::F64(w.into()), Interpretation::Cost, None)
            .map_err(|e| e.to_string())?;
        let problem = EikonalProblem {
            grid,
            cost,
            sources,
        };
        let options = EikonalOptions::DEFAULT
            .with_order(order)
            .with_factoring(order == Order::Second);
        let mut frozen = 0;
        for _ in 0..repeat {
            let t = Instant::now();
            let out = solve(&problem, &options, &Control::new()).map_err(|e| e.to_string())?;
            best = best.min(t.elapsed().as_secs_f64());
            frozen = out.frozen;
        }
        return Ok(TensorMeasured {
            seconds: best,
            frozen,
            max_difference: None,
        });
    }
    let metric = field(kind, &grid)?;
    let problem = TensorProblem {
        grid: grid.clone(),
        metric,
        sources: sources.clone(),
    };
    let options = TensorOptions::DEFAULT
        .with_order(order)
        .with_factoring(order == Order::Second);
    let mut last = None;
    for _ in 0..repeat {
        drop(last.take());
        let t = Instant::now();
        let out = solve_tensor(&problem, &options, &Control::new()).map_err(|e| e.to_string())?;
        best = best.min(t.elapsed().as_secs_f64());
        last = Some(out);
    }
    let out = last.ok_or("no repeat was run")?;
    let max_difference = if kind == TensorKind::TensorIso2 {
        let w: Vec<f64> = (0..grid.len())
            .map(|i| {
                let c = grid.unravel(i);
                iso_cost(c[1] as f64 * h, c[2] as f64 * h)
            })
            .collect();
        let cost = IsotropicCost::new(&grid, CostValues::F64(w.into()), Interpretation::Cost, None)
            .map_err(|e| e.to_string())?;
        let iso = solve(
            &EikonalProblem {
                grid,
                cost,
                sources,
            },
            &EikonalOptions::DEFAULT
                .with_order(order)
                .with_factoring(order == Order::Second),
            &Control::new(),
        )
        .map_err(|e| e.to_string())?;
        Some(
            iso.distance
                .iter()
                .zip(out.output.distance.iter())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max),
        )
    } else {
        None
    };
    Ok(TensorMeasured {
        seconds: best,
        frozen: out.output.frozen,
        max_difference,
    })
}
