//! The local upwind solver shared by fast marching and fast sweeping.
//!
//! # Scheme
//!
//! At a cell `x` with cost `W = W(x)`, each axis `k` (of length > 1) whose
//! smaller known neighbour `x + σ e_k` (`σ = ±1`) has value `a_k` contributes
//! one one-sided difference `D_k U = c_k (U − b_k)`:
//!
//! * first order: `D_k U = (U − a_k) / h_k`, so `c_k = 1/h_k`, `b_k = a_k`;
//! * second order (when the next cell `x + 2σ e_k` is known and its value
//!   `a2_k < a_k`): `D_k U = (3U − 4a_k + a2_k) / (2h_k)`, so
//!   `c_k = 3/(2h_k)`, `b_k = (4a_k − a2_k)/3` (first order for that axis
//!   otherwise). Strictly smaller: where `a2_k = a_k` the two cells are a
//!   flat stretch, the inside of a region source (a mask, cells of equal
//!   value) where `U` has a kink at the region's edge, and the one-sided
//!   difference through the kink would put the first cell out at `2/3` of
//!   its distance.
//!
//! `U` is the root of the upwind quadratic
//!
//! ```text
//! Σ_k c_k² ((U − b_k)⁺)² = W²
//! ```
//!
//! whose left side increases from 0 at `U = min b_k`, so the root exists,
//! is unique and is `> min b_k`. It is found by adding the axes in
//! increasing `b_k` until the root of the active terms is `≤` the next `b`
//! (causality: axes with `b_k ≥ U` are dropped). Because `b_k ≥ a_k` for the
//! second-order terms, `U` is at least every upwind value it uses. This is
//! Sethian's (1996) update with per-axis spacing and Tsitsiklis' (1995)
//! causality; the second order one-sided stencil is Sethian's "FMM 2".
//!
//! # Source factoring
//!
//! Near a point source `p` of cost `W_p` the solution behaves like the cone
//! `U_0(x) = W_p |x − p|_h`, whose gradient is singular at `p` and makes
//! every finite-difference scheme lose about one order near it. With additive
//! factoring (Fomel–Luo–Zhao 2009, Treister–Haber 2016) the scheme works on
//! `V = U − U_0`: every one-sided difference of `U` is replaced by the same
//! difference of `V` plus the exact derivative of `U_0` at `x`,
//!
//! ```text
//! D_k U := D_k V − σ ∂_k U_0(x),
//! ```
//!
//! which keeps the form `c_k (U − b_k)` with a shifted `b_k`. For a constant
//! cost `V ≡ 0`, so every difference is exact and so is the scheme.
//!
//! An axis with no known neighbour on either side is a discrete minimum of
//! `U` along that axis. On the grid line nearest to an off-grid source
//! (`|x_k − p_k| ≤ 1/2`) this is an artefact of the source being between
//! cells, not a sign that `∂_k U ≈ 0`: there the term `(∂_k U_0(x) + ∂_k V)²`
//! is kept, with `∂_k V` estimated by the centred difference of `V` at the
//! most upwind neighbour (0 if that stencil is not known; exact for a
//! constant cost either way). Elsewhere a missing axis is dropped as usual.
//!
//! The factored update is tried only when every upwind neighbour carries the
//! label of the same point source (mixing two sources' cones near a Voronoi
//! boundary would be meaningless). It falls back to the unfactored update
//! when the right side is not positive, the root is not finite or it lies
//! below the smallest upwind value it used.

use crate::numerics::metric::IsotropicCost;

/// Grid geometry, precomputed once per solve.
#[derive(Debug, Clone)]
pub(crate) struct Stencil {
    /// Padded shape.
    pub shape: [usize; 3],
    /// C-order strides of the padded shape.
    pub strides: [usize; 3],
    /// Padded spacing.
    pub h: [f64; 3],
    /// `1/h_k²` (first-order coefficient squared).
    inv_h2: [f64; 3],
    /// `9/(4 h_k²)` (second-order coefficient squared).
    inv_h2_second: [f64; 3],
    /// Axes of length > 1.
    axes: [usize; 3],
    naxes: usize,
    /// Division by `strides[0]` and `strides[1]` (for [`Stencil::unravel`]).
    div: [FastDiv; 2],
}

impl Stencil {
    /// The stencil of a grid.
    pub fn new(grid: &crate::numerics::grid::Grid) -> Self {
        let shape = grid.shape3();
        let h = grid.spacing3();
        let mut axes = [0usize; 3];
        let mut naxes = 0;
        for (k, &n) in shape.iter().enumerate() {
            if n > 1 {
                axes[naxes] = k;
                naxes += 1;
            }
        }
        Self {
            shape,
            strides: grid.strides3(),
            h,
            inv_h2: h.map(|h| 1.0 / (h * h)),
            inv_h2_second: h.map(|h| 2.25 / (h * h)),
            axes,
            naxes,
            div: [
                FastDiv::new(grid.strides3()[0]),
                FastDiv::new(grid.strides3()[1]),
            ],
        }
    }

    /// The axes of length > 1.
    #[inline]
    pub fn axes(&self) -> &[usize] {
        &self.axes[..self.naxes]
    }

    /// The axes of length > 1, as a constant list when `A > 0`: the last
    /// `A` padded axes, which the caller must have checked with
    /// [`Stencil::trailing`] (a 2D grid `(1, n0, n1)`, a 3D grid), so that
    /// loops over it unroll with constant axis numbers. [`Stencil::axes`]
    /// for `A = 0`.
    #[inline(always)]
    pub fn axes_as<const A: usize>(&self) -> &[usize] {
        const ALL: [usize; 3] = [0, 1, 2];
        debug_assert!(A == 0 || self.trailing() == Some(A));
        if A > 0 && A <= 3 {
            &ALL[3 - A..]
        } else {
            self.axes()
        }
    }

    /// `Some(A)` if the axes of length > 1 are exactly the last `A` axes.
    #[inline(always)]
    pub fn trailing(&self) -> Option<usize> {
        let n = self.naxes;
        (n > 0 && (0..n).all(|a| self.axes[a] == 3 - n + a)).then_some(n)
    }

    /// Padded 3D index of linear index `i` (as [`Grid::unravel`], without a
    /// division instruction).
    ///
    /// [`Grid::unravel`]: crate::numerics::grid::Grid::unravel
    #[inline]
    pub fn unravel(&self, i: usize) -> [usize; 3] {
        let a = self.div[0].div(i);
        let r = i - a * self.strides[0];
        let b = self.div[1].div(r);
        [a, b, r - b * self.strides[1]]
    }
}

/// Division of a linear index (`< 2^32`, see [`MAX_CELLS`]) by a fixed
/// divisor `d < 2^32` as a multiplication: `x / d = ⌊M x / 2^64⌋` with
/// `M = ⌈2^64 / d⌉`, exact for every 32-bit `x` and `d` (Lemire, Kaser and
/// Kurz 2019, "Faster remainder by direct computation", theorem 1 with
/// `F = 64 ≥ N + log2 d`).
///
/// [`MAX_CELLS`]: crate::numerics::grid::MAX_CELLS
#[derive(Debug, Clone, Copy)]
struct FastDiv {
    d: usize,
    /// `⌈2^64 / d⌉`, or 0 when `d = 1` (no multiplication then).
    m: u64,
}

impl FastDiv {
    fn new(d: usize) -> Self {
        let d = d.max(1);
        let m = if d == 1 {
            0
        } else {
            // ⌈2^64 / d⌉ = ⌊(2^64 − 1) / d⌋ + 1 for every d ≥ 2 (whether or
            // not d divides 2^64), and it fits: it is at most 2^63.
            u64::MAX / d as u64 + 1
        };
        Self { d, m }
    }

    #[inline]
    fn div(&self, x: usize) -> usize {
        if self.d == 1 {
            x
        } else {
            debug_assert!(x <= u32::MAX as usize);
            ((u128::from(self.m) * x as u128) >> 64) as usize
        }
    }
}

/// Where the update reads the labels of known cells: the label array, or
/// nothing at all when there is one source (every known cell has label 0).
pub(crate) trait Labels {
    /// The label of known cell `j`.
    fn at(&self, j: usize) -> i32;
}

impl Labels for [i32] {
    #[inline(always)]
    fn at(&self, j: usize) -> i32 {
        self[j]
    }
}

/// The labels of a solve with one source: 0 for every known cell.
pub(super) struct OneSource;

impl Labels for OneSource {
    #[inline(always)]
    fn at(&self, _: usize) -> i32 {
        0
    }
}

/// A point source as seen by factoring.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FactorPoint {
    /// Padded index coordinates.
    p: [f64; 3],
    /// `W(p)`.
    w: f64,
}

/// The point sources by label, for source factoring.
#[derive(Debug, Clone)]
pub(crate) struct Factor {
    points: Vec<Option<FactorPoint>>,
}

impl Factor {
    /// Factoring data for the point sources of the front; `None` if there is none.
    ///
    /// `W_p` is the multilinear interpolation of the cost at `p` from the
    /// `2^d` cells around it (the front's nearest-cell value if one of them
    /// is a wall): with the nearest-cell value, `V = U − U_0` would keep a
    /// cone of slope `O(h)` at `p` and cost the second-order scheme a
    /// logarithm.
    pub fn new(problem: &super::EikonalProblem<'_>, front: &super::InitialFront) -> Option<Self> {
        if front.points.is_empty() {
            return None;
        }
        let grid = &problem.grid;
        let shape = grid.shape3();
        let mut points = vec![None; problem.sources.len()];
        for sp in &front.points {
            let p = sp.position;
            let lo = p.map(|x| x.floor().max(0.0) as usize);
            let mut w = 0.0;
            for corner in 0..8usize {
                let mut idx = [0usize; 3];
                let mut weight = 1.0;
                for k in 0..3 {
                    let up = corner >> k & 1 == 1;
                    let t = p[k] - lo[k] as f64;
                    idx[k] = if up {
                        (lo[k] + 1).min(shape[k] - 1)
                    } else {
                        lo[k]
                    };
                    weight *= if up { t } else { 1.0 - t };
                }
                if weight > 0.0 {
                    w += weight * problem.cost.at(grid.linear(idx));
                }
            }
            let w = if w.is_finite() && w > 0.0 { w } else { sp.cost };
            if let Some(slot) = usize::try_from(sp.label)
                .ok()
                .and_then(|l| points.get_mut(l))
            {
                *slot = Some(FactorPoint { p, w });
            }
        }
        Some(Self { points })
    }

    /// The point source of `label`, if it is one.
    #[inline]
    pub fn point(&self, label: i32) -> Option<FactorPoint> {
        usize::try_from(label)
            .ok()
            .and_then(|l| self.points.get(l).copied().flatten())
    }
}

/// One axis' upwind data.
#[derive(Debug, Clone, Copy, Default)]
struct Axis {
    k: usize,
    /// Smaller known neighbour value and index.
    a1: f64,
    j1: usize,
    /// `+1.0` if the neighbour is at `x + e_k`, `-1.0` if at `x − e_k`.
    sigma: f64,
    /// Second neighbour value (`+inf` when the second-order stencil is missing).
    a2: f64,
}

/// One term `c2 ((U − b)⁺)²` of the quadratic.
#[derive(Debug, Clone, Copy, Default)]
struct Term {
    b: f64,
    c2: f64,
    a1: f64,
    j1: usize,
}

/// Computes the upwind update of cell `i` (padded index `idx`, cost `w`).
///
/// `known(j)` says whether neighbour `j` may be used (frozen for fast
/// marching; finite for fast sweeping); its value is `u[j]`. With `multi`
/// (several sources), when the known neighbours carry several labels the
/// update is computed for each label's neighbours alone and the smallest
/// wins. Returns the new value and label, or `None` if no neighbour is known
/// or the value would not be finite. Never returns NaN.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn update<const A: usize, K: Fn(usize) -> bool, L: Labels + ?Sized>(
    st: &Stencil,
    i: usize,
    idx: [usize; 3],
    w: f64,
    u: &[f64],
    labels: &L,
    known: K,
    second: bool,
    factor: Option<&Factor>,
    multi: bool,
    cost: &IsotropicCost<'_>,
) -> Option<(f64, i32)> {
    if multi {
        let (ls, nl) = neighbour_labels::<A>(st, i, idx, |j| known(j).then(|| labels.at(j)));
        if nl > 1 {
            // Each source's front is continued on its own and the smallest
            // value wins: combining differences of two fronts in one
            // quadratic would cut the corner at the Voronoi boundary.
            let mut best: Option<(f64, i32)> = None;
            for &l in &ls[..nl] {
                let r = update_one::<A, _, _>(
                    st,
                    i,
                    idx,
                    w,
                    u,
                    labels,
                    |j| labels.at(j) == l && known(j),
                    second,
                    factor,
                    cost,
                );
                if let Some(r) = r {
                    if best.is_none_or(|b| r.0 < b.0) {
                        best = Some(r);
                    }
                }
            }
            return best;
        }
    }
    update_one::<A, _, _>(st, i, idx, w, u, labels, known, second, factor, cost)
}

/// The distinct labels of the axis neighbours of cell `i` (padded index
/// `idx`) in the order met, `label_of(j)` giving a known neighbour's label
/// (`None` for the others): the labels and how many.
#[inline(always)]
pub(crate) fn neighbour_labels<const A: usize>(
    st: &Stencil,
    i: usize,
    idx: [usize; 3],
    label_of: impl Fn(usize) -> Option<i32>,
) -> ([i32; 6], usize) {
    let mut ls = [0i32; 6];
    let mut nl = 0;
    for &k in st.axes_as::<A>() {
        let s = st.strides[k];
        let lo = (idx[k] > 0).then(|| i - s);
        let hi = (idx[k] + 1 < st.shape[k]).then(|| i + s);
        for j in [lo, hi].into_iter().flatten() {
            if let Some(l) = label_of(j) {
                if !ls[..nl].contains(&l) {
                    ls[nl] = l;
                    nl += 1;
                }
            }
        }
    }
    (ls, nl)
}

/// [`update`] for neighbours that all carry one label (or when labels do not matter).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn update_one<const A: usize, K: Fn(usize) -> bool, L: Labels + ?Sized>(
    st: &Stencil,
    i: usize,
    idx: [usize; 3],
    w: f64,
    u: &[f64],
    labels: &L,
    known: K,
    second: bool,
    factor: Option<&Factor>,
    cost: &IsotropicCost<'_>,
) -> Option<(f64, i32)> {
    let mut ax = [Axis::default(); 3];
    let mut n = 0;
    let mut missing = [0usize; 3];
    let mut nmissing = 0;
    for &k in st.axes_as::<A>() {
        let s = st.strides[k];
        let mut a1 = f64::INFINITY;
        let mut j1 = usize::MAX;
        let mut sigma = 0.0;
        if idx[k] > 0 && known(i - s) {
            a1 = u[i - s];
            j1 = i - s;
            sigma = -1.0;
        }
        if idx[k] + 1 < st.shape[k] && known(i + s) && u[i + s] < a1 {
            a1 = u[i + s];
            j1 = i + s;
            sigma = 1.0;
        }
        if j1 == usize::MAX {
            missing[nmissing] = k;
            nmissing += 1;
            continue;
        }
        let mut a2 = f64::INFINITY;
        if second {
            let j2 = if sigma < 0.0 {
                (idx[k] >= 2).then(|| j1 - s)
            } else {
                (idx[k] + 2 < st.shape[k]).then(|| j1 + s)
            };
            if let Some(j2) = j2 {
                if known(j2) && u[j2] < a1 {
                    a2 = u[j2];
                }
            }
        }
        ax[n] = Axis {
            k,
            a1,
            j1,
            sigma,
            a2,
        };
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let ax = &ax[..n];
    let w2 = w * w;

    if let Some(f) = factor {
        let strip = Strip {
            missing: &missing[..nmissing],
            u,
            known: &known,
        };
        if let Some(r) = factored(st, idx, w2, ax, &strip, labels, f) {
            return Some(cap(st, ax, w, cost, r, labels));
        }
    }

    let mut t = [Term::default(); 3];
    if second && ax.iter().any(|a| a.a2 < f64::INFINITY) {
        for (t, a) in t.iter_mut().zip(ax) {
            *t = if a.a2 < f64::INFINITY {
                Term {
                    b: (4.0 * a.a1 - a.a2) / 3.0,
                    c2: st.inv_h2_second[a.k],
                    a1: a.a1,
                    j1: a.j1,
                }
            } else {
                first_term(st, a)
            };
        }
        if let Some((v, m)) = solve_terms(&mut t[..n], w2) {
            if v.is_finite() && t[..m].iter().all(|t| v >= t.a1) {
                return Some(cap(st, ax, w, cost, (v, label_of(&t[..m], labels)), labels));
            }
        }
    }
    for (t, a) in t.iter_mut().zip(ax) {
        *t = first_term(st, a);
    }
    if let Some((v, m)) = solve_terms(&mut t[..n], w2) {
        if v.is_finite() && v >= t[0].a1 {
            return Some((v, label_of(&t[..m], labels)));
        }
    }
    // Only reached through overflow or rounding: the one-axis update.
    let (v, j) = ax
        .iter()
        .map(|a| (a.a1 + w * st.h[a.k], a.j1))
        .min_by(|x, y| x.0.total_cmp(&y.0))?;
    v.is_finite().then(|| (v, labels.at(j)))
}

/// [`update`] for the first-order unfactored scheme when labels do not
/// matter (one source): the same value with the same arithmetic, without the
/// bookkeeping of the general update (no labels, no second neighbours, no
/// per-axis records).
///
/// A neighbour is known exactly when its value in `u` is finite (`u` may
/// hold NaN or `+inf` on the others).
///
/// Returns the new value of cell `i`, or `None` if no neighbour is known or
/// the value would not be finite. Never returns NaN.
#[inline(always)]
pub(super) fn first_order<const A: usize>(
    st: &Stencil,
    i: usize,
    idx: [usize; 3],
    w: f64,
    u: &[f64],
    one_axis: impl Fn(usize) -> f64,
) -> Option<f64> {
    first_order_by::<A>(st, i, idx, w, |j| u[j], one_axis)
}

/// [`first_order`] with the neighbours' values read through `u` (`+inf`
/// for a neighbour that is not known): the farthest-point sampler masks
/// the cells no front has labelled, and the cells of other labels.
#[inline(always)]
pub(crate) fn first_order_by<const A: usize>(
    st: &Stencil,
    i: usize,
    idx: [usize; 3],
    w: f64,
    u: impl Fn(usize) -> f64,
    one_axis: impl Fn(usize) -> f64,
) -> Option<f64> {
    // Per axis slot: the smaller known neighbour value `b` (+inf when the
    // axis has none), `c²`, `h` and the axis. Fixed slots with constant
    // indices (no compaction, a sorting network instead of an insertion
    // sort) keep all of it in registers: the sort of a compacted array went
    // through the stack, and its stores could not be forwarded to the wider
    // loads of the swaps.
    let mut b = [f64::INFINITY; 3];
    let mut c = [0.0f64; 3];
    let mut hs = [0.0f64; 3];
    let mut ks = [0usize; 3];
    for (slot, &k) in st.axes_as::<A>().iter().enumerate() {
        let s = st.strides[k];
        // `<` is false for NaN and +inf: unknown neighbours drop out.
        let mut a = f64::INFINITY;
        if idx[k] > 0 {
            let v = u(i - s);
            if v < a {
                a = v;
            }
        }
        if idx[k] + 1 < st.shape[k] {
            let v = u(i + s);
            if v < a {
                a = v;
            }
        }
        b[slot] = a;
        c[slot] = st.inv_h2[k];
        hs[slot] = st.h[k];
        ks[slot] = k;
    }
    // Stable sort by `b` (as `solve_terms`): unknown axes (+inf) go last,
    // the known ones keep their axis order among equal values.
    let mut swap_if_less = |x: usize, y: usize| {
        if b[y] < b[x] {
            b.swap(x, y);
            c.swap(x, y);
            hs.swap(x, y);
            ks.swap(x, y);
        }
    };
    swap_if_less(0, 1);
    swap_if_less(1, 2);
    swap_if_less(0, 1);
    let b0 = b[0];
    if b0 == f64::INFINITY {
        return None;
    }
    let w2 = w * w;
    // The root with the first term alone, `√(c² W²) / c²` (what
    // `solve_terms` computes at its first step).
    let r0 = one_axis(ks[0]);
    // The root of the causal leading terms: a term is added while the
    // root without it lies above its `b` (as `solve_terms`).
    let root = if b[1] == f64::INFINITY {
        Some(r0)
    } else if b[2] == f64::INFINITY {
        // Two terms: the two-term root is computed alongside `r0` (two
        // independent chains), then the causal one is kept.
        let d = b[1] - b0;
        let sa = c[0] + c[1];
        let sb = c[1] * d;
        let sc = c[1] * d * d;
        let disc = sb * sb - sa * (sc - w2);
        let v2 = (sb + disc.sqrt()) / sa;
        if r0 <= d {
            Some(r0)
        } else if disc.is_nan() || disc < 0.0 {
            None
        } else {
            Some(v2)
        }
    } else if r0 <= b[1] - b0 {
        Some(r0)
    } else {
        // Three terms: add the second, then the third if the root of two
        // is not causal.
        let d1 = b[1] - b0;
        let mut sa = c[0] + c[1];
        let mut sb = c[1] * d1;
        let mut sc = c[1] * d1 * d1;
        let disc = sb * sb - sa * (sc - w2);
        if disc.is_nan() || disc < 0.0 {
            None
        } else {
            let v = (sb + disc.sqrt()) / sa;
            if v <= b[2] - b0 {
                Some(v)
            } else {
                let d2 = b[2] - b0;
                sa += c[2];
                sb += c[2] * d2;
                sc += c[2] * d2 * d2;
                let disc = sb * sb - sa * (sc - w2);
                if disc.is_nan() || disc < 0.0 {
                    None
                } else {
                    Some((sb + disc.sqrt()) / sa)
                }
            }
        }
    };
    if let Some(v) = root {
        let v = b0 + v;
        if v.is_finite() && v >= b0 {
            return Some(v);
        }
    }
    // Only reached through overflow or rounding: the one-axis update.
    let v = (0..3)
        .filter(|&m| b[m] < f64::INFINITY)
        .map(|m| b[m] + w * hs[m])
        .min_by(|x, y| x.total_cmp(y))?;
    v.is_finite().then_some(v)
}

/// [`update`] for one source (labels do not matter) with the second-order
/// scheme, factoring or both: the same value with the same arithmetic, in
/// fixed axis slots as [`first_order`] (a missing axis is a slot with
/// `a_1 = +inf`), so that no loop has a data-dependent length except the
/// causal one of the quadratic. `point` is the source when factoring is on,
/// `cost_at` the cost field (for [`cap`]).
///
/// A neighbour is known exactly when its value in `u` is finite. Returns the
/// new value of cell `i`, or `None` if no neighbour is known or the value
/// would not be finite. Never returns NaN.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn one_source<const A: usize>(
    st: &Stencil,
    i: usize,
    idx: [usize; 3],
    w: f64,
    u: &[f64],
    second: bool,
    point: Option<FactorPoint>,
    cost_at: impl Fn(usize) -> f64,
) -> Option<f64> {
    let axes = st.axes_as::<A>();
    let mut sl = Slots {
        a1: [f64::INFINITY; 3],
        j1: [i; 3],
        sigma: [0.0; 3],
        a2: [f64::INFINITY; 3],
        k: [0; 3],
    };
    let mut any2 = false;
    for (slot, &k) in axes.iter().enumerate() {
        let s = st.strides[k];
        sl.k[slot] = k;
        // `<` is false for NaN and +inf: unknown neighbours drop out.
        if idx[k] > 0 && u[i - s] < f64::INFINITY {
            sl.a1[slot] = u[i - s];
            sl.j1[slot] = i - s;
            sl.sigma[slot] = -1.0;
        }
        if idx[k] + 1 < st.shape[k] && u[i + s] < sl.a1[slot] {
            sl.a1[slot] = u[i + s];
            sl.j1[slot] = i + s;
            sl.sigma[slot] = 1.0;
        }
        if second && sl.a1[slot] < f64::INFINITY {
            let j = sl.j1[slot];
            let j2 = if sl.sigma[slot] < 0.0 {
                (idx[k] >= 2).then(|| j - s)
            } else {
                (idx[k] + 2 < st.shape[k]).then(|| j + s)
            };
            if let Some(j2) = j2 {
                if u[j2] < sl.a1[slot] {
                    sl.a2[slot] = u[j2];
                    any2 = true;
                }
            }
        }
    }
    if sl.a1.iter().all(|&a| a == f64::INFINITY) {
        return None;
    }
    let w2 = w * w;
    let cap = |v: f64| {
        let mut best = v;
        for slot in 0..axes.len() {
            let (a, h) = (sl.a1[slot], st.h[sl.k[slot]]);
            if a < f64::INFINITY {
                best = cap_step(best, a, h, w, || cost_at(sl.j1[slot]));
            }
        }
        best
    };

    // The factored or second-order value, capped (one call site, so that
    // the cap is inlined); the first-order value returns directly.
    let v = 'capped: {
        if let Some(p) = point {
            if let Some(v) = factored_slots::<A>(st, idx, w2, &sl, axes.len(), u, p) {
                break 'capped v;
            }
        }
        if any2 {
            let mut b = [f64::INFINITY; 3];
            let mut c = [0.0f64; 3];
            for slot in 0..3 {
                let k = sl.k[slot];
                if sl.a2[slot] < f64::INFINITY {
                    b[slot] = (4.0 * sl.a1[slot] - sl.a2[slot]) / 3.0;
                    c[slot] = st.inv_h2_second[k];
                } else if sl.a1[slot] < f64::INFINITY {
                    b[slot] = sl.a1[slot];
                    c[slot] = st.inv_h2[k];
                }
            }
            if let Some((v, m, a)) = solve_slots::<A>(b, c, sl.a1, w2) {
                if v.is_finite() && a[..m].iter().all(|&a| v >= a) {
                    break 'capped v;
                }
            }
        }
        return first_order_slots::<A>(st, w, w2, &sl);
    };
    Some(cap(v))
}

/// The first-order end of [`one_source`] (its value needs no cap).
#[inline(always)]
fn first_order_slots<const A: usize>(st: &Stencil, w: f64, w2: f64, sl: &Slots) -> Option<f64> {
    let mut b = [f64::INFINITY; 3];
    let mut c = [0.0f64; 3];
    for slot in 0..3 {
        b[slot] = sl.a1[slot];
        c[slot] = if sl.a1[slot] < f64::INFINITY {
            st.inv_h2[sl.k[slot]]
        } else {
            0.0
        };
    }
    if let Some((v, _, a)) = solve_slots::<A>(b, c, sl.a1, w2) {
        if v.is_finite() && v >= a[0] {
            return Some(v);
        }
    }
    // Only reached through overflow or rounding: the one-axis update.
    let v = (0..3)
        .filter(|&m| sl.a1[m] < f64::INFINITY)
        .map(|m| sl.a1[m] + w * st.h[sl.k[m]])
        .min_by(|x, y| x.total_cmp(y))?;
    v.is_finite().then_some(v)
}

/// [`first_order`] and [`one_source`] without factoring at a cell whose only
/// known neighbour, of value `a1` along axis `k`, is frozen: the same bits
/// without reading the other neighbours. `a2` is the value of the cell
/// after that neighbour (any value: it is used when `second` and
/// `a2 < a1`), `one_axis` the first-order root of axis `k`
/// ([`one_axis_root`]) and `cost_j1` the cost of the neighbour (for
/// [`cap`]). Fast marching meets such a cell at every first visit.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn one_neighbour(
    st: &Stencil,
    k: usize,
    w: f64,
    a1: f64,
    a2: f64,
    second: bool,
    one_axis: f64,
    cost_j1: impl Fn() -> f64,
) -> Option<f64> {
    let h = st.h[k];
    if second && a2 < a1 {
        // The one-term quadratic as `solve_slots` computes it:
        // `disc = 0² − c² (0 − W²) = c² W²`, root `√disc / c²`.
        let c = st.inv_h2_second[k];
        let disc = c * (w * w);
        if !(disc.is_nan() || disc < 0.0) {
            let v = (4.0 * a1 - a2) / 3.0 + disc.sqrt() / c;
            if v.is_finite() && v >= a1 {
                return Some(cap_step(v, a1, h, w, cost_j1));
            }
        }
    }
    let v = a1 + one_axis;
    if v.is_finite() && v >= a1 {
        return Some(v);
    }
    // Only reached through overflow: the one-axis update.
    let v = a1 + w * h;
    v.is_finite().then_some(v)
}

/// [`one_source`] at a cell `jdx` whose only known neighbour, of value
/// `a1` along axis `k` on side `sigma` (`±1.0`), is frozen: `a2` is the
/// value of the cell after it, `one_axis` the first-order root of axis `k`
/// and `cost_j1` the neighbour's cost (see [`one_neighbour`]). `None` when
/// another axis of the cell lies within half a cell of the factoring
/// source, where the strip rule reads the other neighbours: the caller then
/// runs the full update.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn one_source_first<const A: usize>(
    st: &Stencil,
    jdx: [usize; 3],
    k: usize,
    sigma: f64,
    w: f64,
    a1: f64,
    a2: f64,
    second: bool,
    point: Option<FactorPoint>,
    one_axis: f64,
    cost_j1: impl Fn() -> f64,
) -> Option<Option<f64>> {
    if let Some(fp) = point {
        let near = |m: usize| m != k && (jdx[m] as f64 - fp.p[m]).abs() <= 0.5 + 1e-9;
        if st.axes_as::<A>().iter().any(|&m| near(m)) {
            return None;
        }
        let f = one_neighbour_factored(st, jdx, k, sigma, w, a1, a2, second, fp, &cost_j1);
        if f.is_some() {
            return Some(f);
        }
    }
    Some(one_neighbour(st, k, w, a1, a2, second, one_axis, cost_j1))
}

/// The factored value of [`one_source`] at a cell `jdx` whose only known
/// neighbour, of value `a1` along axis `k` on side `sigma` (`±1.0`), is
/// frozen (see [`one_neighbour`]), capped; `None` where `one_source` falls
/// back to the unfactored update. The caller must have checked that no
/// other axis of the cell is within half a cell of the source (the strip
/// rule would read the other neighbours).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn one_neighbour_factored(
    st: &Stencil,
    jdx: [usize; 3],
    k: usize,
    sigma: f64,
    w: f64,
    a1: f64,
    a2: f64,
    second: bool,
    fp: FactorPoint,
    cost_j1: impl Fn() -> f64,
) -> Option<f64> {
    let rhs = w * w;
    if rhs.is_nan() || rhs <= 0.0 {
        return None;
    }
    let cone = Cone::at(st, jdx, fp)?;
    let h = st.h[k];
    let (b, c) = cone.term(st, k, sigma, a1, (second && a2 < a1).then_some(a2));
    // The one-term quadratic as `solve_slots` computes it.
    let disc = c * rhs;
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    let v = b + disc.sqrt() / c;
    (v.is_finite() && v >= a1).then(|| cap_step(v, a1, h, w, cost_j1))
}

/// Per-axis upwind data of [`one_source`], in fixed slots.
struct Slots {
    /// Smaller known neighbour value (`+inf`: no known neighbour).
    a1: [f64; 3],
    /// Its index.
    j1: [usize; 3],
    /// `±1.0`: the side of that neighbour.
    sigma: [f64; 3],
    /// Second neighbour value (`+inf` when the second-order stencil is missing).
    a2: [f64; 3],
    /// The axis of the slot.
    k: [usize; 3],
}

/// [`factored`] on fixed slots (`n` of them are axes), for [`one_source`].
#[inline(always)]
fn factored_slots<const A: usize>(
    st: &Stencil,
    idx: [usize; 3],
    w2: f64,
    sl: &Slots,
    n: usize,
    u: &[f64],
    fp: FactorPoint,
) -> Option<f64> {
    let cone = Cone::at(st, idx, fp)?;
    let mut rhs = w2;
    for slot in 0..n {
        let k = sl.k[slot];
        if sl.a1[slot] == f64::INFINITY && (idx[k] as f64 - fp.p[k]).abs() <= 0.5 + 1e-9 {
            let dv = strip_dv(st, idx, sl, n, u, k, cone.d, fp.w);
            let gk = cone.grad(k);
            rhs -= (gk + dv) * (gk + dv);
        }
    }
    if rhs.is_nan() || rhs <= 0.0 {
        return None;
    }
    let mut b = [f64::INFINITY; 3];
    let mut c = [0.0f64; 3];
    for slot in 0..3 {
        let a1 = sl.a1[slot];
        if a1 < f64::INFINITY {
            let a2 = sl.a2[slot];
            let k = sl.k[slot];
            let sigma = sl.sigma[slot];
            (b[slot], c[slot]) = cone.term(st, k, sigma, a1, (a2 < f64::INFINITY).then_some(a2));
        }
    }
    let (v, m, a) = solve_slots::<A>(b, c, sl.a1, rhs)?;
    let lowest = a[..m].iter().copied().fold(f64::INFINITY, f64::min);
    (v.is_finite() && v >= lowest).then_some(v)
}

/// [`Strip::dv`] for [`one_source`] (rare: only on the grid lines through
/// the source, so it is kept out of line).
#[allow(clippy::too_many_arguments)]
#[inline(never)]
#[cold]
fn strip_dv(
    st: &Stencil,
    idx: [usize; 3],
    sl: &Slots,
    n: usize,
    u: &[f64],
    k: usize,
    d: [f64; 3],
    wp: f64,
) -> f64 {
    let mut ax = [Axis::default(); 3];
    let mut m = 0;
    for slot in 0..n {
        if sl.a1[slot] < f64::INFINITY {
            ax[m] = Axis {
                k: sl.k[slot],
                a1: sl.a1[slot],
                j1: sl.j1[slot],
                sigma: sl.sigma[slot],
                a2: sl.a2[slot],
            };
            m += 1;
        }
    }
    let known = |x: usize| u[x] < f64::INFINITY;
    let strip = Strip {
        missing: &[],
        u,
        known: &known,
    };
    strip.dv(st, idx, &ax[..m], k, d, wp, 0, &OneSource)
}

/// `solve_terms` on fixed slots (a missing term has `b = +inf`): sorts the
/// slots by `b` (stably, with `a`, the upwind values) and returns the root,
/// the number of active terms and the sorted `a`. With `A = 2` the third
/// slot is known to be empty and is left out.
#[inline(always)]
fn solve_slots<const A: usize>(
    mut b: [f64; 3],
    mut c: [f64; 3],
    mut a: [f64; 3],
    rhs: f64,
) -> Option<(f64, usize, [f64; 3])> {
    let mut swap_if_less = |x: usize, y: usize| {
        if b[y] < b[x] {
            b.swap(x, y);
            c.swap(x, y);
            a.swap(x, y);
        }
    };
    swap_if_less(0, 1);
    if A != 2 {
        swap_if_less(1, 2);
        swap_if_less(0, 1);
    }
    // The sums of `solve_terms`, term by term. The roots with one and two
    // terms are computed before either is tested (two independent chains
    // of a square root and a division, instead of one after the other),
    // then the causal one is kept.
    let b0 = b[0];
    let root = |sa: f64, sb: f64, sc: f64| {
        let disc = sb * sb - sa * (sc - rhs);
        (!(disc.is_nan() || disc < 0.0)).then(|| (sb + disc.sqrt()) / sa)
    };
    let (mut sa, mut sb, mut sc) = (0.0, 0.0, 0.0);
    let d = b[0] - b0;
    sa += c[0];
    sb += c[0] * d;
    sc += c[0] * d * d;
    let v0 = root(sa, sb, sc);
    let d1 = b[1] - b0;
    sa += c[1];
    sb += c[1] * d1;
    sc += c[1] * d1 * d1;
    let v1 = root(sa, sb, sc);
    let v = v0?;
    if v <= d1 {
        return Some((b0 + v, 1, a));
    }
    let v = v1?;
    if A == 2 {
        return Some((b0 + v, 2, a));
    }
    let d2 = b[2] - b0;
    if v <= d2 {
        return Some((b0 + v, 2, a));
    }
    sa += c[2];
    sb += c[2] * d2;
    sc += c[2] * d2 * d2;
    root(sa, sb, sc).map(|v| (b0 + v, 3, a))
}

/// The first-order root with one axis, `√(c_k² W²) / c_k²` with
/// `c_k² = 1/h_k²` (as [`first_order`] and `solve_terms` compute it).
#[inline(always)]
pub(crate) fn one_axis_root(st: &Stencil, k: usize, w: f64) -> f64 {
    let c2 = st.inv_h2[k];
    (c2 * (w * w)).sqrt() / c2
}

/// Caps a second-order or factored value at the cost of one straight step
/// to an upwind neighbour, `a_k + h_k max(W(x), W(x + σ e_k))` (the
/// larger end cost bounds the step's true cost to `O(h³)`). First-order
/// unfactored values satisfy it already; the others can overshoot it where
/// the cost is rough, which would break `U(x) ≤ U(y) + max W |x − y|`.
#[inline(always)]
fn cap<L: Labels + ?Sized>(
    st: &Stencil,
    ax: &[Axis],
    w: f64,
    cost: &IsotropicCost<'_>,
    r: (f64, i32),
    labels: &L,
) -> (f64, i32) {
    let mut best = r;
    for a in ax {
        let v = cap_step(best.0, a.a1, st.h[a.k], w, || cost.at(a.j1));
        if v < best.0 {
            best = (v, labels.at(a.j1));
        }
    }
    best
}

/// `v` capped by the straight step from one upwind neighbour of value `a1`
/// along an axis of spacing `h`: `a1 + h max(W(x), W(neighbour))` (see
/// [`cap`]); the neighbour's cost is read only when the step can bind.
#[inline(always)]
fn cap_step(v: f64, a1: f64, h: f64, w: f64, cost_j1: impl FnOnce() -> f64) -> f64 {
    if a1 + w * h < v {
        let bound = a1 + h * w.max(cost_j1());
        if bound < v {
            return bound;
        }
    }
    v
}

#[inline(always)]
fn first_term(st: &Stencil, a: &Axis) -> Term {
    Term {
        b: a.a1,
        c2: st.inv_h2[a.k],
        a1: a.a1,
        j1: a.j1,
    }
}

/// The label of the active term with the smallest upwind value.
#[inline(always)]
fn label_of<L: Labels + ?Sized>(t: &[Term], labels: &L) -> i32 {
    let mut best = &t[0];
    for x in &t[1..] {
        if x.a1 < best.a1 {
            best = x;
        }
    }
    labels.at(best.j1)
}

/// The cone `U_0 = W_p |x − p|_h` of a factoring source seen from a cell `x`.
#[derive(Debug, Clone, Copy)]
struct Cone {
    /// `x − p` in physical units.
    d: [f64; 3],
    /// `|x − p|_h²` and `|x − p|_h`.
    r2: f64,
    r: f64,
    /// `U_0(x)`.
    u0: f64,
    /// `W_p`.
    wp: f64,
}

impl Cone {
    /// The cone of `fp` at cell `idx`; `None` at the source itself.
    #[inline(always)]
    fn at(st: &Stencil, idx: [usize; 3], fp: FactorPoint) -> Option<Self> {
        let mut d = [0.0; 3];
        let mut r2 = 0.0;
        for k in 0..3 {
            d[k] = (idx[k] as f64 - fp.p[k]) * st.h[k];
            r2 += d[k] * d[k];
        }
        if r2 <= 0.0 {
            return None;
        }
        let r = r2.sqrt();
        Some(Self {
            d,
            r2,
            r,
            u0: fp.w * r,
            wp: fp.w,
        })
    }

    /// `∂_k U_0(x) = W_p (x_k − p_k) h_k / |x − p|_h` (physical
    /// derivative); computed only for the axes that use it (a division each).
    #[inline(always)]
    fn grad(&self, k: usize) -> f64 {
        self.wp * self.d[k] / self.r
    }

    /// The factored term `(b_k, c_k²)` of axis `k` whose upwind neighbour
    /// `x + σ e_k` has value `a1`, and `x + 2σ e_k` value `a2` (second
    /// order when given): the one-sided difference of `V = U − U_0` plus
    /// `σ ∂_k U_0(x)`.
    #[inline(always)]
    fn term(&self, st: &Stencil, k: usize, sigma: f64, a1: f64, a2: Option<f64>) -> (f64, f64) {
        let h = st.h[k];
        let sh = sigma * h;
        let (d, r2, wp) = (self.d[k], self.r2, self.wp);
        // U_0 at x + σ e_k and x + 2σ e_k.
        let v1 = a1 - wp * (r2 + 2.0 * sh * d + h * h).sqrt();
        match a2 {
            Some(a2) => {
                let v2 = a2 - wp * (r2 + 4.0 * sh * d + 4.0 * h * h).sqrt();
                let b = (4.0 * v1 - v2) / 3.0 + self.u0 + (2.0 / 3.0) * sh * self.grad(k);
                (b, st.inv_h2_second[k])
            }
            None => (v1 + self.u0 + sh * self.grad(k), st.inv_h2[k]),
        }
    }
}

/// The factored update (see the module documentation), or `None` to fall back.
#[inline(always)]
fn factored<K: Fn(usize) -> bool, L: Labels + ?Sized>(
    st: &Stencil,
    idx: [usize; 3],
    w2: f64,
    ax: &[Axis],
    strip: &Strip<'_, K>,
    labels: &L,
    f: &Factor,
) -> Option<(f64, i32)> {
    let label = labels.at(ax[0].j1);
    if ax[1..].iter().any(|a| labels.at(a.j1) != label) {
        return None;
    }
    let fp = f.point(label)?;
    let cone = Cone::at(st, idx, fp)?;
    let mut rhs = w2;
    for &k in strip.missing {
        if (idx[k] as f64 - fp.p[k]).abs() <= 0.5 + 1e-9 {
            let dv = strip.dv(st, idx, ax, k, cone.d, fp.w, label, labels);
            let gk = cone.grad(k);
            rhs -= (gk + dv) * (gk + dv);
        }
    }
    if rhs.is_nan() || rhs <= 0.0 {
        return None;
    }
    let mut t = [Term::default(); 3];
    for (t, a) in t.iter_mut().zip(ax) {
        let a2 = (a.a2 < f64::INFINITY).then_some(a.a2);
        let (b, c2) = cone.term(st, a.k, a.sigma, a.a1, a2);
        *t = Term {
            b,
            c2,
            a1: a.a1,
            j1: a.j1,
        };
    }
    let n = ax.len();
    let (v, m) = solve_terms(&mut t[..n], rhs)?;
    let active = &t[..m];
    let lowest = active.iter().map(|t| t.a1).fold(f64::INFINITY, f64::min);
    (v.is_finite() && v >= lowest).then(|| (v, label_of(active, labels)))
}

/// What the strip rule needs to estimate `∂_k V` at a cell with no known
/// neighbour along axis `k`.
struct Strip<'a, K> {
    missing: &'a [usize],
    u: &'a [f64],
    known: &'a K,
}

impl<K: Fn(usize) -> bool> Strip<'_, K> {
    /// `∂_k V(x)`, estimated by the centred difference of `V` along `k` at
    /// the most upwind neighbour `y` of `x` (an `O(h)` estimate at `x`),
    /// or 0 when `y ± e_k` are not both known with the same label.
    ///
    /// Zero would be exact for a constant cost but makes an `O(h^1.5)` error
    /// where the rays bend (the strip then reaches `~√(h R)` from the source,
    /// `R` the rays' radius of curvature).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn dv<L: Labels + ?Sized>(
        &self,
        st: &Stencil,
        idx: [usize; 3],
        ax: &[Axis],
        k: usize,
        d: [f64; 3],
        wp: f64,
        label: i32,
        labels: &L,
    ) -> f64 {
        let Some(a) = ax.iter().min_by(|a, b| a.a1.total_cmp(&b.a1)) else {
            return 0.0;
        };
        if idx[k] == 0 || idx[k] + 1 >= st.shape[k] {
            return 0.0;
        }
        let s = st.strides[k];
        let y = a.j1;
        let (lo, hi) = (y - s, y + s);
        if !((self.known)(lo)
            && (self.known)(hi)
            && labels.at(lo) == label
            && labels.at(hi) == label)
        {
            return 0.0;
        }
        // x − p of y, then of y ∓ e_k (physical).
        let mut dy = d;
        dy[a.k] += a.sigma * st.h[a.k];
        let hk = st.h[k];
        let r_at = |delta: f64| {
            let mut q = dy;
            q[k] += delta;
            wp * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt()
        };
        let v_lo = self.u[lo] - r_at(-hk);
        let v_hi = self.u[hi] - r_at(hk);
        (v_hi - v_lo) / (2.0 * hk)
    }
}

/// Solves `Σ c2_k ((U − b_k)⁺)² = rhs` (`rhs > 0`): sorts the terms by `b`
/// and returns the root and the number of active (leading) terms.
#[inline(always)]
fn solve_terms(t: &mut [Term], rhs: f64) -> Option<(f64, usize)> {
    // Insertion sort of at most 3 terms.
    for a in 1..t.len() {
        let mut b = a;
        while b > 0 && t[b].b < t[b - 1].b {
            t.swap(b, b - 1);
            b -= 1;
        }
    }
    let b0 = t[0].b;
    let (mut sa, mut sb, mut sc) = (0.0, 0.0, 0.0);
    for m in 0..t.len() {
        let c2 = t[m].c2;
        let d = t[m].b - b0;
        sa += c2;
        sb += c2 * d;
        sc += c2 * d * d;
        let disc = sb * sb - sa * (sc - rhs);
        if disc.is_nan() || disc < 0.0 {
            return None;
        }
        let v = (sb + disc.sqrt()) / sa;
        if m + 1 == t.len() || v <= t[m + 1].b - b0 {
            return Some((b0 + v, m + 1));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::grid::Grid;

    fn run(grid: &Grid, u: &[f64], x: [usize; 3], w: f64, second: bool) -> Option<(f64, i32)> {
        let st = Stencil::new(grid);
        let labels: Vec<i32> = (0..u.len() as i32).collect();
        update::<0, _, _>(
            &st,
            grid.linear(x),
            x,
            w,
            u,
            labels.as_slice(),
            |j| u[j].is_finite(),
            second,
            None,
            false,
            &IsotropicCost::constant(w.min(1e300)).unwrap(),
        )
    }

    #[test]
    fn one_neighbour_gives_a_plus_wh() {
        let g = Grid::new(&[3, 3], &[1.0, 0.5]).unwrap();
        let mut u = vec![f64::INFINITY; 9];
        u[g.linear([0, 1, 0])] = 2.0;
        let (v, l) = run(&g, &u, [0, 1, 1], 3.0, false).unwrap();
        assert_eq!(v, 2.0 + 1.5);
        assert_eq!(l, 3);
    }

    #[test]
    fn two_equal_neighbours_give_the_diagonal_value() {
        // (U − 0)² + (U − 0)² = 1  →  U = 1/√2.
        let g = Grid::unit(&[3, 3]).unwrap();
        let mut u = vec![f64::INFINITY; 9];
        u[g.linear([0, 0, 1])] = 0.0;
        u[g.linear([0, 1, 0])] = 0.0;
        let (v, _) = run(&g, &u, [0, 1, 1], 1.0, false).unwrap();
        assert!((v - 0.5f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn causality_drops_a_far_upwind_value() {
        // b = (0, 5): the root with the first axis alone is 1 <= 5.
        let g = Grid::unit(&[3, 3]).unwrap();
        let mut u = vec![f64::INFINITY; 9];
        u[g.linear([0, 0, 1])] = 0.0;
        u[g.linear([0, 1, 0])] = 5.0;
        let (v, l) = run(&g, &u, [0, 1, 1], 1.0, false).unwrap();
        assert_eq!(v, 1.0);
        assert_eq!(l, 1);
    }

    #[test]
    fn second_order_is_exact_on_a_linear_function() {
        // U = 2 x along axis 2 with W = 2: (3U − 4·2 + 0)/2 = 2  →  U = 4.
        let g = Grid::unit(&[1, 5]).unwrap();
        let u = vec![0.0, 2.0, f64::INFINITY, f64::INFINITY, f64::INFINITY];
        let (v, _) = run(&g, &u, [0, 0, 2], 2.0, true).unwrap();
        assert!((v - 4.0).abs() < 1e-14);
        // A missing second neighbour falls back to first order: 2 + 2.
        let u = vec![f64::INFINITY, 2.0, f64::INFINITY, f64::INFINITY, 7.0];
        let (v, _) = run(&g, &u, [0, 0, 2], 2.0, true).unwrap();
        assert_eq!(v, 4.0);
    }

    #[test]
    fn fast_unravel_matches_the_grid() {
        for shape in [[1usize, 7, 13], [5, 1, 9], [3, 4, 1], [2, 65537, 3]] {
            let g = Grid::unit(&shape).unwrap();
            let st = Stencil::new(&g);
            for i in (0..g.len()).step_by(7).chain([g.len() - 1]) {
                assert_eq!(st.unravel(i), g.unravel(i), "{shape:?} {i}");
            }
        }
        // Largest numerators and awkward divisors, against plain division.
        for d in [2usize, 3, 7, 1000, 65_535, 65_536, 65_537, 4_000_000_007] {
            let f = FastDiv::new(d);
            for x in [0usize, 1, d - 1, d, d + 1, 4_294_967_279, u32::MAX as usize] {
                assert_eq!(f.div(x), x / d, "{x} / {d}");
            }
        }
    }

    #[test]
    fn trailing_axes() {
        let t = |shape: &[usize]| Stencil::new(&Grid::unit(shape).unwrap()).trailing();
        assert_eq!(t(&[4, 5]), Some(2));
        assert_eq!(t(&[3, 4, 5]), Some(3));
        assert_eq!(t(&[1, 5]), Some(1));
        assert_eq!(t(&[5, 1, 9]), None);
        assert_eq!(t(&[5, 1]), None);
        assert_eq!(t(&[1, 1]), None);
    }

    /// A neighbour value for the kernel comparison: unknown (NaN or +inf),
    /// one of a few shared values (ties), or any value in [0, 3).
    fn neighbour() -> impl proptest::strategy::Strategy<Value = f64> {
        use proptest::prelude::*;
        prop_oneof![
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(1.0),
            Just(1.25),
            0.0f64..3.0,
        ]
    }

    proptest::proptest! {
        /// The first-order kernel of fast marching gives the very bits of
        /// the general update (first order, no factoring), whatever the
        /// known neighbours, ties, spacing and cost, with its axis loop
        /// unrolled or not.
        #[test]
        fn first_order_kernel_matches_the_general_update(
            three in proptest::bool::ANY,
            vals in proptest::collection::vec(neighbour(), 6),
            h in proptest::collection::vec(0.25f64..2.0, 3),
            w in 0.1f64..4.0,
        ) {
            let (shape, spacing): (Vec<usize>, Vec<f64>) = if three {
                (vec![3, 3, 3], h.clone())
            } else {
                (vec![3, 3], h[..2].to_vec())
            };
            let g = Grid::new(&shape, &spacing).unwrap();
            let st = Stencil::new(&g);
            let x = [usize::from(three), 1, 1];
            let i = g.linear(x);
            let mut u = vec![f64::INFINITY; g.len()];
            for (n, &k) in st.axes().iter().enumerate() {
                u[i - st.strides[k]] = vals[2 * n];
                u[i + st.strides[k]] = vals[2 * n + 1];
            }
            let general = update::<0, _, _>(
                &st,
                i,
                x,
                w,
                &u,
                &OneSource,
                |j| u[j] < f64::INFINITY,
                false,
                None,
                false,
                &IsotropicCost::constant(w).unwrap(),
            )
            .map(|r| r.0.to_bits());
            let one = |k| one_axis_root(&st, k, w);
            let unrolled = if three {
                first_order::<3>(&st, i, x, w, &u, one)
            } else {
                first_order::<2>(&st, i, x, w, &u, one)
            };
            proptest::prop_assert_eq!(unrolled.map(f64::to_bits), general);
            let generic = first_order::<0>(&st, i, x, w, &u, one);
            proptest::prop_assert_eq!(generic.map(f64::to_bits), general);
        }
    }

    /// A 5^d grid (3D if `three`, else 2D) of spacing `h`, its stencil, and
    /// its centre cell (padded index and linear index): every second
    /// neighbour of the centre exists, and so do the diagonal cells the
    /// strip rule reads.
    fn centre_of_five(three: bool, h: &[f64]) -> (Grid, Stencil, [usize; 3], usize) {
        let g = if three {
            Grid::new(&[5, 5, 5], h).unwrap()
        } else {
            Grid::new(&[5, 5], &h[..2]).unwrap()
        };
        let st = Stencil::new(&g);
        let x = [if three { 2 } else { 0 }, 2, 2];
        let i = g.linear(x);
        (g, st, x, i)
    }

    /// A cost field of double precision values.
    fn cost_field<'a>(g: &Grid, cost: &'a [f64]) -> IsotropicCost<'a> {
        use crate::numerics::metric::{CostValues, Interpretation};
        let values = CostValues::F64(std::borrow::Cow::Borrowed(cost));
        IsotropicCost::new(g, values, Interpretation::Cost, None).unwrap()
    }

    /// Padded coordinates from one coordinate per axis of length > 1.
    fn on_axes(st: &Stencil, p: &[f64]) -> [f64; 3] {
        let mut q = [0.0; 3];
        for (n, &k) in st.axes().iter().enumerate() {
            q[k] = p[n];
        }
        q
    }

    /// A coordinate of the source for the kernel comparison: on the cell's
    /// grid line, half a cell off it, or anywhere near it.
    fn source_coordinate() -> impl proptest::strategy::Strategy<Value = f64> {
        use proptest::prelude::*;
        prop_oneof![Just(2.0), Just(1.5), -1.0f64..5.0]
    }

    proptest::proptest! {
        /// The one-source kernel of fast marching gives the very bits of
        /// the general update with one source, whatever the known
        /// neighbours (second neighbours included), ties, spacing, costs
        /// around the cell (the cap reads them), order and factoring (the
        /// source is put near the cell, so that the strip rule of missing
        /// axes is exercised too), with its axis loop unrolled or not.
        #[test]
        fn one_source_kernel_matches_the_general_update(
            three in proptest::bool::ANY,
            second in proptest::bool::ANY,
            factoring in proptest::bool::ANY,
            vals in proptest::collection::vec(neighbour(), 125),
            costs in proptest::collection::vec(0.1f64..4.0, 125),
            h in proptest::collection::vec(0.25f64..2.0, 3),
            p in proptest::collection::vec(source_coordinate(), 3),
            wp in 0.1f64..4.0,
        ) {
            let (g, st, x, i) = centre_of_five(three, &h);
            let mut u = vals[..g.len()].to_vec();
            u[i] = f64::NAN;
            let cost = &costs[..g.len()];
            let w = cost[i];
            let field = cost_field(&g, cost);
            let point = FactorPoint { p: on_axes(&st, &p), w: wp };
            let factor = Factor { points: vec![Some(point)] };
            let general = update::<0, _, _>(
                &st,
                i,
                x,
                w,
                &u,
                &OneSource,
                |j| u[j] < f64::INFINITY,
                second,
                factoring.then_some(&factor),
                false,
                &field,
            )
            .map(|r| r.0.to_bits());
            let point = factoring.then_some(point);
            let at = |j| field.at(j);
            let unrolled = if three {
                one_source::<3>(&st, i, x, w, &u, second, point, at)
            } else {
                one_source::<2>(&st, i, x, w, &u, second, point, at)
            };
            proptest::prop_assert_eq!(unrolled.map(f64::to_bits), general);
            let generic = one_source::<0>(&st, i, x, w, &u, second, point, at);
            proptest::prop_assert_eq!(generic.map(f64::to_bits), general);
        }
    }

    proptest::proptest! {
        /// At a first visit (one known neighbour) the shortcut of fast
        /// marching gives the bits of the one-source kernel, or declines
        /// (`None`) only where the strip rule needs the other neighbours.
        #[test]
        fn first_visit_matches_the_one_source_kernel(
            three in proptest::bool::ANY,
            second in proptest::bool::ANY,
            factoring in proptest::bool::ANY,
            axis in 0usize..3,
            up in proptest::bool::ANY,
            a1 in 0.0f64..3.0,
            a2 in neighbour(),
            costs in proptest::collection::vec(0.1f64..4.0, 125),
            h in proptest::collection::vec(0.25f64..2.0, 3),
            p in proptest::collection::vec(source_coordinate(), 3),
            wp in 0.1f64..4.0,
        ) {
            let (g, st, x, i) = centre_of_five(three, &h);
            let k = st.axes()[axis % st.axes().len()];
            let s = st.strides[k];
            let (j1, beyond) = if up { (i + s, i + 2 * s) } else { (i - s, i - 2 * s) };
            let mut u = vec![f64::NAN; g.len()];
            u[j1] = a1;
            u[beyond] = a2;
            let cost = &costs[..g.len()];
            let w = cost[i];
            let field = cost_field(&g, cost);
            let q = on_axes(&st, &p);
            let point = factoring.then_some(FactorPoint { p: q, w: wp });
            let at = |j| field.at(j);
            let sigma = if up { 1.0 } else { -1.0 };
            let one = one_axis_root(&st, k, w);
            let full = one_source::<0>(&st, i, x, w, &u, second, point, at).map(f64::to_bits);
            let first = |v: Option<Option<f64>>| v.map(|v| v.map(f64::to_bits));
            let generic = one_source_first::<0>(&st, x, k, sigma, w, a1, a2, second, point, one, || cost[j1]);
            let unrolled = if three {
                one_source_first::<3>(&st, x, k, sigma, w, a1, a2, second, point, one, || cost[j1])
            } else {
                one_source_first::<2>(&st, x, k, sigma, w, a1, a2, second, point, one, || cost[j1])
            };
            proptest::prop_assert_eq!(first(generic), first(unrolled));
            // Declined only with factoring and another axis near the source.
            let near = st.axes().iter().any(|&m| m != k && (x[m] as f64 - q[m]).abs() <= 0.5 + 1e-9);
            proptest::prop_assert_eq!(generic.is_none(), factoring && near);
            if let Some(v) = first(generic) {
                proptest::prop_assert_eq!(v, full);
            }
        }
    }

    #[test]
    fn huge_costs_give_none_not_nan() {
        let g = Grid::unit(&[3, 3]).unwrap();
        let mut u = vec![f64::INFINITY; 9];
        u[g.linear([0, 0, 1])] = 1e308;
        u[g.linear([0, 1, 0])] = 1e308;
        assert_eq!(run(&g, &u, [0, 1, 1], 1e308, true), None);
        assert_eq!(run(&g, &[f64::INFINITY; 9], [0, 1, 1], 1.0, true), None);
    }
}
