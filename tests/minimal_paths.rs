//! Minimal paths (`geodex::numerics::paths`) and metric design
//! (`geodex::numerics::metric_design`) against exact geodesics and
//! synthetic images with known centrelines. Each test names its reference
//! and asserts a bound from issue 4. Coordinates: index units, axis 0 first.
//!
//! Print the measured figures with
//! `cargo test --release --test minimal_paths -- --nocapture`.

use geodex::numerics::metric::{CostValues, Interpretation};
use geodex::numerics::metric_design::{self, IntensityDesign, MetricDesign, Reference};
use geodex::numerics::paths::{
    minimal_path, segment_meets_open_box, DescentOptions, DistanceMap, PathError, SourceSet,
};
use geodex::numerics::{
    solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source, StopRules,
};

/// Deterministic xorshift64* generator, uniform in [0, 1).
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    fn normal(&mut self) -> f64 {
        let u = self.uniform().max(1e-300);
        let v = self.uniform();
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

fn problem(grid: Grid, w: Vec<f64>, sources: Vec<Source>) -> EikonalProblem<'static> {
    let cost =
        IsotropicCost::new(&grid, CostValues::F64(w.into()), Interpretation::Cost, None).unwrap();
    EikonalProblem {
        grid,
        cost,
        sources,
    }
}

fn distance(p: &EikonalProblem<'_>, o: &EikonalOptions) -> Vec<f64> {
    solve(p, o, &Control::new())
        .unwrap()
        .distance
        .iter()
        .copied()
        .collect()
}

/// Distance from `x` to the segment `a b`.
fn to_segment(x: &[f64], a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(a, b)| b - a).collect();
    let dd: f64 = d.iter().map(|v| v * v).sum();
    let t = (x
        .iter()
        .zip(a)
        .zip(&d)
        .map(|((x, a), d)| (x - a) * d)
        .sum::<f64>()
        / dd)
        .clamp(0.0, 1.0);
    x.iter()
        .zip(a)
        .zip(&d)
        .map(|((x, a), d)| (x - a - t * d).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Distance from `x` to a densely sampled polyline.
fn to_polyline(x: &[f64], line: &[Vec<f64>]) -> f64 {
    line.windows(2)
        .map(|w| to_segment(x, &w[0], &w[1]))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn unit_cost_paths_are_straight_segments_within_a_tenth_of_a_cell() {
    // 2D, off-grid points, order 2 with factoring.
    let grid = Grid::unit(&[96, 96]).unwrap();
    let cases = [
        ([10.3, 15.7], [85.2, 70.9]),
        ([48.0, 48.0], [5.5, 90.25]),
        ([90.0, 3.0], [4.0, 60.0]),
    ];
    let mut worst: f64 = 0.0;
    for (s, e) in cases {
        let p = problem(
            grid.clone(),
            vec![1.0; grid.len()],
            vec![Source::Point(s.to_vec())],
        );
        let u = distance(&p, &EikonalOptions::DEFAULT);
        let path = minimal_path(&p, &u, &e, &DescentOptions::default()).unwrap();
        let pts = path.index_points(&grid);
        assert_eq!(pts.first().unwrap(), &s.to_vec(), "joined to the source");
        assert_eq!(pts.last().unwrap(), &e.to_vec(), "starts at the end point");
        let dev = pts
            .iter()
            .map(|x| to_segment(x, &s, &e))
            .fold(0.0, f64::max);
        worst = worst.max(dev);
        for (k, x) in pts.iter().enumerate() {
            let d = to_segment(x, &s, &e);
            if d > 0.08 {
                println!(
                    "case {s:?}->{e:?}: vertex {k}/{} at {x:?} dev {d:.3}",
                    pts.len()
                );
            }
        }
        let exact = ((e[0] - s[0]).powi(2) + (e[1] - s[1]).powi(2)).sqrt();
        assert!(
            (path.euclidean_length - exact).abs() < 0.05,
            "{} vs {exact}",
            path.euclidean_length
        );
        assert!((path.geodesic_length - exact).abs() < 0.05);
        assert_eq!(path.discrete_steps, 0, "no fallback on a smooth map");
    }
    println!("straight 2D: max deviation {worst:.4} cells");
    assert!(worst <= 0.1, "max deviation {worst}");

    // 3D with anisotropic spacing: the segment is straight in physical space,
    // hence in index space too.
    let grid = Grid::new(&[40, 40, 40], &[1.0, 1.0, 1.5]).unwrap();
    let (s, e) = ([5.2, 6.0, 4.4], [33.0, 30.5, 35.0]);
    let p = problem(
        grid.clone(),
        vec![1.0; grid.len()],
        vec![Source::Point(s.to_vec())],
    );
    let u = distance(&p, &EikonalOptions::DEFAULT);
    let path = minimal_path(&p, &u, &e, &DescentOptions::default()).unwrap();
    let dev = path
        .index_points(&grid)
        .iter()
        .map(|x| to_segment(x, &s, &e))
        .fold(0.0, f64::max);
    println!("straight 3D: max deviation {dev:.4} cells");
    assert!(dev <= 0.1, "max deviation {dev}");
    let world = path.world_points(&grid);
    assert!((world.last().unwrap()[2] - 35.0 * 1.5).abs() < 1e-12);
}

#[test]
fn poincare_half_plane_geodesics_are_circle_arcs() {
    // W = 1/y on [-0.5, 0.5] x [1, 2] (axis 0 = x, axis 1 = y), 256².
    let n = 256;
    let h = 1.0 / (n - 1) as f64;
    let grid = Grid::new(&[n, n], &[h, h]).unwrap();
    let w: Vec<f64> = (0..grid.len())
        .map(|i| {
            let [_, _, j] = grid.unravel(i);
            1.0 / (1.0 + j as f64 * h)
        })
        .collect();
    let to_index = |x: f64, y: f64| vec![(x + 0.5) / h, (y - 1.0) / h];
    let mut worst: f64 = 0.0;
    for (a, b) in [((-0.4, 1.1), (0.35, 1.5)), ((-0.3, 1.2), (0.3, 1.2))] {
        let p = problem(
            grid.clone(),
            w.clone(),
            vec![Source::Point(to_index(a.0, a.1))],
        );
        let u = distance(&p, &EikonalOptions::DEFAULT);
        let path = minimal_path(&p, &u, &to_index(b.0, b.1), &DescentOptions::default()).unwrap();
        // The circle centred on y = 0 through a and b.
        let xc = (b.0 * b.0 + b.1 * b.1 - a.0 * a.0 - a.1 * a.1) / (2.0 * (b.0 - a.0));
        let r = ((a.0 - xc) * (a.0 - xc) + a.1 * a.1).sqrt();
        let dev = path
            .world_points(&grid)
            .iter()
            .map(|q| {
                let (x, y) = (q[0] - 0.5, q[1] + 1.0);
                (((x - xc).powi(2) + y * y).sqrt() - r).abs() / r
            })
            .fold(0.0, f64::max);
        worst = worst.max(dev);
        // Its hyperbolic length: d = arccosh(1 + |a-b|² / (2 a_y b_y)).
        let exact = (1.0 + ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)) / (2.0 * a.1 * b.1)).acosh();
        assert!(
            (path.geodesic_length - exact).abs() < 1e-3 * exact,
            "{} vs {exact}",
            path.geodesic_length
        );
    }
    println!(
        "Poincaré: max deviation {:.4} % of the radius",
        100.0 * worst
    );
    assert!(worst <= 0.005, "relative deviation {worst}");
}

/// The centreline of the synthetic road: row `i`, column `c(i)`.
fn road_centre(i: f64) -> f64 {
    100.0 + 30.0 * (2.0 * std::f64::consts::PI * i / 150.0).sin()
}

#[test]
fn a_noisy_sinusoidal_road_is_followed_within_one_and_a_half_pixels() {
    // A bright road 3 px wide, f = 0.7 on it and 0.3 around, plus Gaussian
    // noise of standard deviation 0.15 (fixed seed).
    let grid = Grid::unit(&[200, 200]).unwrap();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let curve: Vec<Vec<f64>> = (0..=2000)
        .map(|k| {
            let i = k as f64 * 0.1;
            vec![i, road_centre(i)]
        })
        .collect();
    let f: Vec<f64> = (0..grid.len())
        .map(|c| {
            let [_, i, j] = grid.unravel(c);
            let x = [i as f64, j as f64];
            // Distance to the curve, exact enough for the mask: search nearby samples.
            let k0 = (i as f64 * 10.0) as usize;
            let d = curve[k0.saturating_sub(300)..(k0 + 300).min(curve.len())]
                .iter()
                .map(|q| ((q[0] - x[0]).powi(2) + (q[1] - x[1]).powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min);
            let base = if d <= 1.5 { 0.7 } else { 0.3 };
            base + 0.15 * rng.normal()
        })
        .collect();
    let start = vec![10.0, road_centre(10.0).round()];
    let end = vec![190.0, road_centre(190.0).round()];
    let design = MetricDesign::Intensity(IntensityDesign {
        reference: Reference::Point(start.clone()),
        power: 1.0,
        epsilon: 0.01,
        sigma: 1.0,
    });
    let w = metric_design::design(&grid, &f, &design, &Control::new()).unwrap();
    let p = problem(grid.clone(), w, vec![Source::Point(start.clone())]);
    let mut o = EikonalOptions::DEFAULT;
    o.stop = StopRules {
        targets: vec![end.clone()],
        ..StopRules::default()
    };
    let u = distance(&p, &o);
    let path = minimal_path(&p, &u, &end, &DescentOptions::default()).unwrap();
    let dev = path
        .index_points(&grid)
        .iter()
        .map(|x| to_polyline(x, &curve))
        .fold(0.0, f64::max);
    println!(
        "road: max distance to the centreline {dev:.3} px over {} vertices ({} discrete steps)",
        path.points.len(),
        path.discrete_steps
    );
    assert!(dev <= 1.5, "max distance {dev}");
}

/// The helix axis of the synthetic vessel at parameter `t`.
fn helix(t: f64) -> [f64; 3] {
    [
        t * 128.0 / (3.0 * std::f64::consts::PI),
        64.0 + 30.0 * t.cos(),
        64.0 + 30.0 * t.sin(),
    ]
}

#[test]
fn a_noisy_3d_helix_vessel_is_followed_within_one_and_a_half_voxels() {
    // A bright tube of radius 3 around a helix of 1.5 turns along axis 0,
    // in 128³ with Gaussian noise (fixed seed); vesselness metric.
    let n = 128;
    let grid = Grid::unit(&[n, n, n]).unwrap();
    let axis: Vec<Vec<f64>> = (0..=3000)
        .map(|k| helix(k as f64 * 3.0 * std::f64::consts::PI / 3000.0).to_vec())
        .collect();
    let mut rng = Rng(0xD1B5_4A32_D192_ED03);
    let mut f = vec![0.0; grid.len()];
    for (c, v) in f.iter_mut().enumerate() {
        *v = 0.2 + 0.1 * rng.normal();
        let _ = c;
    }
    // Paint the tube: for each axis sample, the voxels within radius 3.
    let mut inside = vec![false; grid.len()];
    for q in axis.iter().step_by(2) {
        let lo: Vec<usize> = q
            .iter()
            .map(|v| (v - 3.5).floor().max(0.0) as usize)
            .collect();
        for a in lo[0]..=((q[0] + 3.5) as usize).min(n - 1) {
            for b in lo[1]..=((q[1] + 3.5) as usize).min(n - 1) {
                for c in lo[2]..=((q[2] + 3.5) as usize).min(n - 1) {
                    let d2 = (a as f64 - q[0]).powi(2)
                        + (b as f64 - q[1]).powi(2)
                        + (c as f64 - q[2]).powi(2);
                    if d2 <= 9.0 {
                        inside[grid.linear([a, b, c])] = true;
                    }
                }
            }
        }
    }
    for (v, &i) in f.iter_mut().zip(&inside) {
        if i {
            *v += 0.6;
        }
    }
    let design = MetricDesign::Vesselness(metric_design::VesselnessDesign {
        scales: vec![2.0, 3.0],
        ..Default::default()
    });
    let w = metric_design::design(&grid, &f, &design, &Control::new()).unwrap();
    let t0 = 0.15;
    let t1 = 3.0 * std::f64::consts::PI - 0.15;
    let start = helix(t0).to_vec();
    let end = helix(t1).to_vec();
    let p = problem(grid.clone(), w, vec![Source::Point(start)]);
    let mut o = EikonalOptions::DEFAULT;
    o.stop = StopRules {
        targets: vec![end.clone()],
        ..StopRules::default()
    };
    let u = distance(&p, &o);
    let path = minimal_path(&p, &u, &end, &DescentOptions::default()).unwrap();
    let dev = path
        .index_points(&grid)
        .iter()
        .map(|x| to_polyline(x, &axis))
        .fold(0.0, f64::max);
    println!(
        "helix: max distance to the axis {dev:.3} voxels over {} vertices",
        path.points.len()
    );
    assert!(dev <= 1.5, "max distance {dev}");
}

/// A deterministic maze: `m × m` rooms of `room` cells, walls 2 cells thick,
/// carved by a depth-first search with a fixed seed. `true` = wall.
fn maze(m: usize, room: usize, seed: u64) -> (usize, Vec<bool>) {
    let pitch = room + 2;
    let n = m * pitch + 2;
    let mut wall = vec![true; n * n];
    let open = |wall: &mut Vec<bool>, i0: usize, j0: usize, di: usize, dj: usize| {
        for i in i0..i0 + di {
            for j in j0..j0 + dj {
                wall[i * n + j] = false;
            }
        }
    };
    let corner = |r: usize| 2 + r * pitch;
    for r in 0..m {
        for c in 0..m {
            open(&mut wall, corner(r), corner(c), room, room);
        }
    }
    let mut rng = Rng(seed);
    let mut seen = vec![false; m * m];
    let mut stack = vec![(0usize, 0usize)];
    seen[0] = true;
    while let Some(&(r, c)) = stack.last() {
        let mut next = Vec::new();
        if r > 0 && !seen[(r - 1) * m + c] {
            next.push((r - 1, c));
        }
        if r + 1 < m && !seen[(r + 1) * m + c] {
            next.push((r + 1, c));
        }
        if c > 0 && !seen[r * m + c - 1] {
            next.push((r, c - 1));
        }
        if c + 1 < m && !seen[r * m + c + 1] {
            next.push((r, c + 1));
        }
        if next.is_empty() {
            stack.pop();
            continue;
        }
        let (nr, nc) = next[(rng.uniform() * next.len() as f64) as usize];
        seen[nr * m + nc] = true;
        // Knock down the wall between the two rooms.
        let (i0, j0) = (corner(r.min(nr)), corner(c.min(nc)));
        if nr != r {
            open(&mut wall, i0 + room, j0, 2, room);
        } else {
            open(&mut wall, i0, j0 + room, room, 2);
        }
        stack.push((nr, nc));
    }
    (n, wall)
}

#[test]
fn maze_paths_never_enter_a_wall_and_match_the_distance_map() {
    let (n, wall) = maze(5, 20, 7);
    let grid = Grid::unit(&[n, n]).unwrap();
    let w: Vec<f64> = wall
        .iter()
        .map(|&b| if b { f64::INFINITY } else { 1.0 })
        .collect();
    let start = vec![4.0, 4.0];
    let p = problem(grid.clone(), w, vec![Source::Point(start)]);
    let u = distance(&p, &EikonalOptions::DEFAULT);
    let sources = SourceSet::new(&grid, &p.sources).unwrap();
    let map = DistanceMap::new(&grid, &u, &p.cost).unwrap();
    let mut worst: f64 = 0.0;
    // The far corner and a few rooms on the way.
    for end in [
        vec![(n - 5) as f64, (n - 5) as f64],
        vec![(n - 5) as f64, 4.0],
        vec![4.0, (n - 5) as f64],
        vec![(n / 2) as f64 + 0.3, (n / 2) as f64 - 1.7],
    ] {
        let ue = map.value(grid.point3(&end).unwrap());
        let cell = end.iter().map(|v| v.round() as usize).collect::<Vec<_>>();
        if wall[cell[0] * n + cell[1]] {
            continue;
        }
        let path = map
            .descend(
                &sources,
                &end,
                &geodex::numerics::paths::Isotropic,
                &DescentOptions::default(),
            )
            .unwrap();
        for s in path.points.windows(2) {
            for (i, &is_wall) in wall.iter().enumerate() {
                if is_wall {
                    let c = grid.unravel(i).map(|v| v as f64);
                    assert!(
                        !segment_meets_open_box(s[0], s[1], c),
                        "segment {s:?} enters wall cell {c:?}"
                    );
                }
            }
        }
        let rel = (path.geodesic_length - ue).abs() / ue;
        println!(
            "maze end {end:?}: L = {:.3}, U = {ue:.3}",
            path.geodesic_length
        );
        worst = worst.max(rel);
        assert!(rel <= 0.01, "length {} vs U {ue}", path.geodesic_length);
    }
    println!("maze {n}²: worst |L − U| / U = {:.4} %", 100.0 * worst);
}

#[test]
fn voronoi_boundary_and_plateau_end_points_still_reach_a_source() {
    // Constant W, two sources symmetric about column 30: the boundary of
    // their Voronoi cells is the column j = 30, where ∇U is discontinuous.
    let grid = Grid::unit(&[41, 61]).unwrap();
    let sources = vec![
        Source::Point(vec![20.0, 10.0]),
        Source::Point(vec![20.0, 50.0]),
    ];
    let p = problem(grid.clone(), vec![1.0; grid.len()], sources);
    let u = distance(&p, &EikonalOptions::DEFAULT);
    for end in [[35.0, 30.0], [20.0, 30.0], [0.0, 30.0], [40.0, 30.0]] {
        let path = minimal_path(&p, &u, &end, &DescentOptions::default()).unwrap();
        let first = path.index_points(&grid)[0].clone();
        let want = if path.source == 0 {
            [20.0, 10.0]
        } else {
            [20.0, 50.0]
        };
        assert_eq!(first, want.to_vec(), "ends exactly at its source");
        // Still (nearly) the straight segment to the source reached.
        let exact = ((end[0] - want[0]).powi(2) + (end[1] - want[1]).powi(2)).sqrt();
        assert!(
            path.euclidean_length < exact + 1.0,
            "{end:?}: {} vs {exact}",
            path.euclidean_length
        );
    }
    // A true plateau: a cell source covering a block (U = 0 on it) and an
    // end point inside it ends at once; an end point on a flat-topped ridge
    // between two block sources still arrives.
    let block = |i0: usize, j0: usize| Source::Cells {
        cells: (i0..i0 + 5)
            .flat_map(|i| (j0..j0 + 5).map(move |j| vec![i, j]))
            .collect(),
        values: None,
    };
    let p = problem(
        grid.clone(),
        vec![1.0; grid.len()],
        vec![block(18, 5), block(18, 51)],
    );
    let u = distance(&p, &EikonalOptions::DEFAULT);
    let inside = minimal_path(&p, &u, &[20.0, 7.0], &DescentOptions::default()).unwrap();
    assert_eq!(inside.source, 0);
    assert!(inside.euclidean_length <= 1.0);
    let ridge = minimal_path(&p, &u, &[20.0, 30.0], &DescentOptions::default()).unwrap();
    let last = ridge.index_points(&grid)[0].clone();
    assert!(last[1] == 9.0 || last[1] == 51.0, "{last:?}");
}

#[test]
fn bad_end_points_and_budgets_are_refused_not_looped() {
    let grid = Grid::unit(&[20, 20]).unwrap();
    let mut w = vec![1.0; grid.len()];
    for j in 0..20 {
        w[10 * 20 + j] = f64::INFINITY; // a full wall across row 10
    }
    let p = problem(grid.clone(), w, vec![Source::Point(vec![2.0, 2.0])]);
    let u = distance(&p, &EikonalOptions::DEFAULT);
    let o = DescentOptions::default();
    assert!(matches!(
        minimal_path(&p, &u, &[15.0, 5.0], &o),
        Err(PathError::Unreached { .. })
    ));
    assert!(matches!(
        minimal_path(&p, &u, &[10.0, 5.0], &o),
        Err(PathError::Unreached { .. })
    ));
    assert!(matches!(
        minimal_path(&p, &u, &[25.0, 5.0], &o),
        Err(PathError::EndPoint { .. })
    ));
    assert!(matches!(
        minimal_path(&p, &u, &[1.0, 2.0, 3.0], &o),
        Err(PathError::EndPoint { .. })
    ));
    let tight = DescentOptions {
        max_steps: Some(3),
        ..DescentOptions::default()
    };
    assert!(matches!(
        minimal_path(&p, &u, &[8.0, 18.0], &tight),
        Err(PathError::Stalled { steps: 3, .. })
    ));
    let bad = DescentOptions {
        step: 0.8,
        ..DescentOptions::default()
    };
    assert!(matches!(
        minimal_path(&p, &u, &[8.0, 18.0], &bad),
        Err(PathError::Option { field: "step", .. })
    ));
    // A generic direction field (here the isotropic one written as a closure).
    let sources = SourceSet::new(&grid, &p.sources).unwrap();
    let map = DistanceMap::new(&grid, &u, &p.cost).unwrap();
    let closure = |_x: [f64; 3], g: [f64; 3]| Some([-g[0], -g[1], -g[2]]);
    let a = map.descend(&sources, &[8.0, 18.0], &closure, &o).unwrap();
    let b = minimal_path(&p, &u, &[8.0, 18.0], &o).unwrap();
    assert_eq!(a, b);
}
