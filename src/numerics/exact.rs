//! Closed-form geodesic distances: the oracles of the accuracy tests and
//! benchmarks. Coordinates here are physical (already multiplied by the spacing).

/// Constant cost `w`, point source `p`: `U(x) = w |x - p|`.
pub fn point_source(x: &[f64], p: &[f64], w: f64) -> f64 {
    w * x
        .iter()
        .zip(p)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt()
}

/// The Poincaré half-plane, `W(x, y) = 1 / y` with `y > 0`, source `(x0, y0)`:
/// `U = arcosh(1 + ((x - x0)^2 + (y - y0)^2) / (2 y y0))`.
pub fn poincare(x: f64, y: f64, x0: f64, y0: f64) -> f64 {
    (1.0 + ((x - x0).powi(2) + (y - y0).powi(2)) / (2.0 * y * y0)).acosh()
}

/// Unit cost in the plane minus the open disk of centre `c` and radius `r`,
/// source `s` outside the disk, query `x` outside the disk.
///
/// If `x` sees `s` the distance is `|x - s|`. Otherwise the shortest path is
/// the tangent segment from `s`, the arc around the disk and the tangent
/// segment to `x`: `sqrt(|s-c|^2 - r^2) + r θ + sqrt(|x-c|^2 - r^2)`, with
/// `θ = ∠(s-c, x-c) - acos(r/|s-c|) - acos(r/|x-c|)` the arc between the two
/// tangent points. `x` is in the shadow exactly when `θ > 0`.
pub fn disk_obstacle(x: [f64; 2], s: [f64; 2], c: [f64; 2], r: f64) -> f64 {
    let (sx, sy) = (s[0] - c[0], s[1] - c[1]);
    let (xx, xy) = (x[0] - c[0], x[1] - c[1]);
    let ds = sx.hypot(sy);
    let dx = xx.hypot(xy);
    let cos = ((sx * xx + sy * xy) / (ds * dx)).clamp(-1.0, 1.0);
    let angle = cos.acos();
    let theta = angle - (r / ds).clamp(-1.0, 1.0).acos() - (r / dx).clamp(-1.0, 1.0).acos();
    if theta <= 0.0 {
        (x[0] - s[0]).hypot(x[1] - s[1])
    } else {
        (ds * ds - r * r).max(0.0).sqrt() + r * theta + (dx * dx - r * r).max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disk_shadow_matches_the_straight_line_at_its_edge() {
        // Source at (-2, 0), disk of radius 1 at the origin. Just behind the
        // disk the path wraps; far to the side the straight line is free.
        let s = [-2.0, 0.0];
        let d = disk_obstacle([2.0, 0.0], s, [0.0, 0.0], 1.0);
        let wrap = 2.0 * 3f64.sqrt() + (std::f64::consts::PI - 2.0 * (0.5f64).acos());
        assert!((d - wrap).abs() < 1e-12);
        assert_eq!(disk_obstacle([-2.0, 3.0], s, [0.0, 0.0], 1.0), 3.0);
    }

    #[test]
    fn poincare_is_zero_at_the_source_and_symmetric() {
        assert_eq!(poincare(0.0, 1.5, 0.0, 1.5), 0.0);
        let a = poincare(0.3, 1.2, 0.0, 1.5);
        let b = poincare(0.0, 1.5, 0.3, 1.2);
        assert!((a - b).abs() < 1e-14);
        // Along the vertical line the distance is |ln(y / y0)|.
        assert!((poincare(0.0, 2.0, 0.0, 1.5) - (2.0f64 / 1.5).ln()).abs() < 1e-12);
    }
}
