//! Inner geodesic distances of a shape given as a mask (2D or 3D), and its
//! bending-invariant canonical form.
//!
//! The shape `Ω` is the set of the mask's `true` cells. Its inner distance
//! `d_Ω(x, y)` is the length of the shortest path from `x` to `y` that stays
//! in `Ω` (Ling and Jacobs' inner distance of articulated silhouettes; the
//! monograph's section 5.1): `U = d_Ω(x, ·)` is the viscosity solution of
//! `|∇U| = 1` in `Ω` with `U(x) = 0`, the complement of `Ω` a wall. Each
//! row is one fast-marching solve ([`crate::numerics::eikonal::solve`],
//! order 1 or 2, with the cells around the source initialised exactly), in
//! physical units (the grid's spacing).
//!
//! * **Points** are the cells of `Ω` in C order ([`MaskRows::cells`]), so a
//!   matrix column or an embedding row is a cell.
//! * **Rows** come from every cell (all pairs, small shapes) or from `k`
//!   farthest-point landmarks of `Ω`, placed by the local-front sampler
//!   ([`crate::numerics::sampling::farthest_point_sampling`]: each new
//!   landmark is the cell farthest from those already placed). The solves
//!   run in parallel on the caller's pool. The landmark block `D[i, sⱼ]` is
//!   made symmetric as [`Symmetry`] says (fast marching is not symmetric to
//!   rounding: `d(a, b)` and `d(b, a)` differ by the scheme's error).
//! * **Canonical form** ([`mask_embedding`]): classical MDS of all pairs, or
//!   landmark MDS of the rows (de Silva and Tenenbaum), centred on its
//!   principal axes. A bent shape keeps its inner distances up to the
//!   width of its joints, so its canonical form does not depend on the pose
//!   (Elad and Kimmel's construction applied to a planar or solid shape).
//! * **Pixel mesh** ([`pixel_faces`]): in 2D the cells of `Ω` are the
//!   vertices of a triangulation (two triangles per 2 × 2 block of shape
//!   cells, one per block of three), so the embedding can be returned as a
//!   mesh with the shape's own connectivity.
//!
//! A shape in several pieces (under the solver's axial neighbourhood: 4
//! neighbours in 2D, 6 in 3D) is refused: the distances between pieces are
//! infinite.

use std::borrow::Cow;
use std::collections::VecDeque;

use ndarray::Array2;

use super::graph::par_rows;
use super::matrix::{symmetrize_block, Symmetry};
use super::mds::{classical_mds, landmark_mds, principal_axes, Embedding, PairStats};
use super::ShapeError;
use crate::numerics::eikonal::{self, EikonalError, EikonalOptions, EikonalProblem, Order, Source};
use crate::numerics::metric::{CostValues, Interpretation};
use crate::numerics::sampling::{
    farthest_point_sampling, SamplingError, SamplingMethod, SamplingOptions,
};
use crate::numerics::{Control, Grid, IsotropicCost};

/// Inner-distance rows of a mask.
#[derive(Debug, Clone, PartialEq)]
pub struct MaskRows {
    /// The shape's cells (C-order linear indices), the points of the rows.
    pub cells: Vec<usize>,
    /// The source of each row, as a position in `cells`.
    pub sources: Vec<u32>,
    /// `rows[[i, j]] = d_Ω(cells[sources[i]], cells[j])` (`k × n`).
    pub rows: Array2<f64>,
    /// Largest `|d(i, j) − d(j, i)|` of the source block before symmetrisation.
    pub asymmetry: f64,
}

/// The canonical form of a mask.
#[derive(Debug, Clone, PartialEq)]
pub struct MaskEmbedding {
    /// The rows it was computed from.
    pub rows: MaskRows,
    /// The embedded points (`n × dimensions`, one per cell of `Ω`, on their
    /// principal axes) and the MDS eigenvalues.
    pub embedding: Embedding,
    /// Normalised stress `sqrt(Σ (e − g)² / Σ g²)` over the measured pairs.
    pub stress: f64,
    /// `1 − ρ²` between embedded and inner distances (Tenenbaum's residual variance).
    pub residual_variance: f64,
}

/// The number of connected pieces of `mask` under the axial neighbourhood
/// (4 neighbours in 2D, 6 in 3D): the one fast marching propagates through.
pub fn mask_components(grid: &Grid, mask: &[bool]) -> usize {
    let [n0, n1, n2] = grid.shape3();
    let strides = grid.strides3();
    let mut seen = vec![false; mask.len()];
    let mut queue = VecDeque::new();
    let mut pieces = 0;
    for start in 0..mask.len() {
        if !mask[start] || seen[start] {
            continue;
        }
        pieces += 1;
        seen[start] = true;
        queue.push_back(start);
        while let Some(c) = queue.pop_front() {
            let [i, j, k] = grid.unravel(c);
            let idx = [i, j, k];
            let dims = [n0, n1, n2];
            for axis in 0..3 {
                for up in [false, true] {
                    let next = if up {
                        (idx[axis] + 1 < dims[axis]).then(|| c + strides[axis])
                    } else {
                        (idx[axis] > 0).then(|| c - strides[axis])
                    };
                    if let Some(q) = next {
                        if mask[q] && !seen[q] {
                            seen[q] = true;
                            queue.push_back(q);
                        }
                    }
                }
            }
        }
    }
    pieces
}

/// The inner-distance rows of `mask` on `grid`: from every cell when
/// `landmarks` is `None`, else from that many farthest-point landmarks (see
/// the module docs).
pub fn mask_rows(
    grid: &Grid,
    mask: &[bool],
    landmarks: Option<usize>,
    order: Order,
    symmetry: Symmetry,
    control: &Control<'_>,
) -> Result<MaskRows, ShapeError> {
    if mask.len() != grid.len() {
        return Err(ShapeError::InvalidOption {
            option: "mask",
            reason: format!("{} values for a grid of {} cells", mask.len(), grid.len()),
        });
    }
    let cells: Vec<usize> = (0..mask.len()).filter(|&c| mask[c]).collect();
    let n = cells.len();
    if n < 2 {
        return Err(ShapeError::InvalidOption {
            option: "mask",
            reason: format!("the shape has {n} cells: at least 2 are needed"),
        });
    }
    let components = mask_components(grid, mask);
    if components > 1 {
        return Err(ShapeError::Disconnected {
            what: "mask",
            components,
            hint: "keep one piece (label the mask and keep the largest) or close the gaps \
                   (pieces that touch only at corners are apart: fast marching steps along the axes)",
        });
    }
    let mut position = vec![u32::MAX; mask.len()];
    for (p, &c) in cells.iter().enumerate() {
        position[c] = p as u32;
    }
    let walls: Vec<bool> = mask.iter().map(|&m| !m).collect();
    let cost = IsotropicCost::new(
        grid,
        CostValues::Constant(1.0),
        Interpretation::Cost,
        Some(Cow::Owned(walls)),
    )
    .map_err(|e| ShapeError::Numerical(e.to_string()))?;
    let inner = control.cancel_only();
    let sources: Vec<u32> = match landmarks {
        None => (0..n as u32).collect(),
        Some(k) => {
            if k == 0 || k > n {
                return Err(ShapeError::InvalidOption {
                    option: "landmarks",
                    reason: format!("must be between 1 and the shape's {n} cells, got {k}"),
                });
            }
            let sampling = farthest_point_sampling(
                grid,
                &cost,
                &SamplingOptions {
                    count: Some(k),
                    radius: None,
                    seeds: Vec::new(),
                    method: SamplingMethod::Exact,
                },
                &inner,
            )
            .map_err(|e| match e {
                SamplingError::Cancelled => ShapeError::Cancelled,
                other => ShapeError::Numerical(other.to_string()),
            })?;
            sampling
                .samples
                .iter()
                .map(|s| position[grid.linear(pad3(s))])
                .collect()
        }
    };
    let options = EikonalOptions::DEFAULT.with_order(order);
    let mut rows = par_rows(&sources, n, control, |s, row| {
        let point: Vec<f64> = cell_index(grid, cells[s as usize])
            .iter()
            .map(|&x| x as f64)
            .collect();
        let problem = EikonalProblem {
            grid: grid.clone(),
            cost: cost.clone(),
            sources: vec![Source::Point(point)],
        };
        let out = eikonal::solve(&problem, &options, &inner).map_err(|e| match e {
            EikonalError::Cancelled => ShapeError::Cancelled,
            other => ShapeError::Numerical(other.to_string()),
        })?;
        let u = out.distance.as_slice_memory_order().unwrap_or(&[]);
        if u.len() != grid.len() {
            return Err(ShapeError::Numerical(
                "the solve returned a map of another size".into(),
            ));
        }
        for (r, &c) in row.iter_mut().zip(&cells) {
            *r = u[c];
        }
        Ok(())
    })?;
    let asymmetry = symmetrize_block(&mut rows, &sources, symmetry);
    Ok(MaskRows {
        cells,
        sources,
        rows,
        asymmetry,
    })
}

/// A cell's index coordinates (2 or 3, axis 0 first) as the three indices
/// of [`Grid::linear`] (a 2D grid is padded with a leading axis of length 1).
fn pad3(s: &[usize]) -> [usize; 3] {
    let mut idx = [0usize; 3];
    let n = s.len().min(3);
    idx[3 - n..].copy_from_slice(&s[..n]);
    idx
}

/// The index coordinates (axis 0 first, the grid's own axes) of cell `c`.
pub fn cell_index(grid: &Grid, c: usize) -> Vec<usize> {
    grid.unravel(c)[3 - grid.ndim()..].to_vec()
}

/// The canonical form of `mask` in `dimensions` (2 or 3) dimensions: rows
/// as in [`mask_rows`] (averaged symmetric block), then classical MDS (all
/// pairs) or landmark MDS, on principal axes.
pub fn mask_embedding(
    grid: &Grid,
    mask: &[bool],
    landmarks: Option<usize>,
    dimensions: usize,
    order: Order,
    control: &Control<'_>,
) -> Result<MaskEmbedding, ShapeError> {
    if !(2..=3).contains(&dimensions) {
        return Err(ShapeError::InvalidOption {
            option: "dimensions",
            reason: format!("must be 2 or 3, got {dimensions}"),
        });
    }
    if let Some(k) = landmarks {
        if k <= dimensions {
            return Err(ShapeError::InvalidOption {
                option: "landmarks",
                reason: format!(
                    "at least dimensions + 1 = {} landmarks are needed",
                    dimensions + 1
                ),
            });
        }
    }
    let rows = mask_rows(grid, mask, landmarks, order, Symmetry::Average, control)?;
    if rows.cells.len() <= dimensions {
        return Err(ShapeError::InvalidOption {
            option: "mask",
            reason: format!(
                "the shape has {} cells: an embedding in {dimensions} dimensions needs more",
                rows.cells.len()
            ),
        });
    }
    let inner = control.cancel_only();
    let mut embedding = if landmarks.is_none() {
        classical_mds(rows.rows.view(), dimensions, &inner)?
    } else {
        let cols: Vec<usize> = rows.sources.iter().map(|&s| s as usize).collect();
        landmark_mds(rows.rows.view(), &cols, dimensions, &inner)?
    };
    principal_axes(&mut embedding.coords);
    let stats = PairStats::of(rows.rows.view(), &rows.sources, embedding.coords.view());
    Ok(MaskEmbedding {
        stress: stats.normalized_stress(),
        residual_variance: stats.residual_variance(),
        rows,
        embedding,
    })
}

/// The faces of the pixel mesh of a 2D shape (see the module docs), vertex
/// `p` being `cells[p]`: for each 2 × 2 block of cells, two triangles when
/// all four are in the shape (split along the `(i, j)–(i+1, j+1)` diagonal),
/// one when three are. Counter-clockwise in `(column, row)` coordinates.
/// Empty for a 3D grid.
pub fn pixel_faces(grid: &Grid, cells: &[usize]) -> Vec<[u32; 3]> {
    if grid.ndim() != 2 {
        return Vec::new();
    }
    let [_, rows, cols] = grid.shape3();
    let mut position = vec![u32::MAX; grid.len()];
    for (p, &c) in cells.iter().enumerate() {
        position[c] = p as u32;
    }
    let at = |i: usize, j: usize| position[grid.linear([0, i, j])];
    let mut faces = Vec::new();
    for i in 0..rows.saturating_sub(1) {
        for j in 0..cols.saturating_sub(1) {
            let a = at(i, j);
            let b = at(i, j + 1);
            let c = at(i + 1, j);
            let d = at(i + 1, j + 1);
            let inside = [a, b, c, d].map(|v| v != u32::MAX);
            match inside {
                [true, true, true, true] => {
                    faces.push([a, d, b]);
                    faces.push([a, c, d]);
                }
                [false, true, true, true] => faces.push([b, c, d]),
                [true, false, true, true] => faces.push([a, c, d]),
                [true, true, false, true] => faces.push([a, d, b]),
                [true, true, true, false] => faces.push([a, c, b]),
                _ => {}
            }
        }
    }
    faces
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::shape::procrustes::align;

    fn rectangle(rows: usize, cols: usize, pad: usize) -> (Grid, Vec<bool>) {
        let shape = [rows + 2 * pad, cols + 2 * pad];
        let grid = Grid::unit(&shape).expect("grid");
        let mask = (0..grid.len())
            .map(|c| {
                let (i, j) = (c / shape[1], c % shape[1]);
                (pad..pad + rows).contains(&i) && (pad..pad + cols).contains(&j)
            })
            .collect();
        (grid, mask)
    }

    #[test]
    fn rows_equal_single_solves_and_landmarks_are_shape_cells() {
        let (grid, mask) = rectangle(12, 20, 2);
        let r = mask_rows(
            &grid,
            &mask,
            Some(5),
            Order::Second,
            Symmetry::None,
            &Control::new(),
        )
        .expect("rows");
        assert_eq!(r.cells.len(), 240);
        assert_eq!(r.rows.dim(), (5, 240));
        for (i, &s) in r.sources.iter().enumerate() {
            let c = r.cells[s as usize];
            assert!(mask[c]);
            let [_, a, b] = grid.unravel(c);
            let cost = IsotropicCost::new(
                &grid,
                CostValues::Constant(1.0),
                Interpretation::Cost,
                Some(Cow::Owned(mask.iter().map(|&m| !m).collect())),
            )
            .expect("cost");
            let one = eikonal::solve(
                &EikonalProblem {
                    grid: grid.clone(),
                    cost,
                    sources: vec![Source::Point(vec![a as f64, b as f64])],
                },
                &EikonalOptions::DEFAULT,
                &Control::new(),
            )
            .expect("solve");
            for (j, &c) in r.cells.iter().enumerate() {
                assert_eq!(
                    r.rows[[i, j]].to_bits(),
                    one.distance.as_slice().expect("c")[c].to_bits()
                );
            }
        }
        // Farthest points of a rectangle start at its corners.
        let corners = r.sources[..2]
            .iter()
            .map(|&s| grid.unravel(r.cells[s as usize]))
            .filter(|&[_, i, j]| (i == 2 || i == 13) && (j == 2 || j == 21))
            .count();
        assert_eq!(corners, 2);
    }

    #[test]
    fn a_rectangle_embeds_as_itself() {
        // Convex: the inner distance is Euclidean, so MDS gives the cells
        // back up to a rigid motion, within the scheme's error.
        let (grid, mask) = rectangle(16, 40, 1);
        for landmarks in [None, Some(24)] {
            let e = mask_embedding(&grid, &mask, landmarks, 2, Order::Second, &Control::new())
                .expect("embedding");
            let truth = Array2::from_shape_fn((e.rows.cells.len(), 2), |(p, a)| {
                cell_index(&grid, e.rows.cells[p])[a] as f64
            });
            let fit = align(e.embedding.coords.view(), truth.view(), true).expect("align");
            assert!(fit.rms < 0.15, "{landmarks:?}: rms {}", fit.rms);
            assert!(e.residual_variance < 1e-3, "{}", e.residual_variance);
        }
    }

    /// The extents of a point set along its (principal) axes, largest first.
    fn extents(x: &Array2<f64>) -> Vec<f64> {
        let mut e: Vec<f64> = x
            .columns()
            .into_iter()
            .map(|c| {
                c.fold(f64::NEG_INFINITY, |m, &v| m.max(v))
                    - c.fold(f64::INFINITY, |m, &v| m.min(v))
            })
            .collect();
        e.sort_by(|a, b| b.total_cmp(a));
        e
    }

    #[test]
    fn a_bent_arm_has_the_canonical_form_of_the_straight_one() {
        // An arm of two 60 × 8 segments, straight or bent by 90° at the
        // elbow: the inner distances barely change (only across the joint),
        // so the canonical forms agree although the shapes do not.
        let (w, l) = (8usize, 60usize);
        let straight = |i: usize, j: usize| (4..4 + w).contains(&i) && (4..4 + 2 * l).contains(&j);
        let bent = |i: usize, j: usize| {
            (4..4 + w).contains(&i) && (4..4 + l + w).contains(&j)
                || (4..4 + l + w).contains(&i) && (4 + l..4 + l + w).contains(&j)
        };
        let form = |inside: &dyn Fn(usize, usize) -> bool, shape: [usize; 2]| {
            let grid = Grid::unit(&shape).expect("grid");
            let mask: Vec<bool> = (0..grid.len())
                .map(|c| inside(c / shape[1], c % shape[1]))
                .collect();
            let e = mask_embedding(&grid, &mask, Some(30), 2, Order::Second, &Control::new())
                .expect("embedding");
            let cells: Array2<f64> = Array2::from_shape_fn((e.rows.cells.len(), 2), |(p, a)| {
                cell_index(&grid, e.rows.cells[p])[a] as f64
            });
            (extents(&e.embedding.coords), extents(&cells), e.stress)
        };
        let (a, a_shape, a_stress) = form(&straight, [16, 2 * l + 8]);
        let (b, b_shape, b_stress) = form(&bent, [l + w + 8, l + w + 8]);
        // The shapes differ: 127 × 7 against 67 × 67.
        assert!(b_shape[0] < 0.6 * a_shape[0], "{a_shape:?} {b_shape:?}");
        // Their canonical forms do not: long axis within 5 %.
        let gap = (a[0] - b[0]).abs() / a[0];
        assert!(gap < 0.05, "straight {a:?}, bent {b:?}: {gap}");
        // The bent arm unfolds (its own extents are 1 : 1); not into a
        // straight strip, since inside the elbow the inner corner shortens
        // the paths of one side only: 0.26 measured.
        assert!(b[1] < 0.35 * b[0], "the bent arm unfolds: {b:?}");
        assert!(a_stress < 0.02 && b_stress < 0.1, "{a_stress} {b_stress}");
    }

    #[test]
    fn pieces_are_refused_and_pixel_faces_cover_the_shape() {
        let grid = Grid::unit(&[5, 5]).expect("grid");
        let mut mask = vec![false; 25];
        mask[6] = true;
        mask[18] = true; // touches nothing
        assert_eq!(mask_components(&grid, &mask), 2);
        let r = mask_rows(
            &grid,
            &mask,
            None,
            Order::First,
            Symmetry::Average,
            &Control::new(),
        );
        assert!(matches!(
            r,
            Err(ShapeError::Disconnected { components: 2, .. })
        ));
        let (grid, mask) = rectangle(3, 4, 0);
        let cells: Vec<usize> = (0..12).collect();
        assert!(mask.iter().all(|&m| m));
        assert_eq!(pixel_faces(&grid, &cells).len(), 2 * 2 * 3);
    }

    #[test]
    fn a_raised_flag_stops_the_rows() {
        let (grid, mask) = rectangle(30, 30, 0);
        let flag = std::sync::atomic::AtomicBool::new(true);
        let control = Control::new().with_cancel(&flag);
        let r = mask_rows(
            &grid,
            &mask,
            Some(10),
            Order::Second,
            Symmetry::Average,
            &control,
        );
        assert_eq!(r, Err(ShapeError::Cancelled));
    }
}
