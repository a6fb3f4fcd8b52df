//! Farthest-point sampling on grids (`numerics::sampling`) against its
//! references: the hexagonal covering optimum, a full fast-marching solve
//! from all the samples at once, and the Euclidean nearest sample.

use geodex::numerics::eikonal::{EikonalOptions, EikonalProblem, Order, Source};
use geodex::numerics::metric::{CostValues, Interpretation};
use geodex::numerics::sampling::{farthest_point_sampling, GridSampling, SamplingOptions};
use geodex::numerics::{solve, Control, Grid, IsotropicCost};
use proptest::prelude::*;

fn sample(grid: &Grid, cost: &IsotropicCost<'_>, count: usize) -> GridSampling {
    let options = SamplingOptions {
        count: Some(count),
        ..Default::default()
    };
    farthest_point_sampling(grid, cost, &options, &Control::new()).expect("sampling")
}

/// The covering radius of the hexagonal packing of `n` points on area `a`.
fn r_hex(a: f64, n: usize) -> f64 {
    (2.0 * a / (3.0 * 3f64.sqrt() * n as f64)).sqrt()
}

#[test]
fn covering_radius_is_within_1_5_of_the_hexagonal_optimum() {
    let grid = Grid::unit(&[256, 256]).expect("grid");
    let cost = IsotropicCost::constant(1.0).expect("cost");
    let area = 255.0 * 255.0;
    let s = sample(&grid, &cost, 200);
    for n in [50, 100, 200] {
        let r = s.radii[n - 1];
        let ratio = r / r_hex(area, n);
        println!(
            "N = {n}: covering radius {r:.3}, r_hex {:.3}, ratio {ratio:.3}",
            r_hex(area, n)
        );
        assert!(ratio <= 1.5, "N = {n}: ratio {ratio}");
        assert!(ratio >= 0.9, "N = {n}: ratio {ratio} (below the optimum?)");
    }
    // The same ratio with the Euclidean distance to the samples (what the
    // first-order scheme overestimates along diagonals).
    for n in [50, 100, 200] {
        let pts = &s.samples[..n];
        let mut r = 0.0f64;
        for i in 0..256 {
            for j in 0..256 {
                let d = pts
                    .iter()
                    .map(|p| {
                        ((i as f64 - p[0] as f64).powi(2) + (j as f64 - p[1] as f64).powi(2)).sqrt()
                    })
                    .fold(f64::INFINITY, f64::min);
                r = r.max(d);
            }
        }
        println!(
            "N = {n}: Euclidean covering radius {r:.3}, ratio {:.3}",
            r / r_hex(area, n)
        );
    }
    // The local fronts visit far fewer cells than a solve per sample.
    println!(
        "visited {} cells for 200 samples ({:.1} grids)",
        s.visited,
        s.visited as f64 / grid.len() as f64
    );
    assert!(s.visited < 20 * grid.len(), "visited {}", s.visited);
}

/// `U` and the labels are those of one first-order fast march from every
/// sample at once (same update), on a cost field with walls, up to the
/// boundary cells explained below.
#[test]
fn matches_a_full_fast_marching_solve_from_all_samples() {
    for shape in [vec![96usize, 80], vec![24, 20, 18]] {
        let grid = Grid::unit(&shape).expect("grid");
        let n = grid.len();
        let w: Vec<f64> = (0..n)
            .map(|i| {
                let x = i as f64 * 0.37;
                if i % 97 == 5 {
                    f64::INFINITY
                } else {
                    1.0 + 0.5 * x.sin().abs()
                }
            })
            .collect();
        let cost = IsotropicCost::new(&grid, CostValues::F64(w.into()), Interpretation::Cost, None)
            .expect("cost");
        let s = sample(&grid, &cost, 40);
        let problem = EikonalProblem {
            grid: grid.clone(),
            cost: cost.clone(),
            sources: s
                .samples
                .iter()
                .map(|p| Source::Cells {
                    cells: vec![p.clone()],
                    values: None,
                })
                .collect(),
        };
        let options = EikonalOptions::DEFAULT
            .with_order(Order::First)
            .with_factoring(false);
        let full = solve(&problem, &options, &Control::new()).expect("solve");
        let full_u: Vec<f64> = full.distance.iter().copied().collect();
        let full_l: Vec<i32> = full.labels.iter().copied().collect();
        let (mut worst, mut worst_abs) = (0.0f64, 0.0f64);
        let (mut differ, mut below, mut off_boundary) = (0usize, 0usize, 0usize);
        let strides: Vec<usize> = (0..shape.len())
            .map(|k| shape[k + 1..].iter().product())
            .collect();
        for i in 0..n {
            let (a, b) = (s.distance[i], full_u[i]);
            if a.is_infinite() || b.is_infinite() {
                assert_eq!(a, b, "cell {i}");
                continue;
            }
            let rel = (a - b).abs() / b.max(1.0);
            worst = worst.max(rel);
            worst_abs = worst_abs.max((a - b).abs());
            if rel > 1e-9 {
                differ += 1;
                below += usize::from(a < b);
                // On a Voronoi boundary: a neighbour has another label.
                let boundary = strides.iter().enumerate().any(|(k, &st)| {
                    let c = (i / st) % shape[k];
                    (c > 0 && full_l[i - st] != full_l[i])
                        || (c + 1 < shape[k] && full_l[i + st] != full_l[i])
                });
                off_boundary += usize::from(!boundary);
            }
        }
        println!("{shape:?}: {differ} cells differ by > 1e-9 ({below} below the full solve, {off_boundary} off the Voronoi boundaries)");
        let same = (0..n).filter(|&i| s.labels[i] == full_l[i]).count();
        println!(
            "{shape:?}: max difference {worst:.2e} relative, {worst_abs:.3} absolute, labels equal on {same}/{n} cells"
        );
        // The full march's update is computed per label of the known
        // neighbours (the smallest wins), which is not monotone when a
        // neighbour changes label: a cell that keeps its value because the
        // new sample did not lower it can lie below what the full march
        // computes with its neighbours' new labels. So the local fronts agree
        // to rounding except on a few cells next to Voronoi boundaries
        // (mostly lower), by less than half a step of the scheme.
        assert!(differ * 25 <= n, "{shape:?}: {differ}/{n} cells differ");
        assert!(
            off_boundary * 10 <= differ,
            "{shape:?}: {off_boundary} off the boundaries"
        );
        assert!(
            worst_abs <= 0.5 * 1.5,
            "{shape:?}: {worst_abs} (h = 1, max W = 1.5)"
        );
        assert!(worst <= 0.05, "{shape:?}: {worst}");
        assert!(same as f64 >= 0.99 * n as f64, "{shape:?}: {same}/{n}");
    }
}

/// On a constant cost the label of a cell is its Euclidean nearest sample,
/// except on near-ties (within the first-order scheme's error).
#[test]
fn labels_are_the_nearest_sample() {
    let grid = Grid::unit(&[128, 128]).expect("grid");
    let cost = IsotropicCost::constant(1.0).expect("cost");
    let s = sample(&grid, &cost, 60);
    let pts: Vec<[f64; 2]> = s
        .samples
        .iter()
        .map(|p| [p[0] as f64, p[1] as f64])
        .collect();
    let mut agree = 0;
    for i in 0..grid.len() {
        let (x, y) = ((i / 128) as f64, (i % 128) as f64);
        let d = |p: &[f64; 2]| ((x - p[0]).powi(2) + (y - p[1]).powi(2)).sqrt();
        let mut by_distance: Vec<(f64, usize)> =
            pts.iter().enumerate().map(|(k, p)| (d(p), k)).collect();
        by_distance.sort_by(|a, b| a.0.total_cmp(&b.0));
        let label = s.labels[i] as usize;
        if label == by_distance[0].1 {
            agree += 1;
        } else {
            // A near-tie: the label's sample is at most ~1.5 cells farther.
            assert!(
                d(&pts[label]) - by_distance[0].0 <= 1.5,
                "cell ({x}, {y}): label {label} at {}, nearest {} at {}",
                d(&pts[label]),
                by_distance[0].1,
                by_distance[0].0
            );
        }
    }
    let share = agree as f64 / grid.len() as f64;
    println!("labels equal to the Euclidean nearest sample on {share:.4} of the cells");
    assert!(share >= 0.95, "{share}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The covering radius never increases, every sample was the farthest
    /// cell when it was placed (its distance was the previous radius), and
    /// the final map's maximum is the last radius.
    #[test]
    fn covering_radius_never_increases(
        n0 in 3usize..40,
        n1 in 3usize..40,
        count in 1usize..30,
        h in 0.5f64..2.0,
        seed_fraction in 0.0f64..1.0,
    ) {
        let grid = Grid::new(&[n0, n1], &[1.0, h]).expect("grid");
        let count = count.min(n0 * n1);
        let seed = vec![((n0 - 1) as f64 * seed_fraction) as usize, n1 / 2];
        let options = SamplingOptions {
            count: Some(count),
            seeds: vec![seed.clone()],
            ..Default::default()
        };
        let cost = IsotropicCost::constant(1.0).expect("cost");
        let s = farthest_point_sampling(&grid, &cost, &options, &Control::new()).expect("sampling");
        prop_assert_eq!(&s.samples[0], &seed);
        prop_assert!(s.radii.windows(2).all(|w| w[1] <= w[0]), "{:?}", s.radii);
        let max = s.distance.iter().copied().fold(0.0, f64::max);
        prop_assert_eq!(max, s.covering_radius);
        prop_assert_eq!(s.labels.iter().filter(|&&l| l < 0).count(), 0);
    }
}

/// Anisotropic farthest-point sampling (`tensor_farthest_point_sampling`)
/// under a constant metric `M = λ1 e1e1ᵀ + λ2 e2e2ᵀ`: `x ↦ M^{1/2} x` is an
/// isometry onto the Euclidean plane, so the Voronoi cells are Euclidean
/// cells stretched by `sqrt(λ2 / λ1)` along `e1`, and the covering optimum
/// is the hexagonal one of the area measured in the metric, `sqrt(det M) A`.
mod tensor {
    use super::r_hex;
    use geodex::numerics::anisotropic::TensorField;
    use geodex::numerics::sampling::delaunay::{geodesic_delaunay_tensor, DelaunayOptions};
    use geodex::numerics::sampling::triangulation::check_planar;
    use geodex::numerics::sampling::{tensor_farthest_point_sampling, SamplingOptions};
    use geodex::numerics::{Control, Grid};

    /// The summed second moments of the interior cells (those touching no
    /// border cell): `[s00, s01, s11]` about each cell's own centroid.
    fn interior_moments(shape: [usize; 2], labels: &[i32], count: usize) -> ([f64; 3], usize) {
        let [n0, n1] = shape;
        let mut border = vec![false; count];
        let mut sums = vec![[0.0f64; 6]; count]; // n, x, y, xx, xy, yy
        for r in 0..n0 {
            for c in 0..n1 {
                let l = labels[r * n1 + c];
                assert!(l >= 0);
                let l = l as usize;
                if r == 0 || c == 0 || r + 1 == n0 || c + 1 == n1 {
                    border[l] = true;
                }
                let (x, y) = (r as f64, c as f64);
                let s = &mut sums[l];
                s[0] += 1.0;
                s[1] += x;
                s[2] += y;
                s[3] += x * x;
                s[4] += x * y;
                s[5] += y * y;
            }
        }
        let mut m = [0.0; 3];
        let mut interior = 0;
        for (l, s) in sums.iter().enumerate() {
            if border[l] {
                continue;
            }
            interior += 1;
            let (mx, my) = (s[1] / s[0], s[2] / s[0]);
            m[0] += s[3] - s[0] * mx * mx;
            m[1] += s[4] - s[0] * mx * my;
            m[2] += s[5] - s[0] * my * my;
        }
        (m, interior)
    }

    /// Eigenvalues (larger first) and the angle of the leading eigenvector.
    fn principal(m: [f64; 3]) -> (f64, f64, f64) {
        let (a, b, c) = (m[0], m[1], m[2]);
        let mean = 0.5 * (a + c);
        let d = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let angle = 0.5 * (2.0 * b).atan2(a - c);
        (mean + d, mean - d, angle)
    }

    #[test]
    fn voronoi_cells_are_stretched_by_the_metric_and_the_covering_is_near_hexagonal() {
        let grid = Grid::unit(&[240, 240]).expect("grid");
        // λ2 / λ1 = 4: lengths along e1 are half those across it, so the
        // cells are twice as long along e1, which makes 30° with axis 0.
        let theta = 30f64.to_radians();
        let (l1, l2) = (1.0, 4.0);
        let metric =
            TensorField::from_eigen(&grid, &[l1, l2], &[theta.cos(), theta.sin()]).expect("m");
        let count = 150;
        let options = SamplingOptions {
            count: Some(count),
            ..Default::default()
        };
        let s = tensor_farthest_point_sampling(&grid, &metric, &options, &Control::new())
            .expect("sampling");
        assert_eq!(s.samples.len(), count);
        assert!(s.radii.windows(2).all(|w| w[1] <= w[0]));

        let (m, interior) = interior_moments([240, 240], &s.labels, count);
        let (big, small, angle) = principal(m);
        let ratio = (big / small).sqrt();
        let expected = (l2 / l1).sqrt();
        let turn = (angle - theta).abs().to_degrees();
        println!(
            "{interior} interior cells: axis ratio {ratio:.3} (expected {expected}), \
             leading axis at {:.1}°",
            angle.to_degrees()
        );
        assert!(interior >= 60, "{interior} interior cells");
        assert!(
            (ratio / expected - 1.0).abs() <= 0.10,
            "axis ratio {ratio} against {expected}"
        );
        assert!(turn <= 5.0, "leading axis {:.1}°", angle.to_degrees());

        // The covering radius against the hexagonal optimum in the metric.
        let area = 239.0 * 239.0 * (l1 * l2).sqrt();
        for n in [50, 100, 150] {
            let ratio = s.radii[n - 1] / r_hex(area, n);
            println!("N = {n}: covering radius / r_hex = {ratio:.3}");
            assert!(ratio <= 1.5, "N = {n}: ratio {ratio}");
            assert!(ratio >= 0.9, "N = {n}: ratio {ratio}");
        }
    }

    #[test]
    fn the_geodesic_delaunay_dual_of_an_anisotropic_sampling_is_a_valid_triangulation() {
        let grid = Grid::unit(&[120, 160]).expect("grid");
        let metric = TensorField::from_eigen(&grid, &[1.0, 9.0], &[1.0, 2.0]).expect("m");
        let options = SamplingOptions {
            count: Some(80),
            seeds: vec![vec![0, 0], vec![0, 159], vec![119, 0], vec![119, 159]],
            ..Default::default()
        };
        let s = tensor_farthest_point_sampling(&grid, &metric, &options, &Control::new())
            .expect("sampling");
        let d = geodesic_delaunay_tensor(
            &grid,
            &metric,
            s,
            &DelaunayOptions::default(),
            &Control::new(),
        )
        .expect("delaunay");
        assert!(check_planar(&d.points, &d.dual.triangles).is_empty());
        // The triangles tile the rectangle.
        let area: f64 = d
            .dual
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| d.points[v as usize]);
                0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
            })
            .sum();
        assert!((area - 119.0 * 159.0).abs() < 1e-6, "area {area}");
        println!(
            "{} vertices ({} added), {} triangles",
            d.points.len(),
            d.added,
            d.dual.triangles.len()
        );
    }
}
