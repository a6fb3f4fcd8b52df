//! Topology-preserving thinning of a 3D shape to a curve skeleton,
//! anchored on its medial cells (see [`thin_3d`]).

use super::simple_points::{cube_pos, is_simple, ADJ6, CENTRE};
use super::SkeletonError;
use crate::numerics::edt::EdtError;
use crate::numerics::Control;

/// Distance-ordered homotopic thinning of a 3D shape to a curve skeleton.
///
/// `shape` is the padded shape (grid `ps`, empty border), `anchors` its medial
/// cells, `dist` the distance to the boundary, `hmin` the smallest spacing.
/// The current set `X` starts as the shape. For the levels `L = 0, 1, 2, …`
/// (cells with `⌊dist / hmin⌋ ≤ L` may go), rounds of six directional
/// sub-iterations (`±e_0, ±e_1, ±e_2`, as in Lee–Kashyap–Chu 1994) run until a
/// round removes nothing. A sub-iteration for the direction `e`:
/// 1. takes, on `X` as it is, the exposed cells: `p ∈ X` at level `≤ L` with
///    `p + e ∉ X` and `p - e ∈ X` (material behind it, so a sheet or a curve
///    one cell thin across `e` is not pierced; a cell with no 6-neighbour in
///    `X` is exposed too);
/// 2. for each of the 8 subfields (parity classes of the coordinates) in
///    turn, removes the exposed cells of the subfield that are simple
///    ([`is_simple`], (26, 6) connectivity) and are not the end of a medial
///    curve (an anchor with exactly one 26-neighbour in `X`). No two cells of a
///    subfield are 26-adjacent, so these tests do not depend on the order of
///    the removals inside it, and removing them all at once keeps the topology.
///
/// Removing only simple points keeps the topology of the shape: as many
/// 26-components, tunnels and cavities. Peeling from the six sides in turn,
/// the shallowest cells first, with the exposure fixed before each
/// sub-iteration (peeling one layer, never two), keeps what is left centred:
/// it ends as curves through the deepest cells (closed surfaces around
/// cavities). A medial cell near the boundary (a spur of the digitised
/// surface) is reached while it is still inside thick material, with many
/// neighbours, and goes; a curve stops shrinking at an anchored end.
/// A last sequential sweep removes the simple cells that no direction exposes
/// (two curves side by side along a diagonal).
pub(super) fn thin_3d(
    shape: &[bool],
    anchors: &[bool],
    dist: &[f64],
    ps: [usize; 3],
    hmin: f64,
    control: &Control<'_>,
) -> Result<Vec<bool>, SkeletonError> {
    let mut thinning = Thinning::new(shape, anchors, dist, ps, hmin);
    let mut l = 0;
    while l < thinning.border.later.len() {
        thinning.peel_level(l, control)?;
        l += 1;
    }
    thinning.sweep(control)?;
    Ok(thinning.x)
}

/// The 3×3×3 neighbourhoods of the cells of a padded grid (whose border is
/// empty, so that every neighbour of a cell of the set is in the grid).
struct Cube {
    /// Linear offset of each of the 27 positions (see [`cube_pos`]).
    offset: [isize; 27],
    /// Linear offsets of the six face neighbours: `±e_0, ±e_1, ±e_2`.
    faces: [isize; 6],
    /// Linear strides of the grid.
    strides: [usize; 3],
    /// Shape of the grid.
    shape: [usize; 3],
}

impl Cube {
    fn new(ps: [usize; 3]) -> Self {
        let st = [ps[1] * ps[2], ps[2], 1];
        let mut offset = [0isize; 27];
        for (p, o) in offset.iter_mut().enumerate() {
            let d = cube_pos(p);
            *o = d[0] * st[0] as isize + d[1] * st[1] as isize + d[2] * st[2] as isize;
        }
        let faces = [
            st[0] as isize,
            -(st[0] as isize),
            st[1] as isize,
            -(st[1] as isize),
            1,
            -1,
        ];
        Self {
            offset,
            faces,
            strides: st,
            shape: ps,
        }
    }

    /// The neighbourhood of `c` in `x` as a 27-bit mask (centre cleared).
    fn bits(&self, x: &[bool], c: usize) -> u32 {
        let mut bits = 0u32;
        for (p, &o) in self.offset.iter().enumerate() {
            if p != CENTRE && x[c.wrapping_add_signed(o)] {
                bits |= 1 << p;
            }
        }
        bits
    }

    /// The parity class of the coordinates of `c`: one of 8 subfields, no
    /// two cells of which are 26-adjacent.
    fn subfield(&self, c: usize) -> usize {
        (c / self.strides[0] % 2) * 4
            + (c / self.strides[1] % self.shape[1] % 2) * 2
            + c % self.shape[2] % 2
    }
}

/// Whether a cell with neighbourhood `bits` may leave the set: it is simple
/// and not the end of a medial curve (an anchor with one 26-neighbour).
fn removable(bits: u32, anchor: bool) -> bool {
    !(anchor && bits.count_ones() == 1) && is_simple(bits)
}

/// The border cells of the set (those with a 6-neighbour outside it: only
/// they can be simple), by level. Each cell is listed once.
struct Border {
    /// Whether the cell has been listed (in `active` or `later`).
    listed: Vec<bool>,
    /// Listed cells at the current level or below.
    active: Vec<usize>,
    /// `later[l]`: listed cells of level `l` above the current one.
    later: Vec<Vec<usize>>,
}

impl Border {
    /// Lists `c`, of level `lc`, while the thinning is at level `current`.
    fn list(&mut self, c: usize, lc: usize, current: usize) {
        if lc <= current {
            self.listed[c] = true;
            self.active.push(c);
        } else {
            self.list_later(c, lc);
        }
    }

    /// Lists `c` in `later[lc]`, to join `active` when the thinning reaches
    /// level `lc`.
    fn list_later(&mut self, c: usize, lc: usize) {
        self.listed[c] = true;
        if self.later.len() <= lc {
            self.later.resize_with(lc + 1, Vec::new);
        }
        self.later[lc].push(c);
    }
}

/// The state of [`thin_3d`]: the current set `X` and its border.
struct Thinning<'a> {
    /// `X`.
    x: Vec<bool>,
    anchors: &'a [bool],
    dist: &'a [f64],
    hmin: f64,
    cube: Cube,
    border: Border,
    /// Scratch: the exposed cells of a sub-iteration.
    exposed: Vec<usize>,
    /// Scratch: the cells of one subfield that leave together.
    cand: Vec<usize>,
}

impl<'a> Thinning<'a> {
    /// `X` = `shape`, with its border cells listed in `later` by level
    /// (level 0 included: each level joins `active` when it is reached).
    fn new(
        shape: &[bool],
        anchors: &'a [bool],
        dist: &'a [f64],
        ps: [usize; 3],
        hmin: f64,
    ) -> Self {
        let cube = Cube::new(ps);
        let x = shape.to_vec();
        let mut t = Self {
            border: Border {
                listed: vec![false; x.len()],
                active: Vec::new(),
                later: Vec::new(),
            },
            x,
            anchors,
            dist,
            hmin,
            cube,
            exposed: Vec::new(),
            cand: Vec::new(),
        };
        for c in 0..t.x.len() {
            if t.x[c] && t.cube.faces.iter().any(|&o| !t.x[c.wrapping_add_signed(o)]) {
                let lc = t.level(c);
                t.border.list_later(c, lc);
            }
        }
        t
    }

    /// The level of cell `c`: `⌊dist / hmin⌋`.
    fn level(&self, c: usize) -> usize {
        (self.dist[c] / self.hmin) as usize
    }

    /// At level `l`: rounds of the six directional sub-iterations until a
    /// round removes nothing.
    fn peel_level(&mut self, l: usize, control: &Control<'_>) -> Result<(), SkeletonError> {
        self.border.active.append(&mut self.border.later[l]);
        loop {
            if control.is_cancelled() {
                return Err(EdtError::Cancelled.into());
            }
            let mut removed = false;
            for e in self.cube.faces {
                removed |= self.peel_direction(e, l);
            }
            let x = &self.x;
            self.border.active.retain(|&c| x[c]);
            if !removed {
                return Ok(());
            }
        }
    }

    /// One sub-iteration in the direction `e` at level `l` (step 1 and 2 of
    /// [`thin_3d`]); whether it removed a cell.
    fn peel_direction(&mut self, e: isize, l: usize) -> bool {
        // The cells exposed in the direction e, before any removal of this
        // sub-iteration.
        let (x, cube) = (&self.x, &self.cube);
        self.exposed.clear();
        self.exposed
            .extend(self.border.active.iter().copied().filter(|&c| {
                x[c] && !x[c.wrapping_add_signed(e)]
                    && (x[c.wrapping_add_signed(-e)] || cube.bits(x, c) & ADJ6[CENTRE] == 0)
            }));
        let mut removed = false;
        for sub in 0..8 {
            let (x, cube, anchors) = (&self.x, &self.cube, self.anchors);
            self.cand.clear();
            self.cand.extend(
                self.exposed
                    .iter()
                    .copied()
                    .filter(|&c| cube.subfield(c) == sub && removable(cube.bits(x, c), anchors[c])),
            );
            // No two cells of a subfield are 26-adjacent: removing one
            // changes no other's neighbourhood, so the tests above hold for
            // all of them at once.
            let cand = std::mem::take(&mut self.cand);
            for &c in &cand {
                self.remove(c, l);
                removed = true;
            }
            self.cand = cand;
        }
        removed
    }

    /// Removes `c` from `X` and lists its 6-neighbours in `X`, which are now
    /// on the border.
    fn remove(&mut self, c: usize, l: usize) {
        self.x[c] = false;
        for o in self.cube.faces {
            let y = c.wrapping_add_signed(o);
            if self.x[y] && !self.border.listed[y] {
                let ly = self.level(y);
                self.border.list(y, ly, l);
            }
        }
    }

    /// What the directional passes cannot reach: simple cells with
    /// 6-neighbours on opposite sides only across the thin set (two curves
    /// side by side along a diagonal), removed one at a time, in sweeps over
    /// the set until one removes nothing.
    fn sweep(&mut self, control: &Control<'_>) -> Result<(), SkeletonError> {
        let mut cells: Vec<usize> = (0..self.x.len()).filter(|&c| self.x[c]).collect();
        loop {
            if control.is_cancelled() {
                return Err(EdtError::Cancelled.into());
            }
            let mut removed = false;
            for &c in &cells {
                if removable(self.cube.bits(&self.x, c), self.anchors[c]) {
                    self.x[c] = false;
                    removed = true;
                }
            }
            if !removed {
                return Ok(());
            }
            let x = &self.x;
            cells.retain(|&c| x[c]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::medial_axis::medial_axis_with;
    use super::super::{medial_axis, SkeletonError, SkeletonOptions};
    use super::*;
    use crate::numerics::Grid;

    /// 26-connected components of the cells of `m` (shape `s`).
    fn components_26(m: &[bool], s: [usize; 3]) -> usize {
        let mut seen = vec![false; m.len()];
        let mut count = 0;
        for start in 0..m.len() {
            if !m[start] || seen[start] {
                continue;
            }
            count += 1;
            seen[start] = true;
            let mut stack = vec![start];
            while let Some(c) = stack.pop() {
                let p = [c / (s[1] * s[2]), (c / s[2]) % s[1], c % s[2]];
                for q in 0..27 {
                    let d = cube_pos(q);
                    let n: Option<Vec<usize>> = (0..3)
                        .map(|a| p[a].checked_add_signed(d[a]).filter(|&v| v < s[a]))
                        .collect();
                    if let Some(n) = n {
                        let n = (n[0] * s[1] + n[1]) * s[2] + n[2];
                        if m[n] && !seen[n] {
                            seen[n] = true;
                            stack.push(n);
                        }
                    }
                }
            }
        }
        count
    }

    fn solid(s: [usize; 3], inside: impl Fn(f64, f64, f64) -> bool) -> Vec<bool> {
        (0..s[0] * s[1] * s[2])
            .map(|c| {
                let (i, j, k) = (c / (s[1] * s[2]), (c / s[2]) % s[1], c % s[2]);
                inside(i as f64, j as f64, k as f64)
            })
            .collect()
    }

    #[test]
    fn three_d_cylinder_thins_to_its_axis() {
        // Cylinder of radius 6.5 around (j, k) = (10, 10), i in 2..=33.
        let s = [36usize, 21, 21];
        let mask = solid(s, |i, j, k| {
            (2.0..=33.0).contains(&i) && (j - 10.0).powi(2) + (k - 10.0).powi(2) <= 6.5 * 6.5
        });
        let grid = Grid::unit(&s).unwrap();
        let opts = SkeletonOptions::default();
        let raw = medial_axis_with(&grid, &mask, &opts, &Control::new(), false).unwrap();
        let sk = medial_axis(&grid, &mask, &opts, &Control::new()).unwrap();
        let m = &sk.mask;
        let cells: Vec<[usize; 3]> = (0..m.len())
            .filter(|&c| m[c])
            .map(|c| grid.unravel(c))
            .collect();
        let n_raw = raw.mask.iter().filter(|&&v| v).count();
        assert!(
            cells.len() * 4 < n_raw,
            "{} cells of {n_raw} medial cells",
            cells.len()
        );
        assert_eq!(components_26(m, s), 1);
        for p in &cells {
            let off = ((p[1] as f64 - 10.0).powi(2) + (p[2] as f64 - 10.0).powi(2)).sqrt();
            assert!(off <= 1.5, "{p:?} is {off} from the axis");
            assert!(mask[grid.linear(*p)]);
        }
        // A contiguous line: every section from i = 9 to 26 (the axis is
        // the medial axis between 6.5 + 0.5 cells from each cap) holds
        // one or two cells, with the radius function about 7.
        for i in 9..=26 {
            let section: Vec<&[usize; 3]> = cells.iter().filter(|p| p[0] == i).collect();
            assert!((1..=2).contains(&section.len()), "section {i}: {section:?}");
            for p in section {
                let r = sk.radius[grid.linear(*p)];
                assert!((6.0..=7.5).contains(&r), "radius {r} at {p:?}");
            }
        }
        assert!(sk.radius.iter().zip(m).all(|(&r, &k)| (r > 0.0) == k));
    }

    #[test]
    fn three_d_box_thins_and_keeps_topology() {
        // Box of 24 x 18 x 9 cells in a 28 x 22 x 13 grid.
        let s = [28usize, 22, 13];
        let (lo, hi) = ([2.0, 2.0, 2.0], [25.0, 19.0, 10.0]);
        let mask = solid(s, |i, j, k| {
            [i, j, k]
                .iter()
                .enumerate()
                .all(|(a, &v)| (lo[a]..=hi[a]).contains(&v))
        });
        let grid = Grid::unit(&s).unwrap();
        let opts = SkeletonOptions::default();
        let raw = medial_axis_with(&grid, &mask, &opts, &Control::new(), false).unwrap();
        let sk = medial_axis(&grid, &mask, &opts, &Control::new()).unwrap();
        let m = &sk.mask;
        let n = m.iter().filter(|&&v| v).count();
        let n_raw = raw.mask.iter().filter(|&&v| v).count();
        assert!(n > 0 && n * 4 < n_raw, "{n} cells of {n_raw} medial cells");
        assert_eq!(components_26(m, s), 1);
        // Thin: no 2 x 2 block of skeleton cells in any plane.
        for c in 0..m.len() {
            let p = grid.unravel(c);
            if p.iter().zip(&s).any(|(&v, &n)| v + 1 >= n) {
                continue;
            }
            for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                let mut q = p;
                let mut all = true;
                for (da, db) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    q[a] = p[a] + da;
                    q[b] = p[b] + db;
                    all &= m[grid.linear(q)];
                }
                assert!(!all, "2 x 2 block at {p:?} in axes ({a}, {b})");
            }
        }
        // The deepest cells of the box form the sheet k = 6 (between the
        // outside cells at k = 1 and 11), i in 7..=20, j in 7..=14; the
        // skeleton is a curve along the sheet's long axis j = 10.5: every
        // cell within one cell of it, one or two cells per section, and the
        // sections contiguous over the middle of the box.
        let cells: Vec<[usize; 3]> = (0..m.len())
            .filter(|&c| m[c])
            .map(|c| grid.unravel(c))
            .collect();
        for p in &cells {
            assert!(
                (p[1] as f64 - 10.5).abs() <= 1.0 && p[2] == 6,
                "{p:?} is off the axis"
            );
        }
        let lo_i = cells.iter().map(|p| p[0]).min().unwrap();
        let hi_i = cells.iter().map(|p| p[0]).max().unwrap();
        assert!(lo_i <= 12 && hi_i >= 15, "from {lo_i} to {hi_i}");
        for i in lo_i..=hi_i {
            let k = cells.iter().filter(|p| p[0] == i).count();
            assert!((1..=2).contains(&k), "section {i}: {k} cells");
        }
    }

    #[test]
    fn three_d_torus_keeps_its_tunnel() {
        // Torus of radii 9 and 3.5 around the axis 0 through (16, 16).
        let s = [12usize, 33, 33];
        let mask = solid(s, |i, j, k| {
            let rho = ((j - 16.0).powi(2) + (k - 16.0).powi(2)).sqrt();
            (rho - 9.0).powi(2) + (i - 6.0).powi(2) <= 3.5 * 3.5
        });
        let grid = Grid::unit(&s).unwrap();
        let sk = medial_axis(&grid, &mask, &SkeletonOptions::default(), &Control::new()).unwrap();
        let m = &sk.mask;
        assert_eq!(components_26(m, s), 1);
        // A closed curve around the hole: cells in each of the 8 octants of
        // angle, all within 1.5 cells of the core circle.
        let mut octants = [0usize; 8];
        for c in (0..m.len()).filter(|&c| m[c]) {
            let p = grid.unravel(c);
            let (y, z) = (p[1] as f64 - 16.0, p[2] as f64 - 16.0);
            let off = ((y.hypot(z) - 9.0).powi(2) + (p[0] as f64 - 6.0).powi(2)).sqrt();
            assert!(off <= 1.5, "{p:?} is {off} from the core circle");
            let oct = ((z.atan2(y) + std::f64::consts::PI) / (std::f64::consts::PI / 4.0)) as usize;
            octants[oct.min(7)] += 1;
        }
        assert!(octants.iter().all(|&k| k > 0), "{octants:?}");
        // Thin: a one-cell-thin digital circle of radius 9 has about 50
        // cells (the tube holds about 2200).
        let cells = m.iter().filter(|&&v| v).count();
        assert!(cells < 80, "{cells} cells");
    }

    #[test]
    fn three_d_box_axis_and_errors() {
        let grid = Grid::unit(&[12, 12, 30]).unwrap();
        let mask: Vec<bool> = (0..grid.len())
            .map(|c| {
                let p = grid.unravel(c);
                (2..10).contains(&p[0]) && (2..10).contains(&p[1]) && (2..28).contains(&p[2])
            })
            .collect();
        let sk = medial_axis(&grid, &mask, &SkeletonOptions::default(), &Control::new()).unwrap();
        // The central segment of the axis (square cross-section 8 x 8, centre 5.5).
        let on_axis = (6..24)
            .filter(|&k| (4..8).any(|i| (4..8).any(|j| sk.mask[grid.linear([i, j, k])])))
            .count();
        assert_eq!(on_axis, 18);
        assert!(sk.graph.is_none());
        let bad = SkeletonOptions {
            min_boundary_length: -1.0,
            ..SkeletonOptions::default()
        };
        assert!(matches!(
            medial_axis(&grid, &mask, &bad, &Control::new()),
            Err(SkeletonError::Option {
                field: "min_boundary_length",
                ..
            })
        ));
    }
}
