//! Per-cell adaptive stencils of the anisotropic scheme, with walls.
//!
//! For each cell `x` the dual metric in index units, `D̃ = (H M H)⁻¹` with
//! `H = diag(h)`, is decomposed by Selling's reduction ([`super::selling`])
//! into `D̃ = Σ_k ρ_k e_k e_kᵀ`; the stencil of `x` is the `2K` neighbours
//! `x ± e_k` (`K = 3` in 2D, `6` in 3D). The cost of building it grows like
//! `log κ(M)` per cell; its width like the anisotropy at worst.
//!
//! # Walls
//!
//! A neighbour `x ± e_k` is *absent* when it is outside the grid, is a wall,
//! or when the segment `[x, x ± e_k]` touches a wall cell: the segment is
//! walked through every cell whose closed box `[c − ½, c + ½]ᵈ` it meets (its
//! *supercover*, corners included), so a wide offset never jumps over a wall
//! one cell thick, not even between two diagonal wall cells. The same test
//! guards the second neighbour `x ± 2e_k` of the second-order scheme. This is
//! stricter than the digital line of HFM's `WallObstructionTest`, which can
//! cross walls (HFM issue #13).
//!
//! The fast marching loop needs the *reverse* stencils (the cells whose
//! stencil contains `y`, to update when `y` is frozen); they are stored in a
//! compressed row layout.

use super::selling::{decompose2, decompose3};
use super::tensor::TensorField;
use crate::numerics::control::Control;
use crate::numerics::grid::Grid;

/// Marks an absent neighbour.
pub const NONE: u32 = u32::MAX;

/// Why building the stencils stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cancelled;

/// The stencils of every cell and their reverse.
#[derive(Debug, Clone)]
pub struct Stencils {
    /// Offsets per cell (3 in 2D, 6 in 3D).
    pub k: usize,
    /// `ρ_k` of each cell, `n × k`.
    pub rho: Vec<f64>,
    /// Neighbours `x + e_k` and `x − e_k` of each cell, `n × k × 2`, [`NONE`] if absent.
    pub nb: Vec<u32>,
    /// Bit `2k + side` is set when the second neighbour `x ± 2e_k` is present
    /// (its linear index is `2 nb − x`).
    pub second: Vec<u16>,
    /// Start of the reverse list of each cell in `rev` (`n + 1` entries).
    pub rev_start: Vec<usize>,
    /// The cells whose stencil contains each cell.
    pub rev: Vec<u32>,
    /// Largest offset component used (cells).
    pub max_offset: i32,
    /// For cells whose stencil is incomplete (an offset with both `x ± e_k`
    /// outside the grid or behind a wall, near corners of the domain and of
    /// walls), bit `b` marks the `b`-th of the `3ᵈ − 1` immediate neighbours
    /// ([`NEIGHBOURS`]) usable by the graph fallback; 0 elsewhere.
    pub fallback: Vec<u32>,
}

/// The 26 immediate neighbour offsets (padded 3D), in a fixed order; a 2D
/// grid uses those with a zero first component.
pub const NEIGHBOURS: [[i64; 3]; 26] = {
    let mut out = [[0i64; 3]; 26];
    let mut n = 0;
    let mut a = -1i64;
    while a <= 1 {
        let mut b = -1i64;
        while b <= 1 {
            let mut c = -1i64;
            while c <= 1 {
                if !(a == 0 && b == 0 && c == 0) {
                    out[n] = [a, b, c];
                    n += 1;
                }
                c += 1;
            }
            b += 1;
        }
        a += 1;
    }
    out
};

impl Stencils {
    /// The reverse stencil of cell `y`.
    #[inline]
    pub fn reverse(&self, y: usize) -> &[u32] {
        &self.rev[self.rev_start[y]..self.rev_start[y + 1]]
    }
}

/// The dual metric in index units, `(H M H)⁻¹`, as 3 or 6 components.
pub fn dual_index_metric(m: &[f64], h: &[f64]) -> Vec<f64> {
    if m.len() == 3 {
        let (a, b, c) = (m[0] * h[0] * h[0], m[1] * h[0] * h[1], m[2] * h[1] * h[1]);
        let det = a * c - b * b;
        return vec![c / det, -b / det, a / det];
    }
    let a = [
        [m[0] * h[0] * h[0], m[1] * h[0] * h[1], m[2] * h[0] * h[2]],
        [m[1] * h[0] * h[1], m[3] * h[1] * h[1], m[4] * h[1] * h[2]],
        [m[2] * h[0] * h[2], m[4] * h[1] * h[2], m[5] * h[2] * h[2]],
    ];
    let c00 = a[1][1] * a[2][2] - a[1][2] * a[2][1];
    let c01 = a[1][2] * a[2][0] - a[1][0] * a[2][2];
    let c02 = a[1][0] * a[2][1] - a[1][1] * a[2][0];
    let det = a[0][0] * c00 + a[0][1] * c01 + a[0][2] * c02;
    let c11 = a[0][0] * a[2][2] - a[0][2] * a[2][0];
    let c12 = a[0][2] * a[1][0] - a[0][0] * a[1][2];
    let c22 = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    vec![
        c00 / det,
        c01 / det,
        c02 / det,
        c11 / det,
        c12 / det,
        c22 / det,
    ]
}

/// The weights and padded 3D offsets of one cell.
type Decomposition = [(f64, [i64; 3]); 6];

/// Offsets of one cell in padded 3D index units, with their weights.
fn decompose(ndim: usize, dual: &[f64], out: &mut [(f64, [i64; 3]); 6]) -> usize {
    if ndim == 2 {
        let dec = decompose2([dual[0], dual[1], dual[2]]);
        for (slot, (r, e)) in out.iter_mut().zip(dec) {
            *slot = (r, [0, e[0] as i64, e[1] as i64]);
        }
        3
    } else {
        let dec = decompose3([dual[0], dual[1], dual[2], dual[3], dual[4], dual[5]]);
        for (slot, (r, e)) in out.iter_mut().zip(dec) {
            *slot = (r, [e[0] as i64, e[1] as i64, e[2] as i64]);
        }
        6
    }
}

/// Builds the stencils of every non-wall cell. Polls `control` every few
/// thousand cells.
pub fn build(
    grid: &Grid,
    metric: &TensorField,
    control: &Control<'_>,
) -> Result<Stencils, Cancelled> {
    let n = grid.len();
    let ndim = grid.ndim();
    let k = if ndim == 2 { 3 } else { 6 };
    let shape = grid.shape3();
    let h = grid.spacing();
    let walls = WallIndex::new(grid, metric);
    let mut rho = vec![0.0; n * k];
    let mut nb = vec![NONE; n * 2 * k];
    let mut second = vec![0u16; n];
    let mut fallback = vec![0u32; n];
    let mut max_offset = 0i32;
    let mut cached: Option<(usize, Decomposition)> = None;
    let mut dec = [(0.0, [0i64; 3]); 6];
    for i in 0..n {
        if i % 16_384 == 0 && control.is_cancelled() {
            return Err(Cancelled);
        }
        if metric.is_wall(i) {
            continue;
        }
        let kk = if metric.is_constant() {
            match cached {
                Some((kk, d)) => {
                    dec = d;
                    kk
                }
                None => {
                    let kk = decompose(ndim, &dual_index_metric(metric.at(i), h), &mut dec);
                    cached = Some((kk, dec));
                    kk
                }
            }
        } else {
            decompose(ndim, &dual_index_metric(metric.at(i), h), &mut dec)
        };
        let x = grid.unravel(i);
        let xi = [x[0] as i64, x[1] as i64, x[2] as i64];
        let mut incomplete = false;
        for (slot, &(r, e)) in dec[..kk].iter().enumerate() {
            if r <= 0.0 {
                continue;
            }
            let mut present = false;
            rho[i * k + slot] = r;
            for (side, sign) in [(0usize, 1i64), (1, -1)] {
                let e1 = [sign * e[0], sign * e[1], sign * e[2]];
                let y = [xi[0] + e1[0], xi[1] + e1[1], xi[2] + e1[2]];
                if !inside(shape, y) {
                    continue;
                }
                let j = grid.linear([y[0] as usize, y[1] as usize, y[2] as usize]);
                if metric.is_wall(j) || !walls.clear(xi, e1) {
                    continue;
                }
                nb[(i * k + slot) * 2 + side] = j as u32;
                present = true;
                max_offset = max_offset.max(e.iter().map(|v| v.abs()).max().unwrap_or(0) as i32);
                let y2 = [y[0] + e1[0], y[1] + e1[1], y[2] + e1[2]];
                if inside(shape, y2) {
                    let j2 = grid.linear([y2[0] as usize, y2[1] as usize, y2[2] as usize]);
                    if !metric.is_wall(j2) && walls.clear(y, e1) {
                        second[i] |= 1 << (2 * slot + side);
                    }
                }
            }
            incomplete |= !present;
        }
        if incomplete {
            for (b, o) in NEIGHBOURS.iter().enumerate() {
                if ndim == 2 && o[0] != 0 {
                    continue;
                }
                let y = [xi[0] + o[0], xi[1] + o[1], xi[2] + o[2]];
                if !inside(shape, y) {
                    continue;
                }
                let j = grid.linear([y[0] as usize, y[1] as usize, y[2] as usize]);
                if !metric.is_wall(j) && walls.clear(xi, *o) {
                    fallback[i] |= 1 << b;
                }
            }
        }
    }
    // Reverse stencils (counting sort).
    let mut count = vec![0usize; n + 1];
    for &j in &nb {
        if j != NONE {
            count[j as usize + 1] += 1;
        }
    }
    let fallback_neighbour = |i: usize, b: usize| -> usize {
        let x = grid.unravel(i);
        let o = NEIGHBOURS[b];
        grid.linear([
            (x[0] as i64 + o[0]) as usize,
            (x[1] as i64 + o[1]) as usize,
            (x[2] as i64 + o[2]) as usize,
        ])
    };
    for (i, &mask) in fallback.iter().enumerate() {
        for b in (0..26).filter(|b| mask & (1 << b) != 0) {
            count[fallback_neighbour(i, b) + 1] += 1;
        }
    }
    for i in 0..n {
        count[i + 1] += count[i];
    }
    let rev_start = count.clone();
    let mut fill = count;
    let mut rev = vec![0u32; rev_start[n]];
    for (slot, &j) in nb.iter().enumerate() {
        if j != NONE {
            let i = slot / (2 * k);
            rev[fill[j as usize]] = i as u32;
            fill[j as usize] += 1;
        }
    }
    for (i, &mask) in fallback.iter().enumerate() {
        for b in (0..26).filter(|b| mask & (1 << b) != 0) {
            let j = fallback_neighbour(i, b);
            rev[fill[j]] = i as u32;
            fill[j] += 1;
        }
    }
    Ok(Stencils {
        k,
        rho,
        nb,
        second,
        rev_start,
        rev,
        max_offset,
        fallback,
    })
}

#[inline]
fn inside(shape: [usize; 3], y: [i64; 3]) -> bool {
    (0..3).all(|a| y[a] >= 0 && (y[a] as usize) < shape[a])
}

/// Walls and, for each cell, its chessboard distance to the nearest wall, so
/// that segments far from every wall are accepted without walking them.
struct WallIndex<'a> {
    grid: &'a Grid,
    metric: &'a TensorField,
    dist: Vec<u16>,
}

impl<'a> WallIndex<'a> {
    fn new(grid: &'a Grid, metric: &'a TensorField) -> Self {
        let dist = if metric.has_walls() {
            chessboard_distance(grid, metric)
        } else {
            Vec::new()
        };
        Self { grid, metric, dist }
    }

    /// True when the segment from cell `a` to `a + e` touches no wall cell
    /// (closed supercover: every cell whose closed box meets the segment).
    fn clear(&self, a: [i64; 3], e: [i64; 3]) -> bool {
        if self.dist.is_empty() {
            return true;
        }
        let reach = e.iter().map(|v| v.unsigned_abs()).max().unwrap_or(0);
        let i = self
            .grid
            .linear([a[0] as usize, a[1] as usize, a[2] as usize]);
        if (self.dist[i] as u64) > reach {
            return true;
        }
        let shape = self.grid.shape3();
        let wall = |c: [i64; 3]| -> bool {
            inside(shape, c)
                && self.metric.is_wall(self.grid.linear([
                    c[0] as usize,
                    c[1] as usize,
                    c[2] as usize,
                ]))
        };
        let len = [e[0].abs(), e[1].abs(), e[2].abs()];
        let sgn = [e[0].signum(), e[1].signum(), e[2].signum()];
        // Next crossing of axis j at t = (2 m_j + 1) / (2 len_j).
        let mut m = [0i64; 3];
        let mut cur = a;
        loop {
            // The smallest pending crossing, compared as fractions.
            let mut best: Option<(i64, i64)> = None;
            for j in 0..3 {
                if len[j] == 0 || m[j] >= len[j] {
                    continue;
                }
                let (num, den) = (2 * m[j] + 1, 2 * len[j]);
                best = match best {
                    Some((bn, bd)) if bn * den <= num * bd => Some((bn, bd)),
                    _ => Some((num, den)),
                };
            }
            let Some((bn, bd)) = best else {
                return true;
            };
            let mut group = [false; 3];
            for j in 0..3 {
                if len[j] != 0 && m[j] < len[j] && (2 * m[j] + 1) * bd == bn * 2 * len[j] {
                    group[j] = true;
                }
            }
            // Every cell around the crossing point: any subset of the crossing axes stepped.
            let axes: Vec<usize> = (0..3).filter(|&j| group[j]).collect();
            for mask in 1u32..(1 << axes.len()) {
                let mut c = cur;
                for (b, &j) in axes.iter().enumerate() {
                    if mask & (1 << b) != 0 {
                        c[j] += sgn[j];
                    }
                }
                if wall(c) {
                    return false;
                }
            }
            for &j in &axes {
                cur[j] += sgn[j];
                m[j] += 1;
            }
        }
    }
}

/// Chessboard (L∞, index units) distance of every cell to the nearest wall,
/// capped at `u16::MAX`: two chamfer passes with the 8 / 26 neighbours, exact
/// for this metric.
fn chessboard_distance(grid: &Grid, metric: &TensorField) -> Vec<u16> {
    let n = grid.len();
    let shape = grid.shape3();
    let mut d: Vec<u16> = (0..n)
        .map(|i| if metric.is_wall(i) { 0 } else { u16::MAX })
        .collect();
    let mut back: Vec<[i64; 3]> = Vec::new();
    for a in -1i64..=1 {
        for b in -1i64..=1 {
            for c in -1i64..=1 {
                let o = [a, b, c];
                if o < [0, 0, 0] {
                    back.push(o);
                }
            }
        }
    }
    let pass = |d: &mut Vec<u16>, offsets: &[[i64; 3]], order: &mut dyn Iterator<Item = usize>| {
        for i in order {
            let x = grid.unravel(i);
            let mut best = d[i];
            for o in offsets {
                let y = [x[0] as i64 + o[0], x[1] as i64 + o[1], x[2] as i64 + o[2]];
                if inside(shape, y) {
                    let j = grid.linear([y[0] as usize, y[1] as usize, y[2] as usize]);
                    best = best.min(d[j].saturating_add(1));
                }
            }
            d[i] = best;
        }
    };
    let fwd: Vec<[i64; 3]> = back.clone();
    let bwd: Vec<[i64; 3]> = back.iter().map(|o| [-o[0], -o[1], -o[2]]).collect();
    pass(&mut d, &fwd, &mut (0..n));
    pass(&mut d, &bwd, &mut (0..n).rev());
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field_with_walls(shape: &[usize], walls: &[[usize; 2]]) -> (Grid, TensorField) {
        let g = Grid::unit(shape).unwrap();
        let mut w = vec![false; g.len()];
        for c in walls {
            w[g.linear([0, c[0], c[1]])] = true;
        }
        let t = TensorField::constant(&g, &[1.0, 0.0, 1.0])
            .unwrap()
            .with_walls(&g, w)
            .unwrap();
        (g, t)
    }

    #[test]
    fn segments_do_not_cross_walls_even_diagonally() {
        let (g, t) = field_with_walls(&[8, 8], &[[3, 3], [4, 4]]);
        let w = WallIndex::new(&g, &t);
        // Between the two diagonal wall cells.
        assert!(!w.clear([0, 3, 4], [0, 1, -1]));
        // A long offset over a wall cell.
        assert!(!w.clear([0, 3, 1], [0, 0, 4]));
        assert!(!w.clear([0, 1, 1], [0, 5, 5]));
        // Far from the walls, and an axis step along a wall's side.
        assert!(w.clear([0, 0, 0], [0, 1, 2]));
        assert!(w.clear([0, 2, 2], [0, 0, 1]) && w.clear([0, 5, 0], [0, 0, 7]));
        // A knight move that passes the wall's corner at a distance.
        assert!(w.clear([0, 2, 4], [0, 1, 2]));
        assert!(!w.clear([0, 2, 2], [0, 2, 1]));
    }

    #[test]
    fn reverse_stencils_invert_the_stencils() {
        let g = Grid::unit(&[9, 7]).unwrap();
        let t = TensorField::from_eigen(&g, &[1.0, 400.0], &[1.0, 0.6]).unwrap();
        let s = build(&g, &t, &Control::new()).unwrap();
        assert!(s.max_offset >= 2);
        for y in 0..g.len() {
            for &x in s.reverse(y) {
                let x = x as usize;
                // In the stencil of x, or one of its fallback neighbours.
                let in_stencil = s.nb[x * 2 * s.k..(x + 1) * 2 * s.k].contains(&(y as u32));
                assert!(in_stencil || s.fallback[x] != 0, "{x} -> {y}");
            }
        }
    }
}
