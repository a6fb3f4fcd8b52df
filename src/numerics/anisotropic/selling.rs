//! Selling's reduction: the decomposition of a positive definite matrix `D`
//! into non-negative weights on integer offsets,
//!
//! ```text
//! D = Σ_i ρ_i e_i e_iᵀ,   ρ_i ≥ 0,   e_i ∈ Zᵈ,
//! ```
//!
//! with 3 offsets in 2D and 6 in 3D (Selling 1874; Conway–Sloane 1992;
//! Mirebeau, "Fast-marching methods for curvature penalized shortest paths",
//! 2018, and the FM-ASR / Riemann stencils of HFM).
//!
//! A superbase `(b_0, …, b_d)` of `Zᵈ` (a basis plus `b_d = −Σ b_k`) is
//! *D-obtuse* when `⟨b_i, D b_j⟩ ≤ 0` for all `i ≠ j`. Selling's algorithm
//! starts from the canonical superbase and, while some pair has
//! `⟨b_i, D b_j⟩ > 0`, flips it: in 2D `(b_i, b_j, b_k) → (−b_i, b_j, b_i − b_j)`,
//! in 3D `(b_i, b_j, b_k, b_l) → (−b_i, b_j, b_k + b_i, b_l + b_i)`. Each flip
//! lowers the energy `Σ ‖b_k‖²_D`, so it ends; the number of flips grows
//! like the logarithm of the condition number of `D`. For an obtuse
//! superbase, with `ρ_ij = −⟨b_i, D b_j⟩`:
//! * 2D: `e_ij = b_k^⊥` (the remaining vector rotated by 90°);
//! * 3D: `e_ij = b_k × b_l` (cross product of the two remaining vectors).
//!
//! In 2D the obtuse superbase contains a `D`-reduced basis in the sense of
//! Lagrange–Gauss lattice basis reduction, the basis of FM-LBR (Mirebeau
//! 2014): the stencil is the same family of offsets.

/// The `D`-obtuse superbase of Selling's algorithm in 2D, from the
/// canonical one, `d = [d00, d01, d11]`: the weight of offset slot `s` of
/// [`decompose2`] is `ρ_s = −⟨b_i, D b_j⟩` with `(i, j) = PAIRS2[s]` (the
/// derivative of the weights with respect to `D`, for fixed superbase, is
/// `∂ρ_s/∂D = −(b_i b_jᵀ + b_j b_iᵀ)/2`).
pub fn superbase2(d: [f64; 3]) -> [[i32; 2]; 3] {
    let dot = |u: [i32; 2], v: [i32; 2]| dot2(d, u, v);
    let mut b = [[1, 0], [0, 1], [-1, -1]];
    // Each flip strictly lowers the energy; the cap only guards against a
    // non-terminating loop on degenerate input (validated tensors never hit it).
    for _ in 0..200 {
        let mut flipped = false;
        for (i, j, k) in [(0, 1, 2), (0, 2, 1), (1, 2, 0)] {
            if dot(b[i], b[j]) > 0.0 {
                let (bi, bj) = (b[i], b[j]);
                b[i] = [-bi[0], -bi[1]];
                b[k] = [bi[0] - bj[0], bi[1] - bj[1]];
                flipped = true;
                break;
            }
        }
        if !flipped {
            break;
        }
    }
    b
}

/// The superbase pairs `(i, j)` of the offset slots of [`decompose2`]:
/// slot `s` has `ρ_s = −⟨b_i, D b_j⟩` and `e_s = b_k^⊥`, `k` the third index.
pub const PAIRS2: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

fn dot2(d: [f64; 3], u: [i32; 2], v: [i32; 2]) -> f64 {
    let (u0, u1, v0, v1) = (u[0] as f64, u[1] as f64, v[0] as f64, v[1] as f64);
    d[0] * u0 * v0 + d[1] * (u0 * v1 + u1 * v0) + d[2] * u1 * v1
}

/// Decomposition in 2D: `(ρ_i, e_i)` for the 3 offsets, `d = [d00, d01, d11]`.
pub fn decompose2(d: [f64; 3]) -> [(f64, [i32; 2]); 3] {
    let b = superbase2(d);
    let dot = |u: [i32; 2], v: [i32; 2]| dot2(d, u, v);
    let perp = |v: [i32; 2]| [-v[1], v[0]];
    [
        ((-dot(b[0], b[1])).max(0.0), perp(b[2])),
        ((-dot(b[0], b[2])).max(0.0), perp(b[1])),
        ((-dot(b[1], b[2])).max(0.0), perp(b[0])),
    ]
}

/// The superbase quadruples `(i, j, k, l)` of the offset slots of
/// [`decompose3`]: slot `s` has `ρ_s = −⟨b_i, D b_j⟩` and `e_s = b_k × b_l`.
pub const PAIRS3: [(usize, usize, usize, usize); 6] = [
    (0, 1, 2, 3),
    (0, 2, 1, 3),
    (0, 3, 1, 2),
    (1, 2, 0, 3),
    (1, 3, 0, 2),
    (2, 3, 0, 1),
];

fn dot3(d: [f64; 6], u: [i32; 3], v: [i32; 3]) -> f64 {
    let dm = [[d[0], d[1], d[2]], [d[1], d[3], d[4]], [d[2], d[4], d[5]]];
    let mut s = 0.0;
    for a in 0..3 {
        for c in 0..3 {
            s += dm[a][c] * u[a] as f64 * v[c] as f64;
        }
    }
    s
}

/// The `D`-obtuse superbase of Selling's algorithm in 3D,
/// `d = [d00, d01, d02, d11, d12, d22]`: the weight of slot `s` of
/// [`decompose3`] is `ρ_s = −⟨b_i, D b_j⟩`, `(i, j, _, _) = PAIRS3[s]`.
pub fn superbase3(d: [f64; 6]) -> [[i32; 3]; 4] {
    let dot = |u: [i32; 3], v: [i32; 3]| dot3(d, u, v);
    let mut b = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, -1, -1]];
    for _ in 0..400 {
        let mut flipped = false;
        for &(i, j, k, l) in &PAIRS3 {
            if dot(b[i], b[j]) > 0.0 {
                let bi = b[i];
                b[i] = [-bi[0], -bi[1], -bi[2]];
                for m in [k, l] {
                    b[m] = [b[m][0] + bi[0], b[m][1] + bi[1], b[m][2] + bi[2]];
                }
                flipped = true;
                break;
            }
        }
        if !flipped {
            break;
        }
    }
    b
}

/// Decomposition in 3D: `(ρ_i, e_i)` for the 6 offsets,
/// `d = [d00, d01, d02, d11, d12, d22]`.
pub fn decompose3(d: [f64; 6]) -> [(f64, [i32; 3]); 6] {
    let b = superbase3(d);
    let dot = |u: [i32; 3], v: [i32; 3]| dot3(d, u, v);
    let cross = |u: [i32; 3], v: [i32; 3]| {
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    };
    let mut out = [(0.0, [0; 3]); 6];
    for (slot, &(i, j, k, l)) in PAIRS3.iter().enumerate() {
        out[slot] = ((-dot(b[i], b[j])).max(0.0), cross(b[k], b[l]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rebuild2(dec: &[(f64, [i32; 2]); 3]) -> [f64; 3] {
        let mut m = [0.0; 3];
        for (r, e) in dec {
            let (a, b) = (e[0] as f64, e[1] as f64);
            m[0] += r * a * a;
            m[1] += r * a * b;
            m[2] += r * b * b;
        }
        m
    }

    #[test]
    fn decomposition_2d_rebuilds_the_matrix() {
        for &(mu, theta) in &[
            (1.0, 0.0),
            (10.0, 0.5),
            (100.0, 0.52),
            (100.0, 0.785),
            (1000.0, 2.0),
        ] {
            let (c, s): (f64, f64) = (f64::cos(theta), f64::sin(theta));
            let (l1, l2) = (1.0, mu * mu);
            let d = [
                l1 * c * c + l2 * s * s,
                (l1 - l2) * c * s,
                l1 * s * s + l2 * c * c,
            ];
            let dec = decompose2(d);
            assert!(dec.iter().all(|(r, _)| *r >= 0.0));
            let m = rebuild2(&dec);
            for k in 0..3 {
                assert!(
                    (m[k] - d[k]).abs() <= 1e-9 * l2,
                    "mu {mu} theta {theta}: {m:?} vs {d:?}"
                );
            }
        }
    }

    #[test]
    fn decomposition_3d_rebuilds_the_matrix() {
        let cases = [
            [1.0, 0.0, 0.0, 1.0, 0.0, 1.0],
            [3.0, 1.0, -0.5, 2.0, 0.3, 1.5],
            // Needle of ratio 10 along (1, 2, 2)/3.
            {
                let e = [1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0];
                let (l1, l2) = (100.0, 1.0);
                let mut d = [0.0; 6];
                let mut s = 0;
                for a in 0..3 {
                    for b in a..3 {
                        d[s] = l2 * if a == b { 1.0 } else { 0.0 } + (l1 - l2) * e[a] * e[b];
                        s += 1;
                    }
                }
                d
            },
        ];
        for d in cases {
            let dec = decompose3(d);
            let mut m = [0.0; 6];
            for (r, e) in dec {
                assert!(r >= 0.0);
                let mut s = 0;
                for a in 0..3 {
                    for b in a..3 {
                        m[s] += r * e[a] as f64 * e[b] as f64;
                        s += 1;
                    }
                }
            }
            for k in 0..6 {
                assert!((m[k] - d[k]).abs() < 1e-9 * 100.0, "{m:?} vs {d:?}");
            }
        }
    }
}
