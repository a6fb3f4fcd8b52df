//! Exact Euclidean distance transforms (EDT) on 2D and 3D grids with a
//! per-axis spacing: the binary transform, its feature transform, the signed
//! transform and the multi-label transform.
//!
//! # Definitions
//! With cell `x` at the physical point `(x_0 h_0, x_1 h_1[, x_2 h_2])`:
//! * binary: `D(x) = min { |x - y| : mask(y) }` (0 on the mask, `+inf`
//!   everywhere when the mask is empty), and the feature transform `F(x)`, the
//!   linear (C order) index of one cell `y` that attains the minimum;
//! * multi-label: `D(x) = min { |x - y| : L(y) != L(x) }`, the distance to
//!   the nearest cell of another label (`+inf` when the image holds one label);
//! * signed: `S(x) = D_mask(x)` outside the mask and `-D_{not mask}(x)`
//!   inside (negative inside; a two-label transform with a sign).
//!
//! # Algorithm
//! The squared distance is separable:
//! `D²(x) = min_{y_0} [ (h_0 (x_0-y_0))² + min_{y_1} [ (h_1 (x_1-y_1))² + ... ] ]`,
//! so it is computed one axis at a time (Saito–Toriwaki). The first pass of
//! the binary transform is the two-scan 1D distance of Rosenfeld–Pfaltz
//! (Meijster et al.), run over whole rows so that it reads memory in order;
//! every later pass computes, on each line, the lower envelope of the
//! parabolas `q ↦ h² (q - p)² + f(p)` in `O(n)` (Felzenszwalb–Huttenlocher
//! 2012). The multi-label transform runs the envelope on each run of equal
//! labels of a line, with the two cells that bound the run (of another label)
//! as parabolas of height 0; a cell of another label farther along the line
//! is never nearer than the one that bounds the run, which makes the pass
//! exact. The transform is exact: every value is `sqrt` of a sum of the same
//! squared axis offsets as the brute-force minimum, so the two agree to
//! rounding (the tests assert 1e-12 on random anisotropic masks).
//!
//! Cost: `O(N)` time per axis, `N` f64 (and `N` u32 for features) of memory.
//! Each pass is parallel over lines with rayon: in the caller's pool, or in a
//! pool of [`EdtOptions::threads`] threads.
//!
//! # Examples
//! ```
//! use geodex::numerics::{edt, Control, Grid};
//! let grid = Grid::new(&[1, 5], &[1.0, 0.5])?;
//! let mask = [false, false, true, false, false];
//! let out = edt::edt(&grid, &mask, &edt::EdtOptions::default(), &Control::new())?;
//! assert_eq!(out.distance, vec![1.0, 0.5, 0.0, 0.5, 1.0]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use ndarray::{ArrayViewMut2, Axis};
use rayon::prelude::*;

use super::{Control, Grid};

/// No feature: the mask is empty (binary), or the image has one label.
pub const NO_FEATURE: u32 = u32::MAX;

/// Lines gathered together by a strided pass (one 64-byte cache line of f64).
const GATHER: usize = 8;

/// Why a transform was refused or interrupted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EdtError {
    /// The mask or label image does not have one value per cell.
    #[error("the input has {got} values but the grid has {expected} cells")]
    Length {
        /// Values given.
        got: usize,
        /// Cells of the grid.
        expected: usize,
    },
    /// The thread pool could not be built.
    #[error("cannot start {threads} threads: {reason}")]
    Threads {
        /// Threads asked for.
        threads: usize,
        /// Why rayon refused.
        reason: String,
    },
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

/// Options of the transforms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EdtOptions {
    /// Also compute the feature transform. Default: false.
    pub features: bool,
    /// Run in a new pool of this many threads; `None` (the default) runs in
    /// the caller's rayon pool (the global one outside any pool).
    pub threads: Option<usize>,
}

impl EdtOptions {
    /// Defaults with the feature transform on or off.
    pub fn with_features(mut self, features: bool) -> Self {
        self.features = features;
        self
    }

    /// Defaults with a thread count.
    pub fn with_threads(mut self, threads: Option<usize>) -> Self {
        self.threads = threads;
        self
    }
}

/// A distance transform.
#[derive(Debug, Clone, PartialEq)]
pub struct EdtOutput {
    /// Distances in C order (physical units, `+inf` where there is no feature).
    pub distance: Vec<f64>,
    /// Linear index of the nearest feature cell, [`NO_FEATURE`] where none;
    /// `Some` when [`EdtOptions::features`] is set.
    pub features: Option<Vec<u32>>,
}

/// Binary transform: distance of every cell to the nearest cell where `mask`
/// is true (0 on the mask).
pub fn edt(
    grid: &Grid,
    mask: &[bool],
    options: &EdtOptions,
    control: &Control<'_>,
) -> Result<EdtOutput, EdtError> {
    check_len(grid, mask.len())?;
    in_pool(options.threads, || {
        let mut sq = squared_binary(grid, mask, options.features, control)?;
        finish(&mut sq.0, None::<(&[bool], bool)>);
        Ok(EdtOutput {
            distance: sq.0,
            features: sq.1,
        })
    })
}

/// Squared binary transform (physical units squared), for callers that
/// threshold distances and want to skip the square roots.
pub fn edt_squared(
    grid: &Grid,
    mask: &[bool],
    options: &EdtOptions,
    control: &Control<'_>,
) -> Result<EdtOutput, EdtError> {
    check_len(grid, mask.len())?;
    in_pool(options.threads, || {
        let (distance, features) = squared_binary(grid, mask, options.features, control)?;
        Ok(EdtOutput { distance, features })
    })
}

/// Signed transform: outside the mask the distance to the nearest mask cell,
/// inside minus the distance to the nearest cell outside. The feature of a
/// cell is the nearest cell on the other side.
pub fn signed_edt(
    grid: &Grid,
    mask: &[bool],
    options: &EdtOptions,
    control: &Control<'_>,
) -> Result<EdtOutput, EdtError> {
    check_len(grid, mask.len())?;
    in_pool(options.threads, || {
        let (mut d, f) = squared_multilabel(grid, mask, options.features, control)?;
        finish(&mut d, Some((mask, true)));
        Ok(EdtOutput {
            distance: d,
            features: f,
        })
    })
}

/// Multi-label transform: distance of every cell to the nearest cell whose
/// label differs from its own.
pub fn multilabel_edt<L: Copy + PartialEq + Send + Sync>(
    grid: &Grid,
    labels: &[L],
    options: &EdtOptions,
    control: &Control<'_>,
) -> Result<EdtOutput, EdtError> {
    check_len(grid, labels.len())?;
    in_pool(options.threads, || {
        let (mut d, f) = squared_multilabel(grid, labels, options.features, control)?;
        finish(&mut d, None::<(&[bool], bool)>);
        Ok(EdtOutput {
            distance: d,
            features: f,
        })
    })
}

fn check_len(grid: &Grid, got: usize) -> Result<(), EdtError> {
    if got != grid.len() {
        return Err(EdtError::Length {
            got,
            expected: grid.len(),
        });
    }
    Ok(())
}

fn in_pool<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> Result<T, EdtError> + Send,
) -> Result<T, EdtError> {
    match threads {
        None => f(),
        Some(n) => {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map_err(|e| EdtError::Threads {
                    threads: n,
                    reason: e.to_string(),
                })?;
            pool.install(f)
        }
    }
}

/// Square roots (and the sign inside `mask` for the signed transform).
fn finish(d: &mut [f64], signed: Option<(&[bool], bool)>) {
    match signed {
        None => d.par_chunks_mut(1 << 14).for_each(|c| {
            for v in c {
                *v = v.sqrt();
            }
        }),
        Some((mask, _)) => d
            .par_chunks_mut(1 << 14)
            .zip(mask.par_chunks(1 << 14))
            .for_each(|(c, m)| {
                for (v, &inside) in c.iter_mut().zip(m) {
                    let r = v.sqrt();
                    *v = if inside { -r } else { r };
                }
            }),
    }
}

/// The axes of length > 1, in order; the first one gets the row-sweep pass.
fn active_axes(shape: [usize; 3]) -> Vec<usize> {
    let axes: Vec<usize> = (0..3).filter(|&a| shape[a] > 1).collect();
    if axes.is_empty() {
        vec![2]
    } else {
        axes
    }
}

fn squared_binary(
    grid: &Grid,
    mask: &[bool],
    features: bool,
    control: &Control<'_>,
) -> Result<(Vec<f64>, Option<Vec<u32>>), EdtError> {
    let shape = grid.shape3();
    let h = grid.spacing3();
    let axes = active_axes(shape);
    let n = grid.len();
    let mut d = vec![0.0f64; n];
    let mut feat = features.then(|| vec![NO_FEATURE; n]);
    let first = axes[0];
    row_sweeps(
        shape[first],
        n / shape[first],
        h[first],
        mask,
        &mut d,
        feat.as_deref_mut(),
    );
    control.report(1.0 / axes.len() as f64);
    for (k, &axis) in axes.iter().enumerate().skip(1) {
        if control.is_cancelled() {
            return Err(EdtError::Cancelled);
        }
        envelope_pass::<bool>(
            shape,
            axis,
            h[axis],
            &mut d,
            feat.as_deref_mut(),
            None,
            control,
        );
        control.report((k + 1) as f64 / axes.len() as f64);
    }
    if control.is_cancelled() {
        return Err(EdtError::Cancelled);
    }
    Ok((d, feat))
}

fn squared_multilabel<L: Copy + PartialEq + Send + Sync>(
    grid: &Grid,
    labels: &[L],
    features: bool,
    control: &Control<'_>,
) -> Result<(Vec<f64>, Option<Vec<u32>>), EdtError> {
    let shape = grid.shape3();
    let h = grid.spacing3();
    let axes = active_axes(shape);
    let n = grid.len();
    let mut d = vec![f64::INFINITY; n];
    let mut feat = features.then(|| vec![NO_FEATURE; n]);
    for (k, &axis) in axes.iter().enumerate() {
        if control.is_cancelled() {
            return Err(EdtError::Cancelled);
        }
        envelope_pass(
            shape,
            axis,
            h[axis],
            &mut d,
            feat.as_deref_mut(),
            Some(labels),
            control,
        );
        control.report((k + 1) as f64 / axes.len() as f64);
    }
    if control.is_cancelled() {
        return Err(EdtError::Cancelled);
    }
    Ok((d, feat))
}

/// First pass of the binary transform along an axis whose lines are the
/// columns of an `(rows, width)` C-order matrix: the 1D distance in cells to
/// the nearest mask cell of the column (a forward and a backward sweep over
/// whole rows), then squared and scaled by `h`. Parallel over blocks of columns.
fn row_sweeps(
    rows: usize,
    width: usize,
    h: f64,
    mask: &[bool],
    d: &mut [f64],
    feat: Option<&mut [u32]>,
) {
    let block = block_width(width);
    let Ok(mut dv) = ArrayViewMut2::from_shape((rows, width), d) else {
        return;
    };
    let sweep = |c0: usize,
                 mut dc: ndarray::ArrayViewMut2<'_, f64>,
                 mut fc: Option<ndarray::ArrayViewMut2<'_, u32>>| {
        let w = dc.ncols();
        // Forward sweep: cells to the nearest mask cell at or above.
        let mut run = vec![f64::INFINITY; w];
        let mut frun = vec![NO_FEATURE; if fc.is_some() { w } else { 0 }];
        for i in 0..rows {
            let m = &mask[i * width + c0..i * width + c0 + w];
            let mut row = dc.row_mut(i);
            for ((v, r), &inside) in row.iter_mut().zip(run.iter_mut()).zip(m) {
                *r = if inside { 0.0 } else { *r + 1.0 };
                *v = *r;
            }
            if let Some(fc) = fc.as_mut() {
                let mut frow = fc.row_mut(i);
                for (j, ((fv, fr), &inside)) in
                    frow.iter_mut().zip(frun.iter_mut()).zip(m).enumerate()
                {
                    if inside {
                        *fr = (i * width + c0 + j) as u32;
                    }
                    *fv = *fr;
                }
            }
        }
        // Backward sweep: the nearer of above and below, squared and scaled.
        run.fill(f64::INFINITY);
        for i in (0..rows).rev() {
            let mut row = dc.row_mut(i);
            match fc.as_mut() {
                None => {
                    for (v, r) in row.iter_mut().zip(run.iter_mut()) {
                        let below = *r + 1.0;
                        let c = if below < *v { below } else { *v };
                        *r = c;
                        let x = c * h;
                        *v = x * x;
                    }
                }
                Some(fc) => {
                    let mut frow = fc.row_mut(i);
                    for ((v, r), (fv, fr)) in row
                        .iter_mut()
                        .zip(run.iter_mut())
                        .zip(frow.iter_mut().zip(frun.iter_mut()))
                    {
                        let below = *r + 1.0;
                        if below < *v {
                            *r = below;
                            *fv = *fr;
                        } else {
                            *r = *v;
                            *fr = *fv;
                        }
                        let x = *r * h;
                        *v = x * x;
                    }
                }
            }
        }
    };
    match feat {
        None => {
            dv.axis_chunks_iter_mut(Axis(1), block)
                .into_par_iter()
                .enumerate()
                .for_each(|(b, dc)| sweep(b * block, dc, None));
        }
        Some(f) => {
            let Ok(mut fv) = ArrayViewMut2::from_shape((rows, width), f) else {
                return;
            };
            dv.axis_chunks_iter_mut(Axis(1), block)
                .into_par_iter()
                .zip(fv.axis_chunks_iter_mut(Axis(1), block).into_par_iter())
                .enumerate()
                .for_each(|(b, (dc, fc))| sweep(b * block, dc, Some(fc)));
        }
    }
}

/// Columns per task of the row sweeps: a few KiB per row, and enough tasks
/// for every thread.
fn block_width(width: usize) -> usize {
    let threads = rayon::current_num_threads().max(1);
    let by_threads = width.div_ceil(4 * threads);
    by_threads.clamp(64, 4096).min(width.max(1))
}

/// Per-task scratch space of the envelope passes.
#[derive(Default)]
struct Scratch {
    /// Site positions along the line.
    pos: Vec<u32>,
    /// Site heights `f(p)` (squared distances).
    val: Vec<f64>,
    /// Site features.
    sfeat: Vec<u32>,
    /// `f(p) / h² + p²`, the parabola's constant in the intersection formula.
    a: Vec<f64>,
    /// Envelope: site indices.
    v: Vec<u32>,
    /// Envelope: left end of each parabola's interval.
    z: Vec<f64>,
    /// Gathered lines (strided passes).
    lines: Vec<f64>,
    flines: Vec<u32>,
}

/// One pass along `axis`: replaces `f` on every line by
/// `min_p h² (q - p)² + f(p)` (per run of equal labels in the multi-label case).
fn envelope_pass<L: Copy + PartialEq + Send + Sync>(
    shape: [usize; 3],
    axis: usize,
    h: f64,
    d: &mut [f64],
    feat: Option<&mut [u32]>,
    labels: Option<&[L]>,
    control: &Control<'_>,
) {
    let n = shape[axis];
    let stride: usize = shape[axis + 1..].iter().product();
    let h2 = h * h;
    if stride == 1 {
        // Contiguous lines: in place.
        let run = |sc: &mut Scratch, li: usize, line: &mut [f64], fline: Option<&mut [u32]>| {
            if control.is_cancelled() {
                return;
            }
            let base = li * n;
            let lab = labels.map(|l| &l[base..base + n]);
            line_envelope(sc, line, fline, lab, base, 1, h2);
        };
        match feat {
            None => d
                .par_chunks_mut(n)
                .enumerate()
                .for_each_init(Scratch::default, |sc, (li, line)| run(sc, li, line, None)),
            Some(f) => d
                .par_chunks_mut(n)
                .zip(f.par_chunks_mut(n))
                .enumerate()
                .for_each_init(Scratch::default, |sc, (li, (line, fl))| {
                    run(sc, li, line, Some(fl))
                }),
        }
        return;
    }
    let block = n * stride;
    let run = |sc: &mut Scratch, bi: usize, bd: &mut [f64], mut bf: Option<&mut [u32]>| {
        let mut lines = std::mem::take(&mut sc.lines);
        let mut flines = std::mem::take(&mut sc.flines);
        let mut lab: Vec<L> = Vec::with_capacity(if labels.is_some() { n } else { 0 });
        lines.resize(GATHER * n, 0.0);
        if bf.is_some() {
            flines.resize(GATHER * n, NO_FEATURE);
        }
        for i0 in (0..stride).step_by(GATHER) {
            if control.is_cancelled() {
                break;
            }
            let w = GATHER.min(stride - i0);
            for k in 0..n {
                let row = &bd[k * stride + i0..k * stride + i0 + w];
                for (j, &v) in row.iter().enumerate() {
                    lines[j * n + k] = v;
                }
            }
            if let Some(bf) = bf.as_deref() {
                for k in 0..n {
                    let row = &bf[k * stride + i0..k * stride + i0 + w];
                    for (j, &v) in row.iter().enumerate() {
                        flines[j * n + k] = v;
                    }
                }
            }
            for j in 0..w {
                let base = bi * block + i0 + j;
                let line = &mut lines[j * n..(j + 1) * n];
                let fline = bf.is_some().then(|| &mut flines[j * n..(j + 1) * n]);
                match labels {
                    None => line_envelope::<L>(sc, line, fline, None, base, stride, h2),
                    Some(l) => {
                        lab.clear();
                        lab.extend((0..n).map(|k| l[base + k * stride]));
                        line_envelope(sc, line, fline, Some(&lab), base, stride, h2);
                    }
                }
            }
            for k in 0..n {
                let row = &mut bd[k * stride + i0..k * stride + i0 + w];
                for (j, v) in row.iter_mut().enumerate() {
                    *v = lines[j * n + k];
                }
            }
            if let Some(bf) = bf.as_deref_mut() {
                for k in 0..n {
                    let row = &mut bf[k * stride + i0..k * stride + i0 + w];
                    for (j, v) in row.iter_mut().enumerate() {
                        *v = flines[j * n + k];
                    }
                }
            }
        }
        sc.lines = lines;
        sc.flines = flines;
    };
    match feat {
        None => d
            .par_chunks_mut(block)
            .enumerate()
            .for_each_init(Scratch::default, |sc, (bi, bd)| run(sc, bi, bd, None)),
        Some(f) => d
            .par_chunks_mut(block)
            .zip(f.par_chunks_mut(block))
            .enumerate()
            .for_each_init(Scratch::default, |sc, (bi, (bd, bf))| {
                run(sc, bi, bd, Some(bf))
            }),
    }
}

/// The envelope on one line, in place. `base + k * stride` is the linear
/// index of the line's cell `k` (the feature of a run's bounding cell).
fn line_envelope<L: Copy + PartialEq>(
    sc: &mut Scratch,
    line: &mut [f64],
    mut fline: Option<&mut [u32]>,
    labels: Option<&[L]>,
    base: usize,
    stride: usize,
    h2: f64,
) {
    let n = line.len();
    match labels {
        None => {
            sc.pos.clear();
            sc.val.clear();
            sc.sfeat.clear();
            for (k, &v) in line.iter().enumerate() {
                if v.is_finite() {
                    sc.pos.push(k as u32);
                    sc.val.push(v);
                    if let Some(f) = fline.as_deref() {
                        sc.sfeat.push(f[k]);
                    }
                }
            }
            evaluate(sc, line, fline, 0, n, h2);
        }
        Some(lab) => {
            let mut s = 0;
            while s < n {
                let mut e = s + 1;
                while e < n && lab[e] == lab[s] {
                    e += 1;
                }
                sc.pos.clear();
                sc.val.clear();
                sc.sfeat.clear();
                let feats = fline.is_some();
                if s > 0 {
                    sc.pos.push((s - 1) as u32);
                    sc.val.push(0.0);
                    if feats {
                        sc.sfeat.push((base + (s - 1) * stride) as u32);
                    }
                }
                for k in s..e {
                    if line[k].is_finite() {
                        sc.pos.push(k as u32);
                        sc.val.push(line[k]);
                        if let Some(f) = fline.as_deref() {
                            sc.sfeat.push(f[k]);
                        }
                    }
                }
                if e < n {
                    sc.pos.push(e as u32);
                    sc.val.push(0.0);
                    if feats {
                        sc.sfeat.push((base + e * stride) as u32);
                    }
                }
                evaluate(sc, line, fline.as_deref_mut(), s, e, h2);
                s = e;
            }
        }
    }
}

/// Lower envelope of the parabolas of the sites in `sc` (positions
/// increasing), evaluated on `q` in `[q0, q1)` into `line` (and the winning
/// site's feature into `fline`). The value written is `f(p) + (h (q - p))²`
/// for the winning site `p`, the same sum as the brute-force distance.
fn evaluate(
    sc: &mut Scratch,
    line: &mut [f64],
    fline: Option<&mut [u32]>,
    q0: usize,
    q1: usize,
    h2: f64,
) {
    let m = sc.pos.len();
    if m == 0 {
        line[q0..q1].fill(f64::INFINITY);
        if let Some(f) = fline {
            f[q0..q1].fill(NO_FEATURE);
        }
        return;
    }
    sc.a.clear();
    sc.a.extend(sc.pos.iter().zip(&sc.val).map(|(&p, &f)| {
        let p = f64::from(p);
        f / h2 + p * p
    }));
    sc.v.clear();
    sc.z.clear();
    sc.v.push(0);
    sc.z.push(f64::NEG_INFINITY);
    for s in 1..m {
        let qs = f64::from(sc.pos[s]);
        let aq = sc.a[s];
        loop {
            let Some(&top) = sc.v.last() else {
                sc.v.push(s as u32);
                sc.z.push(f64::NEG_INFINITY);
                break;
            };
            let t = top as usize;
            let x = (aq - sc.a[t]) / (2.0 * (qs - f64::from(sc.pos[t])));
            let zt = sc.z[sc.z.len() - 1];
            if x <= zt {
                sc.v.pop();
                sc.z.pop();
            } else {
                sc.v.push(s as u32);
                sc.z.push(x);
                break;
            }
        }
    }
    let k = sc.v.len();
    let h = h2.sqrt();
    let mut j = 0;
    let mut out_f = fline;
    for q in q0..q1 {
        let qf = q as f64;
        while j + 1 < k && sc.z[j + 1] < qf {
            j += 1;
        }
        let s = sc.v[j] as usize;
        let dq = (qf - f64::from(sc.pos[s])) * h;
        line[q] = sc.val[s] + dq * dq;
        if let Some(f) = out_f.as_deref_mut() {
            f[q] = sc.sfeat[s];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(grid: &Grid, sites: impl Fn(usize, usize) -> bool) -> Vec<f64> {
        let h = grid.spacing3();
        (0..grid.len())
            .map(|i| {
                let a = grid.unravel(i);
                let mut best = f64::INFINITY;
                for j in 0..grid.len() {
                    if sites(i, j) {
                        let b = grid.unravel(j);
                        let mut s = 0.0;
                        for k in 0..3 {
                            let d = (a[k] as f64 - b[k] as f64) * h[k];
                            s += d * d;
                        }
                        best = best.min(s);
                    }
                }
                best.sqrt()
            })
            .collect()
    }

    fn dist(grid: &Grid, i: usize, j: usize) -> f64 {
        let (a, b, h) = (grid.unravel(i), grid.unravel(j), grid.spacing3());
        (0..3)
            .map(|k| ((a[k] as f64 - b[k] as f64) * h[k]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    fn case() -> impl Strategy<Value = (Vec<usize>, Vec<f64>, Vec<u8>)> {
        (2usize..=3)
            .prop_flat_map(|nd| {
                let dims = if nd == 2 { 1usize..=14 } else { 1usize..=7 };
                (
                    proptest::collection::vec(dims, nd),
                    proptest::collection::vec(0.2f64..3.0, nd),
                    0u8..=3,
                )
            })
            .prop_flat_map(|(shape, spacing, nl)| {
                let n: usize = shape.iter().product();
                let max = if nl == 0 { 1 } else { nl };
                (
                    Just(shape),
                    Just(spacing),
                    proptest::collection::vec(0u8..=max, n),
                )
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn binary_signed_and_multilabel_equal_brute_force((shape, spacing, values) in case()) {
            let grid = Grid::new(&shape, &spacing).unwrap();
            let mask: Vec<bool> = values.iter().map(|&v| v == 1).collect();
            let opts = EdtOptions::default().with_features(true);
            let c = Control::new();

            let out = edt(&grid, &mask, &opts, &c).unwrap();
            let want = brute(&grid, |_, j| mask[j]);
            let feats = out.features.unwrap();
            for i in 0..grid.len() {
                prop_assert!((out.distance[i] - want[i]).abs() <= 1e-12 || out.distance[i] == want[i],
                    "binary cell {i}: {} vs {}", out.distance[i], want[i]);
                if want[i].is_finite() {
                    let f = feats[i] as usize;
                    prop_assert!(mask[f]);
                    prop_assert!((dist(&grid, i, f) - want[i]).abs() <= 1e-12);
                } else {
                    prop_assert_eq!(feats[i], NO_FEATURE);
                }
            }

            let out = signed_edt(&grid, &mask, &opts, &c).unwrap();
            let want = brute(&grid, |i, j| mask[i] != mask[j]);
            let feats = out.features.unwrap();
            for i in 0..grid.len() {
                let w = if mask[i] { -want[i] } else { want[i] };
                prop_assert!((out.distance[i] - w).abs() <= 1e-12 || out.distance[i] == w,
                    "signed cell {i}: {} vs {}", out.distance[i], w);
                if want[i].is_finite() {
                    let f = feats[i] as usize;
                    prop_assert!(mask[f] != mask[i]);
                    prop_assert!((dist(&grid, i, f) - want[i]).abs() <= 1e-12);
                }
            }

            let out = multilabel_edt(&grid, &values, &opts, &c).unwrap();
            let want = brute(&grid, |i, j| values[i] != values[j]);
            let feats = out.features.unwrap();
            for i in 0..grid.len() {
                prop_assert!((out.distance[i] - want[i]).abs() <= 1e-12 || out.distance[i] == want[i],
                    "multilabel cell {i}: {} vs {}", out.distance[i], want[i]);
                if want[i].is_finite() {
                    let f = feats[i] as usize;
                    prop_assert!(values[f] != values[i]);
                    prop_assert!((dist(&grid, i, f) - want[i]).abs() <= 1e-12);
                } else {
                    prop_assert_eq!(feats[i], NO_FEATURE);
                }
            }
        }
    }

    #[test]
    fn threads_give_the_same_answer_and_wrong_lengths_are_refused() {
        let grid = Grid::new(&[40, 33, 21], &[1.0, 0.7, 1.3]).unwrap();
        let mask: Vec<bool> = (0..grid.len()).map(|i| (i * 7919) % 97 == 0).collect();
        let c = Control::new();
        let one = edt(
            &grid,
            &mask,
            &EdtOptions::default().with_threads(Some(1)),
            &c,
        )
        .unwrap();
        let two = edt(
            &grid,
            &mask,
            &EdtOptions::default().with_threads(Some(2)),
            &c,
        )
        .unwrap();
        assert_eq!(one, two);
        let sq = edt_squared(&grid, &mask, &EdtOptions::default(), &c).unwrap();
        for (a, b) in sq.distance.iter().zip(&one.distance) {
            assert!((a.sqrt() - b).abs() <= 1e-12);
        }
        assert_eq!(
            edt(&grid, &mask[1..], &EdtOptions::default(), &c),
            Err(EdtError::Length {
                got: grid.len() - 1,
                expected: grid.len()
            })
        );
        let flag = std::sync::atomic::AtomicBool::new(true);
        let cancelled = Control::new().with_cancel(&flag);
        assert_eq!(
            edt(&grid, &mask, &EdtOptions::default(), &cancelled),
            Err(EdtError::Cancelled)
        );
    }

    #[test]
    fn empty_mask_is_infinite_everywhere() {
        let grid = Grid::unit(&[5, 6]).unwrap();
        let out = edt(
            &grid,
            &[false; 30],
            &EdtOptions::default().with_features(true),
            &Control::new(),
        )
        .unwrap();
        assert!(out.distance.iter().all(|d| d.is_infinite()));
        assert!(out.features.unwrap().iter().all(|&f| f == NO_FEATURE));
    }
}
