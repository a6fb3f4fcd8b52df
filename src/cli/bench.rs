//! `geodex bench`: timings of the eikonal solvers on fixed problems, with the
//! error against the exact solution where there is one.
//!
//! Speed lives here, never in the test suite. Every case is solved `--repeat`
//! times on one thread (the solvers are serial) and the best wall time is
//! reported, with nanoseconds per grid cell.
//!
//! # Cases
//! Names are `KIND-N-METHOD-VARIANT`; `--case` keeps the cases whose name
//! contains the given text (repeatable), `--list` prints them.
//!
//! * `point2d-N`: unit cost on `[0, 1]^2` sampled by `N x N` cells
//!   (`h = 1/(N-1)`), point source at the centre. Exact: `U = |x - p|`.
//! * `poincare2d-N`: `W(x, y) = 1/y` on `[-0.5, 0.5] x [1, 2]` (axis 0 is
//!   `x`, axis 1 is `y`), source `(0, 1.5)`. Exact:
//!   `U = arcosh(1 + |x - p|^2 / (2 y y_0))`.
//! * `random2d-N`: cost uniform in `[1, 2]` (splitmix64, seed 42), source at
//!   the centre; no exact solution.
//! * `point3d-N`: unit cost on `[0, 1]^3`, point source at the centre.
//!
//! Variants: `o1` (first order, no source factoring: the scheme of
//! scikit-fmm), `o2` (second order with factoring), `o2plain` (second order
//! without factoring: the scheme of scikit-fmm's order 2, for the point
//! sources), `c4`/`c8`/`c16` (`c6`/`c18`/`c26` in 3D) for Dijkstra's
//! neighbourhoods.
//!
//! # Peak memory
//! Each case runs in a child process (`geodex bench --single NAME`), so that
//! memory freed by an earlier case and kept by the allocator does not hide the
//! peak of the next. On Linux, before the first repeat the child writes `5` to
//! `/proc/self/clear_refs`, which resets the peak resident set size `VmHWM`
//! of `/proc/self/status` to the current `VmRSS`; after the solve the extra
//! peak `VmHWM - VmRSS(before)` divided by the number of cells is the peak
//! memory per cell of the solve (working arrays, heap and output; the input
//! cost array is excluded as it exists before). Page granularity makes it
//! meaningless on tiny grids. Reported as `null` / `-` where `/proc` is not
//! available.

use std::borrow::Cow;
use std::time::Instant;

use clap::Args;
use serde_json::json;

use super::bench_tensor::TensorKind;
use crate::numerics::eikonal::{Connectivity, Method, Order};
use crate::numerics::exact;
use crate::numerics::metric::{CostValues, Interpretation};
use crate::numerics::{
    solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source,
};

/// Flags of `geodex bench`.
#[derive(Debug, Clone, Args)]
pub struct BenchArgs {
    /// Keep only the cases whose name contains this text; repeatable.
    #[arg(long = "case", value_name = "NAME")]
    pub cases: Vec<String>,
    /// Solve each case this many times and report the best time.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
    /// Small grids only (256^2 and 48^3): a smoke run of every case.
    #[arg(long)]
    pub quick: bool,
    /// One JSON object per line instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Print the case names and exit.
    #[arg(long)]
    pub list: bool,
    /// Run every case in this process instead of one child process per case
    /// (the peak memory of later cases is then hidden by freed memory that the
    /// allocator keeps).
    #[arg(long)]
    pub in_process: bool,
    /// Internal: run exactly this case in this process and print one JSON line.
    #[arg(long, hide = true, value_name = "NAME")]
    pub single: Option<String>,
}

/// Why `geodex bench` failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// No case matches the filters.
    #[error("--case: no benchmark case matches {0:?} (see geodex bench --list)")]
    NoCase(Vec<String>),
    /// Some cases could not be solved (each was reported on its own line).
    #[error("{0} case(s) failed")]
    Failed(usize),
}

/// The problem family of a case.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Point2,
    Poincare2,
    Random2,
    Point3,
    /// Anisotropic cases (issue 7), see [`super::bench_tensor`].
    Tensor(super::bench_tensor::TensorKind),
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Point2 => "point2d",
            Kind::Poincare2 => "poincare2d",
            Kind::Random2 => "random2d",
            Kind::Point3 => "point3d",
            Kind::Tensor(t) => match t {
                TensorKind::Aniso2 => "tensor2d",
                TensorKind::Aniso3 => "tensor3d",
                TensorKind::SmoothIso2 => "smoothiso2d",
                TensorKind::TensorIso2 => "tensoriso2d",
            },
        }
    }

    fn dims(self) -> usize {
        if self == Kind::Point3 || self == Kind::Tensor(TensorKind::Aniso3) {
            3
        } else {
            2
        }
    }
}

/// One benchmark: a problem, a size and a solver configuration.
#[derive(Debug, Clone)]
struct Case {
    kind: Kind,
    n: usize,
    method: Method,
    order: Order,
    connectivity: Connectivity,
    /// Source factoring (fast marching and sweeping): on for order 2 by
    /// default; the `o2plain` cases turn it off (scikit-fmm's scheme).
    factoring: bool,
}

impl Case {
    fn name(&self) -> String {
        let method = match self.method {
            Method::FastMarching => "fmm",
            Method::FastSweeping => "fsm",
            Method::Dijkstra => "dijkstra",
        };
        let variant = match self.method {
            Method::Dijkstra => {
                let k = match (self.connectivity, self.kind.dims()) {
                    (Connectivity::Axial, 2) => 4,
                    (Connectivity::Diagonal, 2) => 8,
                    (Connectivity::Extended, 2) => 16,
                    (Connectivity::Axial, _) => 6,
                    (Connectivity::Diagonal, _) => 18,
                    (Connectivity::Extended, _) => 26,
                };
                format!("c{k}")
            }
            _ => match (self.order, self.factoring) {
                (Order::First, _) => "o1".into(),
                (Order::Second, true) => "o2".into(),
                (Order::Second, false) => "o2plain".into(),
            },
        };
        format!("{}-{}-{method}-{variant}", self.kind.name(), self.n)
    }

    fn options(&self) -> EikonalOptions {
        EikonalOptions::DEFAULT
            .with_method(self.method)
            .with_order(self.order)
            // Order 1 without factoring is the scheme of scikit-fmm; order 2
            // with factoring is the accurate default (`o2plain`: without,
            // scikit-fmm's order-2 scheme).
            .with_factoring(self.factoring)
            .with_connectivity(self.connectivity)
    }
}

fn all_cases(quick: bool) -> Vec<Case> {
    use Connectivity::{Axial, Diagonal, Extended};
    use Method::{Dijkstra, FastMarching as Fmm, FastSweeping as Fsm};
    use Order::{First, Second};
    let (sizes2, n2, sizes3, n3) = if quick {
        (vec![256], 256, vec![48], 48)
    } else {
        (vec![1024, 2048, 4001], 1024, vec![128, 256], 128)
    };
    let case = |kind, n, method, order, connectivity| Case {
        kind,
        n,
        method,
        order,
        connectivity,
        factoring: order == Second,
    };
    // Order 2 without factoring, the scheme scikit-fmm's order 2 runs.
    let plain = |kind, n| Case {
        factoring: false,
        ..case(kind, n, Fmm, Second, Diagonal)
    };
    let mut out = Vec::new();
    for &n in &sizes2 {
        for order in [First, Second] {
            out.push(case(Kind::Point2, n, Fmm, order, Diagonal));
        }
        out.push(plain(Kind::Point2, n));
    }
    for kind in [Kind::Poincare2, Kind::Random2] {
        for order in [First, Second] {
            out.push(case(kind, n2, Fmm, order, Diagonal));
        }
    }
    for &n in &sizes3 {
        for order in [First, Second] {
            out.push(case(Kind::Point3, n, Fmm, order, Diagonal));
        }
        out.push(plain(Kind::Point3, n));
    }
    for kind in [Kind::Point2, Kind::Poincare2, Kind::Random2] {
        for order in [First, Second] {
            out.push(case(kind, n2, Fsm, order, Diagonal));
        }
    }
    for order in [First, Second] {
        out.push(case(Kind::Point3, n3, Fsm, order, Diagonal));
    }
    for conn in [Axial, Diagonal, Extended] {
        out.push(case(Kind::Point2, n2, Dijkstra, First, conn));
        out.push(case(Kind::Point3, n3, Dijkstra, First, conn));
    }
    out.push(case(Kind::Poincare2, n2, Dijkstra, First, Diagonal));
    out.push(case(Kind::Random2, n2, Dijkstra, First, Diagonal));
    // Issue 7: HFM's Riemann2 1001² / Riemann3 101³ settings, and the tensor
    // engine side by side with the isotropic one on an isotropic field.
    let (t2, t3) = if quick { (256, 48) } else { (1001, 101) };
    for order in [First, Second] {
        out.push(case(
            Kind::Tensor(TensorKind::Aniso2),
            t2,
            Fmm,
            order,
            Diagonal,
        ));
        out.push(case(
            Kind::Tensor(TensorKind::Aniso3),
            t3,
            Fmm,
            order,
            Diagonal,
        ));
        out.push(case(
            Kind::Tensor(TensorKind::SmoothIso2),
            t2,
            Fmm,
            order,
            Diagonal,
        ));
        out.push(case(
            Kind::Tensor(TensorKind::TensorIso2),
            t2,
            Fmm,
            order,
            Diagonal,
        ));
    }
    out
}

/// A benchmark problem with its exact solution, if known.
struct Setup {
    grid: Grid,
    cost: Option<Vec<f64>>,
    source: Vec<f64>,
    exact: Option<Box<dyn Fn([usize; 3]) -> f64>>,
}

fn setup(kind: Kind, n: usize) -> Result<Setup, String> {
    let h = 1.0 / (n - 1) as f64;
    let mid = (n - 1) as f64 / 2.0;
    let grid =
        Grid::new(&vec![n; kind.dims()], &vec![h; kind.dims()]).map_err(|e| e.to_string())?;
    let centre = vec![mid; kind.dims()];
    Ok(match kind {
        Kind::Point2 | Kind::Point3 => Setup {
            grid,
            cost: None,
            source: centre,
            exact: Some(Box::new(move |x: [usize; 3]| {
                // Exact: U = |x - p| (unit cost); a 2D grid pads axis 0.
                let axes = &x[3 - kind.dims()..];
                h * axes
                    .iter()
                    .map(|&c| (c as f64 - mid).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })),
        },
        Kind::Poincare2 => {
            // Axis 0 is x in [-0.5, 0.5], axis 1 is y in [1, 2]; W = 1/y.
            let mut w = Vec::with_capacity(n * n);
            for _i in 0..n {
                for j in 0..n {
                    w.push(1.0 / (1.0 + j as f64 * h));
                }
            }
            Setup {
                grid,
                cost: Some(w),
                source: vec![0.5 / h, 0.5 / h],
                exact: Some(Box::new(move |x: [usize; 3]| {
                    exact::poincare(-0.5 + x[1] as f64 * h, 1.0 + x[2] as f64 * h, 0.0, 1.5)
                })),
            }
        }
        Kind::Tensor(_) => return Err("tensor cases are set up by bench_tensor".into()),
        Kind::Random2 => {
            let mut state = 42u64;
            let w = (0..n * n).map(|_| 1.0 + uniform(&mut state)).collect();
            Setup {
                grid,
                cost: Some(w),
                source: centre,
                exact: None,
            }
        }
    })
}

/// splitmix64: a uniform number in `[0, 1)`.
fn uniform(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// One measured case.
struct Measured {
    seconds: f64,
    max_error: Option<f64>,
    mean_error: Option<f64>,
    peak_bytes_per_cell: Option<f64>,
    frozen: usize,
    sweeps: Option<usize>,
}

fn measure(case: &Case, repeat: u32) -> Result<Measured, String> {
    if let Kind::Tensor(kind) = case.kind {
        let m = super::bench_tensor::measure(kind, case.n, case.order, repeat)?;
        return Ok(Measured {
            seconds: m.seconds,
            // The tensor-vs-isotropic difference where there is one.
            max_error: m.max_difference,
            mean_error: None,
            peak_bytes_per_cell: None,
            frozen: m.frozen,
            sweeps: None,
        });
    }
    let s = setup(case.kind, case.n)?;
    let cost = match &s.cost {
        Some(w) => IsotropicCost::new(
            &s.grid,
            CostValues::F64(Cow::Borrowed(w)),
            Interpretation::Cost,
            None,
        ),
        None => IsotropicCost::constant(1.0),
    }
    .map_err(|e| e.to_string())?;
    let problem = EikonalProblem {
        grid: s.grid.clone(),
        cost,
        sources: vec![Source::Point(s.source.clone())],
    };
    let options = case.options();
    let mut best = f64::INFINITY;
    let mut peak = None;
    let mut last = None;
    for r in 0..repeat {
        // Free the previous output before measuring the next solve.
        drop(last.take());
        let base = if r == 0 { reset_peak() } else { None };
        let started = Instant::now();
        let out = solve(&problem, &options, &Control::new()).map_err(|e| e.to_string())?;
        best = best.min(started.elapsed().as_secs_f64());
        if let (Some(base), Some(hwm)) = (base, peak_kib()) {
            peak = Some(hwm.saturating_sub(base) as f64 * 1024.0 / s.grid.len() as f64);
        }
        last = Some(out);
    }
    let out = last.ok_or("no repeat was run")?;
    let (mut max, mut sum, mut count) = (None, 0.0, 0usize);
    if let Some(exact) = &s.exact {
        let mut m = 0.0f64;
        for (i, &u) in out.distance.iter().enumerate() {
            if u.is_finite() {
                let e = (u - exact(s.grid.unravel(i))).abs();
                m = m.max(e);
                sum += e;
                count += 1;
            }
        }
        max = Some(m);
    }
    Ok(Measured {
        seconds: best,
        max_error: max,
        mean_error: max.map(|_| sum / count.max(1) as f64),
        peak_bytes_per_cell: peak,
        frozen: out.frozen,
        sweeps: out.sweeps,
    })
}

/// Resets the peak RSS to the current RSS; returns the current RSS in KiB.
fn reset_peak() -> Option<u64> {
    std::fs::write("/proc/self/clear_refs", "5").ok()?;
    status_kib("VmRSS:")
}

/// The peak RSS since the last reset, in KiB.
fn peak_kib() -> Option<u64> {
    status_kib("VmHWM:")
}

fn status_kib(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    line[key.len()..].split_whitespace().next()?.parse().ok()
}

fn method_name(m: Method) -> &'static str {
    match m {
        Method::FastMarching => "fast_marching",
        Method::FastSweeping => "fast_sweeping",
        Method::Dijkstra => "dijkstra",
    }
}

fn fmt_opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.prec$e}"))
}

/// The result of one case, as printed by `--json`.
fn record(case: &Case, repeat: u32, m: Result<Measured, String>) -> serde_json::Value {
    let cells = case.n.pow(case.kind.dims() as u32);
    match m {
        Ok(m) => json!({
            "tool": "geodex",
            "case": case.name(),
            "method": method_name(case.method),
            "order": if case.order == Order::First { 1 } else { 2 },
            "cells": cells,
            "frozen": m.frozen,
            "sweeps": m.sweeps,
            "repeat": repeat,
            "seconds": m.seconds,
            "ns_per_cell": m.seconds * 1e9 / cells as f64,
            "max_error": m.max_error,
            "mean_error": m.mean_error,
            "peak_bytes_per_cell": m.peak_bytes_per_cell,
        }),
        Err(e) => json!({"tool": "geodex", "case": case.name(), "cells": cells, "error": e}),
    }
}

/// Runs one case in a child process; falls back to this process if the
/// executable cannot be started.
fn run_isolated(case: &Case, args: &BenchArgs) -> serde_json::Value {
    let child = std::env::current_exe().and_then(|exe| {
        let mut cmd = std::process::Command::new(exe);
        cmd.args(["bench", "--single", &case.name(), "--repeat"])
            .arg(args.repeat.to_string());
        if args.quick {
            cmd.arg("--quick");
        }
        cmd.stderr(std::process::Stdio::inherit()).output()
    });
    match child {
        Ok(out) => {
            let text = String::from_utf8_lossy(&out.stdout);
            match text
                .lines()
                .last()
                .and_then(|l| serde_json::from_str(l).ok())
            {
                Some(v) => v,
                None => record(
                    case,
                    args.repeat,
                    Err(format!("the child process failed ({})", out.status)),
                ),
            }
        }
        Err(_) => record(case, args.repeat, measure(case, args.repeat)),
    }
}

/// One row of the table (the `--json` line in columns).
pub fn table_row(v: &serde_json::Value) -> String {
    let name = v["case"].as_str().unwrap_or("?");
    if let Some(e) = v["error"].as_str() {
        return format!("{name:<28} error: {e}");
    }
    let num = |k: &str| v[k].as_f64();
    format!(
        "{:<28} {:>10} {:>10.4} {:>9.1} {:>10} {:>10} {:>8}",
        name,
        v["cells"].as_u64().unwrap_or(0),
        num("seconds").unwrap_or(f64::NAN),
        num("ns_per_cell").unwrap_or(f64::NAN),
        fmt_opt(num("max_error"), 2),
        fmt_opt(num("mean_error"), 2),
        num("peak_bytes_per_cell").map_or("-".into(), |b| format!("{b:.1}")),
    )
}

/// The table header matching [`table_row`].
pub fn table_header() -> String {
    format!(
        "{:<28} {:>10} {:>10} {:>9} {:>10} {:>10} {:>8}",
        "case", "cells", "best_s", "ns/cell", "max_err", "mean_err", "B/cell"
    )
}

/// Runs `geodex bench`.
pub fn run(args: &BenchArgs) -> Result<(), BenchError> {
    if let Some(name) = &args.single {
        let case = all_cases(args.quick)
            .into_iter()
            .find(|c| &c.name() == name)
            .ok_or_else(|| BenchError::NoCase(vec![name.clone()]))?;
        println!(
            "{}",
            record(&case, args.repeat, measure(&case, args.repeat))
        );
        return Ok(());
    }
    let cases: Vec<Case> = all_cases(args.quick)
        .into_iter()
        .filter(|c| args.cases.is_empty() || args.cases.iter().any(|f| c.name().contains(f)))
        .collect();
    if cases.is_empty() {
        return Err(BenchError::NoCase(args.cases.clone()));
    }
    if args.list {
        for c in &cases {
            println!("{}", c.name());
        }
        return Ok(());
    }
    if !args.json {
        println!("{}", table_header());
    }
    let mut failed = 0;
    for case in &cases {
        let v = if args.in_process {
            record(case, args.repeat, measure(case, args.repeat))
        } else {
            run_isolated(case, args)
        };
        if v.get("error").is_some() {
            failed += 1;
        }
        if args.json {
            println!("{v}");
        } else {
            println!("{}", table_row(&v));
        }
    }
    if failed > 0 {
        return Err(BenchError::Failed(failed));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn case_names_are_unique_and_cover_every_method() {
        for quick in [false, true] {
            let cases = all_cases(quick);
            let mut names: Vec<String> = cases.iter().map(Case::name).collect();
            let n = names.len();
            names.sort();
            names.dedup();
            assert_eq!(names.len(), n);
            for m in ["fmm-o1", "fmm-o2", "fsm-o2", "dijkstra-c8", "dijkstra-c26"] {
                assert!(names.iter().any(|c| c.contains(m)), "{m}");
            }
        }
        assert!(all_cases(false)
            .iter()
            .any(|c| c.name() == "point2d-4001-fmm-o2"));
    }

    #[test]
    fn plain_order_two_cases_turn_factoring_off() {
        let cases = all_cases(true);
        let find = |name: &str| {
            let c = cases.iter().find(|c| c.name() == name);
            c.cloned().unwrap_or_else(|| panic!("no case {name}"))
        };
        let factored = find("point2d-256-fmm-o2");
        let plain = find("point2d-256-fmm-o2plain");
        assert!(factored.options().factoring && !plain.options().factoring);
        assert_eq!(plain.options().order, Order::Second);
        assert!(cases.iter().any(|c| c.name() == "point3d-48-fmm-o2plain"));
        // Unit cost: factoring makes order 2 exact to rounding; without it
        // the point source costs O(h) near p.
        let small = |c: Case| Case { n: 33, ..c };
        let e_factored = measure(&small(factored), 1).unwrap().max_error.unwrap();
        let e_plain = measure(&small(plain), 1).unwrap().max_error.unwrap();
        assert!(e_factored < 1e-12, "{e_factored}");
        assert!(e_plain > 1e-4, "{e_plain}");
    }

    #[test]
    fn exact_solutions_vanish_at_the_sources() {
        // Point source at the centre of a 5^3 grid: U(2,2,2) = 0, U(0,2,2) = 2h.
        let s = setup(Kind::Point3, 5).unwrap();
        let exact = s.exact.unwrap();
        assert_eq!(exact([2, 2, 2]), 0.0);
        assert!((exact([0, 2, 2]) - 0.5).abs() < 1e-15);
        let s = setup(Kind::Point2, 5).unwrap();
        let exact = s.exact.unwrap();
        assert!((exact([0, 0, 2]) - 0.5).abs() < 1e-15);
        // Poincaré: the source (0, 1.5) sits at index (0.5/h, 0.5/h).
        let s = setup(Kind::Poincare2, 5).unwrap();
        assert_eq!(s.source, vec![2.0, 2.0]);
        assert!(s.exact.unwrap()([0, 2, 2]).abs() < 1e-15);
        assert!((s.cost.unwrap()[4] - 0.5).abs() < 1e-15);
    }

    #[test]
    fn random_costs_are_reproducible_and_in_range() {
        let a = setup(Kind::Random2, 16).unwrap().cost.unwrap();
        let b = setup(Kind::Random2, 16).unwrap().cost.unwrap();
        assert_eq!(a, b);
        assert!(a.iter().all(|&w| (1.0..2.0).contains(&w)));
        let mean = a.iter().sum::<f64>() / a.len() as f64;
        assert!((mean - 1.5).abs() < 0.05, "{mean}");
    }

    #[test]
    fn dijkstra_cases_run_and_report_their_metrication_error() {
        let case = Case {
            kind: Kind::Point2,
            n: 33,
            method: Method::Dijkstra,
            order: Order::First,
            connectivity: Connectivity::Diagonal,
            factoring: false,
        };
        let m = measure(&case, 1).unwrap();
        assert_eq!(m.frozen, 33 * 33);
        // 8 neighbours: error up to 8.2 % of |x - p| <= 0.71.
        let max = m.max_error.unwrap();
        assert!(max > 0.01 && max < 0.0824 * 0.71, "{max}");
    }
}
