//! Polyline simplification: the Ramer–Douglas–Peucker algorithm.
//!
//! A traced minimal path has a vertex every half cell (the Runge–Kutta step),
//! so a path across a 1024² image has thousands of vertices, most of them on
//! nearly straight stretches. [`simplify`] keeps a subset of the vertices such
//! that every dropped vertex lies within `tolerance` of the kept polyline:
//! for each stretch between two kept vertices `a` and `b`, the dropped
//! vertices `p` between them satisfy `dist(p, [a, b]) ≤ tolerance`, the
//! distance to the segment (not the line). The first and last vertices are
//! always kept, so a simplified path still runs from its source to its end.
//!
//! The recursion of the classic algorithm is an explicit stack here: the
//! worst case is `O(n²)` distance evaluations (a spiral), the usual case
//! `O(n log n)`, and no input can overflow the call stack.
//!
//! # Examples
//!
//! ```
//! use geodex::numerics::polyline::simplify;
//! // Five points on a line and one bump of 0.3 at x = 2.
//! let p = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.3], [3.0, 0.0], [4.0, 0.0]];
//! assert_eq!(simplify(&p, 0.5), vec![0, 4]);
//! assert_eq!(simplify(&p, 0.2), vec![0, 2, 4]);
//! ```

/// The indices of the vertices of `points` kept by Ramer–Douglas–Peucker
/// with the given `tolerance` (same units as the points), in order. The first
/// and last index are always kept; a `tolerance` that is not positive (0, or
/// NaN) keeps every vertex.
pub fn simplify<const D: usize>(points: &[[f64; D]], tolerance: f64) -> Vec<usize> {
    let n = points.len();
    if n <= 2 || tolerance.is_nan() || tolerance <= 0.0 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((a, b)) = stack.pop() {
        if b <= a + 1 {
            continue;
        }
        let (mut far, mut far_d) = (a, -1.0);
        for (k, p) in points.iter().enumerate().take(b).skip(a + 1) {
            let d = segment_distance(p, &points[a], &points[b]);
            if d > far_d {
                far_d = d;
                far = k;
            }
        }
        if far_d > tolerance {
            keep[far] = true;
            stack.push((a, far));
            stack.push((far, b));
        }
    }
    keep.iter()
        .enumerate()
        .filter_map(|(k, &kept)| kept.then_some(k))
        .collect()
}

/// Euclidean distance from `p` to the segment `[a, b]`.
fn segment_distance<const D: usize>(p: &[f64; D], a: &[f64; D], b: &[f64; D]) -> f64 {
    let mut ab2 = 0.0;
    let mut ap_ab = 0.0;
    for k in 0..D {
        let ab = b[k] - a[k];
        ab2 += ab * ab;
        ap_ab += (p[k] - a[k]) * ab;
    }
    let t = if ab2 > 0.0 {
        (ap_ab / ab2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut d2 = 0.0;
    for k in 0..D {
        let q = a[k] + t * (b[k] - a[k]);
        d2 += (p[k] - q) * (p[k] - q);
    }
    d2.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn short_and_zero_tolerance_keep_everything() {
        assert_eq!(simplify::<2>(&[], 1.0), Vec::<usize>::new());
        assert_eq!(simplify(&[[0.0, 0.0]], 1.0), vec![0]);
        let p = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
        assert_eq!(simplify(&p, 0.0), vec![0, 1, 2]);
        assert_eq!(simplify(&p, f64::NAN), vec![0, 1, 2]);
        assert_eq!(simplify(&p, 1e-9), vec![0, 2]);
    }

    #[test]
    fn a_circle_keeps_the_chord_bound() {
        // A circle of radius r sampled finely: chords of sagitta ≤ tol have
        // half-angle θ with r(1 − cos θ) ≤ tol, so about π / acos(1 − tol/r)
        // vertices are needed, and not many more.
        let r = 100.0;
        let n = 4000;
        let p: Vec<[f64; 2]> = (0..=n)
            .map(|k| {
                let t = std::f64::consts::PI * k as f64 / n as f64;
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        let tol = 0.25;
        let kept = simplify(&p, tol);
        let ideal = std::f64::consts::PI / (2.0 * (1.0 - tol / r).acos());
        assert!(
            (kept.len() as f64) < 2.5 * ideal + 2.0,
            "{} kept, ideal {ideal}",
            kept.len()
        );
        assert!(
            (kept.len() as f64) > ideal,
            "{} kept, ideal {ideal}",
            kept.len()
        );
    }

    #[test]
    fn distance_is_to_the_segment_not_the_line() {
        // The middle point lies on the line through the ends, 5 beyond b.
        let p = [[0.0, 0.0], [15.0, 0.0], [10.0, 0.0]];
        assert_eq!(simplify(&p, 1.0), vec![0, 1, 2]);
    }

    proptest! {
        /// Every dropped vertex is within the tolerance of the kept polyline
        /// (of the kept segment spanning it), and the ends are kept.
        #[test]
        fn dropped_vertices_are_within_tolerance(
            steps in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), 0..200),
            tol in 0.01f64..3.0,
        ) {
            let mut p = vec![[0.0, 0.0, 0.0]];
            for (dx, dy, dz) in steps {
                let q = p[p.len() - 1];
                p.push([q[0] + dx, q[1] + dy, q[2] + dz]);
            }
            let kept = simplify(&p, tol);
            prop_assert_eq!(kept[0], 0);
            prop_assert_eq!(*kept.last().unwrap(), p.len() - 1);
            for w in kept.windows(2) {
                prop_assert!(w[0] < w[1]);
                for k in w[0] + 1..w[1] {
                    let d = segment_distance(&p[k], &p[w[0]], &p[w[1]]);
                    prop_assert!(d <= tol, "vertex {} at {} > {}", k, d, tol);
                }
            }
        }
    }
}
