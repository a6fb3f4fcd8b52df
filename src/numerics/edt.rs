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
//! 2012). The multi-label transform has the same layout: its first pass,
//! over whole rows along the outermost axis, counts the cells to the nearest
//! label change above and below (the distance to the cells that bound each
//! run of equal labels); every later pass runs the envelope on each run of
//! equal labels of a line, with the two cells that bound the run (of another
//! label) as parabolas of height 0. A cell of another label farther along the
//! line is never nearer than the one that bounds the run, which makes the
//! passes exact. In 2D no pass gathers strided lines, in 3D one does. The transform is exact: every value is `sqrt` of a sum of the same
//! squared axis offsets as the brute-force minimum, so the two agree to
//! rounding (the tests assert 1e-12 on random anisotropic masks).
//!
//! Cost: `O(N)` time per axis, `N` f64 (and `N` u32 for features) of memory.
//! Each pass is parallel over lines with rayon, in the caller's pool (the
//! one the caller is running on, the global one outside any pool): the
//! transforms start no threads of their own, so a service that runs every
//! solve on one pool keeps its thread budget. The result does not depend on
//! the number of threads (every line is computed by the same sequential
//! code).
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

use ndarray::{s, ArrayViewMut2, ArrayViewMut3, Axis};
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
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

/// Options of the transforms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EdtOptions {
    /// Also compute the feature transform. Default: false.
    pub features: bool,
}

impl EdtOptions {
    /// Defaults with the feature transform on or off.
    pub fn with_features(mut self, features: bool) -> Self {
        self.features = features;
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
/// is true (0 on the mask): `D(x) = min { |h ⊙ (x − y)| : mask(y) }`, and
/// with [`EdtOptions::features`] the cell `F(x)` that attains it.
///
/// # Examples
/// ```
/// use geodex::numerics::edt::{edt, EdtOptions};
/// use geodex::numerics::{Control, Grid};
/// let grid = Grid::new(&[3, 4], &[2.0, 1.0])?; // cells 2 high, 1 wide
/// let mask: Vec<bool> = (0..12).map(|c| c == 0).collect(); // the cell (0, 0)
/// let out = edt(&grid, &mask, &EdtOptions::default().with_features(true), &Control::new())?;
/// assert_eq!(out.distance[2 * 4 + 3], 5.0); // (2, 3): √((2·2)² + (3·1)²)
/// assert_eq!(out.features.as_deref().map(|f| f[2 * 4 + 3]), Some(0));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn edt(
    grid: &Grid,
    mask: &[bool],
    options: &EdtOptions,
    control: &Control<'_>,
) -> Result<EdtOutput, EdtError> {
    check_len(grid, mask.len())?;
    let mut sq = squared_binary(grid, mask, options.features, control)?;
    finish(&mut sq.0, None::<(&[bool], bool)>);
    Ok(EdtOutput {
        distance: sq.0,
        features: sq.1,
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
    let (distance, features) = squared_binary(grid, mask, options.features, control)?;
    Ok(EdtOutput { distance, features })
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
    let (mut d, f) = squared_multilabel(grid, mask, options.features, control)?;
    finish(&mut d, Some((mask, true)));
    Ok(EdtOutput {
        distance: d,
        features: f,
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
    let (mut d, f) = squared_multilabel(grid, labels, options.features, control)?;
    finish(&mut d, None::<(&[bool], bool)>);
    Ok(EdtOutput {
        distance: d,
        features: f,
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
    squared_by_axes::<bool>(grid, None, features, control, |rows, width, h, d, f| {
        row_sweeps(rows, width, h, mask, d, f, control)
    })
}

fn squared_multilabel<L: Copy + PartialEq + Send + Sync>(
    grid: &Grid,
    labels: &[L],
    features: bool,
    control: &Control<'_>,
) -> Result<(Vec<f64>, Option<Vec<u32>>), EdtError> {
    squared_by_axes(
        grid,
        Some(labels),
        features,
        control,
        |rows, width, h, d, f| label_row_sweeps(rows, width, h, labels, d, f, control),
    )
}

/// Rows of a first-pass sweep between two polls of the cancel flag (the
/// caller sees the flag after the pass and discards it).
const POLL_ROWS: usize = 256;

/// The squared transform, one axis at a time. The outermost axis goes
/// first, swept over whole rows by `first_pass(rows, width, h, d, features)`
/// (memory read in order, no gather; with no distance yet, its pass is a
/// 1D distance along columns); then each other axis takes the lower
/// envelope of the parabolas of the previous passes, among cells of equal
/// label when `labels` is given. Progress after each axis; cancellation
/// polled within each pass (every [`POLL_ROWS`] rows or line) and between
/// axes.
fn squared_by_axes<L: Copy + PartialEq + Send + Sync>(
    grid: &Grid,
    labels: Option<&[L]>,
    features: bool,
    control: &Control<'_>,
    first_pass: impl FnOnce(usize, usize, f64, &mut [f64], Option<&mut [u32]>),
) -> Result<(Vec<f64>, Option<Vec<u32>>), EdtError> {
    let shape = grid.shape3();
    let h = grid.spacing3();
    let axes = active_axes(shape);
    let n = grid.len();
    let mut d = vec![0.0f64; n];
    let mut feat = features.then(|| vec![NO_FEATURE; n]);
    let first = axes[0];
    first_pass(
        shape[first],
        n / shape[first],
        h[first],
        &mut d,
        feat.as_deref_mut(),
    );
    if control.is_cancelled() {
        return Err(EdtError::Cancelled);
    }
    control.report(1.0 / axes.len() as f64);
    for (k, &axis) in axes.iter().enumerate().skip(1) {
        if control.is_cancelled() {
            return Err(EdtError::Cancelled);
        }
        envelope_pass(
            shape,
            axis,
            h[axis],
            &mut d,
            feat.as_deref_mut(),
            labels,
            control,
        );
        control.report((k + 1) as f64 / axes.len() as f64);
    }
    if control.is_cancelled() {
        return Err(EdtError::Cancelled);
    }
    Ok((d, feat))
}

/// First pass of the multi-label transform along an axis whose lines are the
/// columns of an `(rows, width)` C-order matrix: on each run `[s, e)` of equal
/// labels of a column, the cell `q` gets `(h (q - b))²` for the nearer of the
/// bounding cells `b = s - 1` and `b = e` that exist (`+inf` when the column
/// holds one label; the upper one on a tie). A forward sweep counts the cells
/// since the last label change above, a backward one since the next below,
/// over whole rows (memory read in order); parallel over blocks of columns.
fn label_row_sweeps<L: Copy + PartialEq + Send + Sync>(
    rows: usize,
    width: usize,
    h: f64,
    labels: &[L],
    d: &mut [f64],
    feat: Option<&mut [u32]>,
    control: &Control<'_>,
) {
    let sweep = |c0: usize,
                 mut dc: ndarray::ArrayViewMut2<'_, f64>,
                 mut fc: Option<ndarray::ArrayViewMut2<'_, u32>>| {
        let w = dc.ncols();
        let lab = |i: usize| &labels[i * width + c0..i * width + c0 + w];
        // Forward: cells to the last cell of another label above.
        let mut run = vec![f64::INFINITY; w];
        let mut frun = vec![NO_FEATURE; if fc.is_some() { w } else { 0 }];
        dc.row_mut(0).fill(f64::INFINITY);
        for i in 1..rows {
            if i % POLL_ROWS == 0 && control.is_cancelled() {
                return;
            }
            let (m, up) = (lab(i), lab(i - 1));
            let mut row = dc.row_mut(i);
            for (((v, r), &a), &b) in row.iter_mut().zip(run.iter_mut()).zip(m).zip(up) {
                *r = if a != b { 1.0 } else { *r + 1.0 };
                *v = *r;
            }
            if let Some(fc) = fc.as_mut() {
                let mut frow = fc.row_mut(i);
                for (j, ((fv, fr), (&a, &b))) in frow
                    .iter_mut()
                    .zip(frun.iter_mut())
                    .zip(m.iter().zip(up))
                    .enumerate()
                {
                    if a != b {
                        *fr = ((i - 1) * width + c0 + j) as u32;
                    }
                    *fv = *fr;
                }
            }
        }
        if let Some(fc) = fc.as_mut() {
            fc.row_mut(0).fill(NO_FEATURE);
        }
        // Backward: the nearer of above and below, squared and scaled.
        run.fill(f64::INFINITY);
        frun.fill(NO_FEATURE);
        for i in (0..rows).rev() {
            if i % POLL_ROWS == 0 && control.is_cancelled() {
                return;
            }
            let m = lab(i);
            let down = if i + 1 < rows { lab(i + 1) } else { m };
            let mut row = dc.row_mut(i);
            match fc.as_mut() {
                None => {
                    for (((v, r), &a), &b) in row.iter_mut().zip(run.iter_mut()).zip(m).zip(down) {
                        let below = if a != b { 1.0 } else { *r + 1.0 };
                        *r = below;
                        let c = if below < *v { below } else { *v };
                        let x = c * h;
                        *v = x * x;
                    }
                }
                Some(fc) => {
                    let mut frow = fc.row_mut(i);
                    for (j, ((v, r), ((fv, fr), (&a, &b)))) in row
                        .iter_mut()
                        .zip(run.iter_mut())
                        .zip(frow.iter_mut().zip(frun.iter_mut()).zip(m.iter().zip(down)))
                        .enumerate()
                    {
                        if a != b {
                            *r = 1.0;
                            *fr = ((i + 1) * width + c0 + j) as u32;
                        } else {
                            *r += 1.0;
                        }
                        if *r < *v {
                            *v = *r;
                            *fv = *fr;
                        }
                        let x = *v * h;
                        *v = x * x;
                    }
                }
            }
        }
    };
    column_blocks(rows, width, d, feat, sweep);
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
    control: &Control<'_>,
) {
    let sweep = |c0: usize,
                 mut dc: ndarray::ArrayViewMut2<'_, f64>,
                 mut fc: Option<ndarray::ArrayViewMut2<'_, u32>>| {
        let w = dc.ncols();
        // Forward sweep: cells to the nearest mask cell at or above.
        let mut run = vec![f64::INFINITY; w];
        let mut frun = vec![NO_FEATURE; if fc.is_some() { w } else { 0 }];
        for i in 0..rows {
            if i % POLL_ROWS == 0 && control.is_cancelled() {
                return;
            }
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
            if i % POLL_ROWS == 0 && control.is_cancelled() {
                return;
            }
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
    column_blocks(rows, width, d, feat, sweep);
}

/// Runs `sweep(c0, d, f)` on the blocks of columns of the `(rows, width)`
/// C-order matrices `d` (and `feat`), `c0` being a block's first column:
/// in parallel, with blocks of [`block_width`] columns.
fn column_blocks<F>(rows: usize, width: usize, d: &mut [f64], feat: Option<&mut [u32]>, sweep: F)
where
    F: Fn(usize, ArrayViewMut2<'_, f64>, Option<ArrayViewMut2<'_, u32>>) + Sync,
{
    let block = block_width(width);
    let Ok(mut dv) = ArrayViewMut2::from_shape((rows, width), d) else {
        return;
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
struct Scratch<L> {
    env: Envelope,
    /// Gathered lines (strided passes), line `j` at `j * n..(j + 1) * n`.
    lines: Vec<f64>,
    flines: Vec<u32>,
    labs: Vec<L>,
}

impl<L> Default for Scratch<L> {
    fn default() -> Self {
        Self {
            env: Envelope::default(),
            lines: Vec::new(),
            flines: Vec::new(),
            labs: Vec::new(),
        }
    }
}

/// The lower envelope of the parabolas `q ↦ (h (q - p))² + f(p)` of a line,
/// built left to right (Felzenszwalb–Huttenlocher): a stack of sites with
/// position `p`, height `f`, feature, `a = f / h² + p²` and the left end `z`
/// of the interval where the site is lowest. The parabolas of sites `t < s`
/// meet at `x = (a_s - a_t) / (2 (p_s - p_t))`; the top site is dropped while
/// `x <= z_top`, tested as `a_s - a_t <= z_top · 2 (p_s - p_t)` (the factor is
/// positive) so that only kept sites cost a division.
#[derive(Default)]
struct Envelope {
    p: Vec<f64>,
    f: Vec<f64>,
    a: Vec<f64>,
    z: Vec<f64>,
    ft: Vec<u32>,
}

impl Envelope {
    fn clear(&mut self) {
        self.p.clear();
        self.f.clear();
        self.a.clear();
        self.z.clear();
        self.ft.clear();
    }

    /// Adds the site at `p` (greater than every site's) of height `f`.
    #[inline]
    fn push(&mut self, p: f64, f: f64, ft: u32, inv_h2: f64) {
        let a = f * inv_h2 + p * p;
        let mut z = f64::NEG_INFINITY;
        while let (Some(&pt), Some(&at), Some(&zt)) = (self.p.last(), self.a.last(), self.z.last())
        {
            let num = a - at;
            let den = 2.0 * (p - pt);
            if num <= zt * den {
                self.p.pop();
                self.f.pop();
                self.a.pop();
                self.z.pop();
                self.ft.pop();
            } else {
                z = num / den;
                break;
            }
        }
        self.p.push(p);
        self.f.push(f);
        self.a.push(a);
        self.z.push(z);
        self.ft.push(ft);
    }

    /// Writes `f(p) + (h (q - p))²` of the lowest site `p` at every `q` of
    /// `[q0, q1)` (the same sum as the brute-force distance), and its feature.
    fn write(&self, line: &mut [f64], fline: Option<&mut [u32]>, q0: usize, q1: usize, h: f64) {
        let k = self.p.len();
        if k == 0 {
            line[q0..q1].fill(f64::INFINITY);
            if let Some(f) = fline {
                f[q0..q1].fill(NO_FEATURE);
            }
            return;
        }
        let mut j = 0;
        match fline {
            None => {
                for (q, out) in line.iter_mut().enumerate().take(q1).skip(q0) {
                    let qf = q as f64;
                    while j + 1 < k && self.z[j + 1] < qf {
                        j += 1;
                    }
                    let dq = (qf - self.p[j]) * h;
                    *out = self.f[j] + dq * dq;
                }
            }
            Some(fl) => {
                for q in q0..q1 {
                    let qf = q as f64;
                    while j + 1 < k && self.z[j + 1] < qf {
                        j += 1;
                    }
                    let dq = (qf - self.p[j]) * h;
                    line[q] = self.f[j] + dq * dq;
                    fl[q] = self.ft[j];
                }
            }
        }
    }
}

/// One pass along `axis`: replaces `f` on every line by
/// `min_p h² (q - p)² + f(p)` (per run of equal labels in the multi-label case).
/// Contiguous lines are transformed in place; strided ones are gathered
/// [`GATHER`] at a time into a contiguous tile (row reads), transformed and
/// scattered back, in parallel over (outer index, column chunk).
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
    if stride == 1 {
        let run = |sc: &mut Scratch<L>, li: usize, line: &mut [f64], fline: Option<&mut [u32]>| {
            if control.is_cancelled() {
                return;
            }
            let base = li * n;
            let lab = labels.map(|l| &l[base..base + n]);
            line_envelope(&mut sc.env, line, fline, lab, base, 1, h);
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
    let outer = d.len() / (n * stride);
    let width = chunk_width(stride, outer);
    let Ok(mut dv) = ArrayViewMut3::from_shape((outer, n, stride), d) else {
        return;
    };
    // One chunk: columns `c0..c0 + w` of the `(n, stride)` plane `o`.
    let tile = |sc: &mut Scratch<L>,
                o: usize,
                c0: usize,
                mut dc: ArrayViewMut2<'_, f64>,
                mut fc: Option<ArrayViewMut2<'_, u32>>| {
        let w = dc.ncols();
        let plane = o * n * stride;
        let feats = fc.is_some();
        sc.lines.resize(GATHER * n, 0.0);
        if fc.is_some() {
            sc.flines.resize(GATHER * n, NO_FEATURE);
        }
        for t0 in (0..w).step_by(GATHER) {
            if control.is_cancelled() {
                return;
            }
            let tw = GATHER.min(w - t0);
            let mut td = dc.slice_mut(s![.., t0..t0 + tw]);
            let mut tf = fc.as_mut().map(|fc| fc.slice_mut(s![.., t0..t0 + tw]));
            for (k, row) in td.rows().into_iter().enumerate() {
                for (j, &v) in row.iter().enumerate() {
                    sc.lines[j * n + k] = v;
                }
            }
            if let Some(tf) = tf.as_ref() {
                for (k, row) in tf.rows().into_iter().enumerate() {
                    for (j, &v) in row.iter().enumerate() {
                        sc.flines[j * n + k] = v;
                    }
                }
            }
            if let Some(l) = labels {
                let b = plane + c0 + t0;
                sc.labs.clear();
                sc.labs.resize(tw * n, l[b]);
                for k in 0..n {
                    let row = &l[b + k * stride..b + k * stride + tw];
                    for (j, &v) in row.iter().enumerate() {
                        sc.labs[j * n + k] = v;
                    }
                }
            }
            for j in 0..tw {
                let base = plane + c0 + t0 + j;
                let line = &mut sc.lines[j * n..(j + 1) * n];
                let fline = feats.then(|| &mut sc.flines[j * n..(j + 1) * n]);
                let lab = labels.is_some().then(|| &sc.labs[j * n..(j + 1) * n]);
                line_envelope(&mut sc.env, line, fline, lab, base, stride, h);
            }
            for (k, mut row) in td.rows_mut().into_iter().enumerate() {
                for (j, v) in row.iter_mut().enumerate() {
                    *v = sc.lines[j * n + k];
                }
            }
            if let Some(tf) = tf.as_mut() {
                for (k, mut row) in tf.rows_mut().into_iter().enumerate() {
                    for (j, v) in row.iter_mut().enumerate() {
                        *v = sc.flines[j * n + k];
                    }
                }
            }
        }
    };
    match feat {
        None => dv
            .axis_iter_mut(Axis(0))
            .into_par_iter()
            .enumerate()
            .for_each(|(o, mut pd)| {
                pd.axis_chunks_iter_mut(Axis(1), width)
                    .into_par_iter()
                    .enumerate()
                    .for_each_init(Scratch::default, |sc, (c, dc)| {
                        tile(sc, o, c * width, dc, None)
                    })
            }),
        Some(f) => {
            let Ok(mut fv) = ArrayViewMut3::from_shape((outer, n, stride), f) else {
                return;
            };
            dv.axis_iter_mut(Axis(0))
                .into_par_iter()
                .zip(fv.axis_iter_mut(Axis(0)).into_par_iter())
                .enumerate()
                .for_each(|(o, (mut pd, mut pf))| {
                    pd.axis_chunks_iter_mut(Axis(1), width)
                        .into_par_iter()
                        .zip(pf.axis_chunks_iter_mut(Axis(1), width).into_par_iter())
                        .enumerate()
                        .for_each_init(Scratch::default, |sc, (c, (dc, fc))| {
                            tile(sc, o, c * width, dc, Some(fc))
                        })
                })
        }
    }
}

/// Columns per task of a strided pass: a multiple of [`GATHER`], with about
/// four tasks per thread over the `outer` planes together.
fn chunk_width(stride: usize, outer: usize) -> usize {
    let tasks = 4 * rayon::current_num_threads().max(1);
    let per_plane = tasks.div_ceil(outer.max(1)).max(1);
    stride.div_ceil(per_plane).div_ceil(GATHER).max(1) * GATHER
}

/// The envelope on one line, in place. `base + k * stride` is the linear
/// index of the line's cell `k` (the feature of a run's bounding cell).
fn line_envelope<L: Copy + PartialEq>(
    env: &mut Envelope,
    line: &mut [f64],
    mut fline: Option<&mut [u32]>,
    labels: Option<&[L]>,
    base: usize,
    stride: usize,
    h: f64,
) {
    let n = line.len();
    let inv_h2 = 1.0 / (h * h);
    match labels {
        None => {
            env.clear();
            match fline.as_deref() {
                None => {
                    for (k, &v) in line.iter().enumerate() {
                        if v.is_finite() {
                            env.push(k as f64, v, 0, inv_h2);
                        }
                    }
                }
                Some(f) => {
                    for (k, (&v, &ft)) in line.iter().zip(f).enumerate() {
                        if v.is_finite() {
                            env.push(k as f64, v, ft, inv_h2);
                        }
                    }
                }
            }
            env.write(line, fline, 0, n, h);
        }
        Some(lab) => {
            let mut s = 0;
            while s < n {
                let mut e = s + 1;
                while e < n && lab[e] == lab[s] {
                    e += 1;
                }
                env.clear();
                if s > 0 {
                    env.push(
                        (s - 1) as f64,
                        0.0,
                        (base + (s - 1) * stride) as u32,
                        inv_h2,
                    );
                }
                for k in s..e {
                    if line[k].is_finite() {
                        let ft = fline.as_deref().map_or(0, |f| f[k]);
                        env.push(k as f64, line[k], ft, inv_h2);
                    }
                }
                if e < n {
                    env.push(e as f64, 0.0, (base + e * stride) as u32, inv_h2);
                }
                env.write(line, fline.as_deref_mut(), s, e, h);
                s = e;
            }
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
        // The transform runs on the caller's pool: the caller picks the
        // thread count.
        let in_pool = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| edt(&grid, &mask, &EdtOptions::default(), &c))
                .unwrap()
        };
        let one = in_pool(1);
        let two = in_pool(2);
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
