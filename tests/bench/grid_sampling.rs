//! Farthest-point sampling on a grid against one full distance map of the
//! same grid, in the same process (issue 18's target: 10,000 points on a
//! 1024² grid in at most 3 times one full map).
//!
//! ```text
//! cargo bench --bench grid_sampling -- 1024 10000 3   # side, samples, repeats
//! ```
//!
//! Prints one JSON line per measurement and a last line with the best times
//! and their ratios. The full maps are fast marching from the centre cell
//! on the unit cost, first order (the scheme the sampler's local fronts
//! use) and second order (the default); the sampler starts from the same
//! centre cell as a seed. Each repeat runs all of them in turn, so drift of
//! the machine hits all of them alike.
//!
//! Each repeat then runs the clustered method (`SamplingMethod::Clustered`:
//! farthest points on blocks of 3 cells, one front per sample from the
//! coarse map's bound) with the same seed and count, and prints its time,
//! covering radius, and the cells the bound kept out (`repaired`).

use std::time::Instant;

use geodex::numerics::sampling::{farthest_point_sampling, SamplingMethod, SamplingOptions};
use geodex::numerics::{
    solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Order, Source,
};

fn arg<T: std::str::FromStr>(args: &[String], i: usize, default: T) -> T {
    args.get(i).and_then(|s| s.parse().ok()).unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `cargo bench` passes `--bench`; keep the positional arguments.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let n: usize = arg(&args, 0, 1024);
    let count: usize = arg(&args, 1, 10_000);
    let repeat: usize = arg(&args, 2, 3);
    let grid = Grid::new(&[n, n], &[1.0, 1.0])?;
    let centre = vec![(n / 2) as f64, (n / 2) as f64];
    let mut best = [f64::INFINITY; 4];
    for _ in 0..repeat {
        for (k, order) in [Order::First, Order::Second].into_iter().enumerate() {
            let problem = EikonalProblem {
                grid: grid.clone(),
                cost: IsotropicCost::constant(1.0)?,
                sources: vec![Source::Point(centre.clone())],
            };
            let t = Instant::now();
            let out = solve(
                &problem,
                &EikonalOptions::DEFAULT.with_order(order),
                &Control::new(),
            )?;
            let s = t.elapsed().as_secs_f64();
            best[k] = best[k].min(s);
            println!(
                "{{\"case\": \"full-map-{}\", \"cells\": {}, \"seconds\": {s:.4}, \"max\": {:.3}}}",
                if k == 0 { "order1" } else { "order2" },
                n * n,
                out.distance.iter().copied().fold(0.0, f64::max)
            );
        }
        let options = SamplingOptions {
            count: Some(count),
            radius: None,
            seeds: vec![vec![n / 2, n / 2]],
            method: SamplingMethod::Exact,
        };
        let t = Instant::now();
        let s = farthest_point_sampling(
            &grid,
            &IsotropicCost::constant(1.0)?,
            &options,
            &Control::new(),
        )?;
        let secs = t.elapsed().as_secs_f64();
        best[2] = best[2].min(secs);
        let hex = (2.0 * (n * n) as f64 / (3.0 * 3f64.sqrt() * count as f64)).sqrt();
        println!(
            "{{\"case\": \"farthest-{count}\", \"cells\": {}, \"seconds\": {secs:.4}, \"visited\": {}, \"covering_radius\": {:.3}, \"hexagonal_radius\": {hex:.3}}}",
            n * n,
            s.visited,
            s.covering_radius
        );
        // The clustered method (farthest points on blocks of cells, then one
        // front per sample from the coarse map's bound).
        let t = Instant::now();
        let c = farthest_point_sampling(
            &grid,
            &IsotropicCost::constant(1.0)?,
            &SamplingOptions {
                method: SamplingMethod::Clustered,
                ..options.clone()
            },
            &Control::new(),
        )?;
        let secs = t.elapsed().as_secs_f64();
        best[3] = best[3].min(secs);
        let report = c
            .clustered
            .ok_or("the clustered method fell back to exact")?;
        println!(
            "{{\"case\": \"clustered-{count}\", \"seconds\": {secs:.4}, \"visited\": {}, \"covering_radius\": {:.3}, \"block\": {}, \"repaired\": {}, \"refined\": {}}}",
            c.visited, c.covering_radius, report.block, report.repaired, report.refined
        );
    }
    println!(
        "{{\"best_full_order1\": {:.4}, \"best_full_order2\": {:.4}, \"best_exact\": {:.4}, \"best_clustered\": {:.4}, \"exact_to_order1\": {:.2}, \"exact_to_order2\": {:.2}, \"clustered_to_order1\": {:.2}, \"clustered_to_order2\": {:.2}}}",
        best[0],
        best[1],
        best[2],
        best[3],
        best[2] / best[0],
        best[2] / best[1],
        best[3] / best[0],
        best[3] / best[1]
    );
    Ok(())
}
