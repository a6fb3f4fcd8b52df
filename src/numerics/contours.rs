//! Boundaries of the regions of a 2D label image, as closed rings that follow
//! the cell edges ("crack" boundaries), grouped into polygons with holes.
//!
//! Cell `(i, j)` is the square `[i - 1/2, i + 1/2] x [j - 1/2, j + 1/2]` in
//! index coordinates (axis 0 first), so a region's polygons cover exactly its
//! cells. Regions are 4-connected: two cells of one label that touch only at a
//! corner give two polygons that share that corner. In the plane `(x, y) =
//! (axis 0, axis 1)`, outer rings turn counter-clockwise and holes clockwise
//! (the orientation GeoJSON asks for), and the first vertex is repeated at the end.
//!
//! The tracer works on the directed edges between a cell and a neighbour of
//! another label (or the outside of the grid), oriented with the cell on the
//! left; every cell side is visited once, so the cost is `O(N)`.

use super::Control;

/// One directed boundary edge: from corner `from` to corner `to` (corner
/// `(ci, cj)` has linear index `ci * (n1 + 1) + cj` and sits at the point
/// `(ci - 1/2, cj - 1/2)`), with the region's cell on its left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CrackEdge {
    /// Start corner.
    pub from: u32,
    /// End corner.
    pub to: u32,
    /// The cell on the left (inside the region).
    pub inside: u32,
    /// The cell on the right, `None` outside the grid.
    pub outside: Option<u32>,
    /// Direction: 0 = +axis0, 1 = +axis1, 2 = -axis0, 3 = -axis1.
    pub dir: u8,
}

/// Why the boundaries were not traced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ContourError {
    /// The caller raised the cancel flag.
    #[error("cancelled")]
    Cancelled,
}

/// A closed ring of boundary edges of one region.
#[derive(Debug, Clone, PartialEq)]
pub struct Ring {
    /// The label of the region on the left.
    pub label: i64,
    /// The 4-connected component (index into [`Boundaries::components`]) on the left.
    pub component: usize,
    /// The edges in order.
    pub edges: Vec<CrackEdge>,
    /// Twice the signed area in index units (> 0: outer ring, < 0: hole).
    pub twice_area: i64,
}

/// All boundaries of a label image.
#[derive(Debug, Clone, PartialEq)]
pub struct Boundaries {
    /// Shape `(n0, n1)`.
    pub shape: [usize; 2],
    /// The rings.
    pub rings: Vec<Ring>,
    /// For each 4-connected component: its label and its cell count.
    pub components: Vec<(i64, usize)>,
}

/// A polygon: one outer ring and its holes, as vertex lists in index coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    /// The label of the region.
    pub label: i64,
    /// Outer ring then holes; each closed (first vertex repeated), corners only.
    pub rings: Vec<Vec<[f64; 2]>>,
    /// Number of cells of the component.
    pub cells: usize,
}

/// The boundaries of every region of `labels` (shape `(n0, n1)`, C order).
/// Cells whose label is `skip` (for instance a background) get no ring.
/// `control` is polled once per row of cells and once per ring.
pub fn trace(
    labels: &[i64],
    shape: [usize; 2],
    skip: Option<i64>,
    control: &Control<'_>,
) -> Result<Boundaries, ContourError> {
    let [n0, n1] = shape;
    let poll = || {
        if control.is_cancelled() {
            Err(ContourError::Cancelled)
        } else {
            Ok(())
        }
    };
    let nc1 = n1 + 1;
    let corner = |ci: usize, cj: usize| (ci * nc1 + cj) as u32;
    // Components (4-connectivity), by flood fill.
    let mut comp = vec![u32::MAX; labels.len()];
    let mut components = Vec::new();
    let mut stack = Vec::new();
    for start in 0..labels.len() {
        if start % n1.max(1) == 0 {
            poll()?;
        }
        if comp[start] != u32::MAX || Some(labels[start]) == skip {
            continue;
        }
        let id = components.len() as u32;
        let l = labels[start];
        let mut count = 0;
        comp[start] = id;
        stack.push(start);
        while let Some(c) = stack.pop() {
            count += 1;
            let (i, j) = (c / n1, c % n1);
            let mut push = |k: usize| {
                if comp[k] == u32::MAX && labels[k] == l {
                    comp[k] = id;
                    stack.push(k);
                }
            };
            if i > 0 {
                push(c - n1);
            }
            if i + 1 < n0 {
                push(c + n1);
            }
            if j > 0 {
                push(c - 1);
            }
            if j + 1 < n1 {
                push(c + 1);
            }
        }
        components.push((l, count));
    }
    // Directed edges, region on the left, and the outgoing edges of each corner.
    let mut edges: Vec<CrackEdge> = Vec::new();
    for c in 0..labels.len() {
        if c % n1.max(1) == 0 {
            poll()?;
        }
        if Some(labels[c]) == skip {
            continue;
        }
        let (i, j) = (c / n1, c % n1);
        let l = labels[c];
        let nb = |di: i64, dj: i64| -> Option<usize> {
            let (a, b) = (i as i64 + di, j as i64 + dj);
            (a >= 0 && b >= 0 && (a as usize) < n0 && (b as usize) < n1)
                .then(|| a as usize * n1 + b as usize)
        };
        // Counter-clockwise around the square in the (axis0, axis1) plane:
        // (i,j) -> (i+1,j) -> (i+1,j+1) -> (i,j+1) -> (i,j) in corner indices.
        let sides = [
            (nb(0, -1), corner(i, j), corner(i + 1, j), 0u8),
            (nb(1, 0), corner(i + 1, j), corner(i + 1, j + 1), 1),
            (nb(0, 1), corner(i + 1, j + 1), corner(i, j + 1), 2),
            (nb(-1, 0), corner(i, j + 1), corner(i, j), 3),
        ];
        for (other, from, to, dir) in sides {
            if other.is_none_or(|o| labels[o] != l) {
                edges.push(CrackEdge {
                    from,
                    to,
                    inside: c as u32,
                    outside: other.map(|o| o as u32),
                    dir,
                });
            }
        }
    }
    let ncorners = (n0 + 1) * nc1;
    let mut first_out = vec![u32::MAX; ncorners];
    let mut next_out = vec![u32::MAX; edges.len()];
    for (e, edge) in edges.iter().enumerate() {
        next_out[e] = first_out[edge.from as usize];
        first_out[edge.from as usize] = e as u32;
    }
    let mut used = vec![false; edges.len()];
    let mut rings = Vec::new();
    for start in 0..edges.len() {
        if used[start] {
            continue;
        }
        poll()?;
        let label = labels[edges[start].inside as usize];
        let mut ring = Vec::new();
        let mut e = start;
        let mut twice_area: i64 = 0;
        loop {
            used[e] = true;
            let edge = edges[e];
            ring.push(edge);
            let (fi, fj) = (
                (edge.from as usize / nc1) as i64,
                (edge.from as usize % nc1) as i64,
            );
            let (ti, tj) = (
                (edge.to as usize / nc1) as i64,
                (edge.to as usize % nc1) as i64,
            );
            twice_area += fi * tj - ti * fj;
            // Next edge of the same label leaving `to`; at a saddle, the left
            // turn (4-connectivity).
            let mut best: Option<(usize, u8)> = None;
            let mut k = first_out[edge.to as usize];
            while k != u32::MAX {
                let cand = edges[k as usize];
                if !used[k as usize] && labels[cand.inside as usize] == label {
                    let turn = (cand.dir + 4 - edge.dir) % 4; // 0 straight, 1 left, 3 right
                    let rank = match turn {
                        1 => 0,
                        0 => 1,
                        _ => 2,
                    };
                    if best.is_none_or(|(_, r)| rank < r) {
                        best = Some((k as usize, rank));
                    }
                }
                k = next_out[k as usize];
            }
            match best {
                Some((k, _)) => e = k,
                None => break,
            }
        }
        let component = comp[edges[start].inside as usize] as usize;
        rings.push(Ring {
            label,
            component,
            edges: ring,
            twice_area,
        });
    }
    Ok(Boundaries {
        shape,
        rings,
        components,
    })
}

impl Boundaries {
    /// The polygons: one per 4-connected component, outer ring first, then
    /// its holes, with only the corner vertices kept.
    pub fn polygons(&self) -> Vec<Polygon> {
        let nc1 = self.shape[1] + 1;
        let mut outer: Vec<Option<Vec<[f64; 2]>>> = vec![None; self.components.len()];
        let mut holes: Vec<Vec<Vec<[f64; 2]>>> = vec![Vec::new(); self.components.len()];
        for ring in &self.rings {
            let mut pts = Vec::new();
            for (k, e) in ring.edges.iter().enumerate() {
                let prev = ring.edges[(k + ring.edges.len() - 1) % ring.edges.len()];
                if k == 0 || prev.dir != e.dir {
                    let c = e.from as usize;
                    pts.push([(c / nc1) as f64 - 0.5, (c % nc1) as f64 - 0.5]);
                }
            }
            if let Some(&p0) = pts.first() {
                pts.push(p0);
            }
            if ring.twice_area > 0 {
                outer[ring.component] = Some(pts);
            } else {
                holes[ring.component].push(pts);
            }
        }
        let mut out = Vec::new();
        for (c, o) in outer.into_iter().enumerate() {
            if let Some(o) = o {
                let mut rings = vec![o];
                rings.append(&mut holes[c]);
                out.push(Polygon {
                    label: self.components[c].0,
                    rings,
                    cells: self.components[c].1,
                });
            }
        }
        out
    }
}

/// Shoelace area of a closed ring (first vertex repeated).
pub fn ring_area(ring: &[[f64; 2]]) -> f64 {
    ring.windows(2)
        .map(|w| w[0][0] * w[1][1] - w[1][0] * w[0][1])
        .sum::<f64>()
        / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_with_hole_and_diagonal_cells() {
        // 5x5 ring of label 1 around a hole of label 0, plus two cells of
        // label 2 that touch at a corner.
        let mut l = vec![0i64; 7 * 7];
        for i in 0..5 {
            for j in 0..5 {
                if i == 0 || i == 4 || j == 0 || j == 4 {
                    l[i * 7 + j] = 1;
                }
            }
        }
        l[5 * 7 + 5] = 2;
        l[6 * 7 + 6] = 2;
        let b = trace(&l, [7, 7], Some(0), &Control::new()).unwrap();
        let polys = b.polygons();
        let ones: Vec<_> = polys.iter().filter(|p| p.label == 1).collect();
        assert_eq!(ones.len(), 1);
        assert_eq!(ones[0].rings.len(), 2);
        let outer = ring_area(&ones[0].rings[0]);
        let hole = ring_area(&ones[0].rings[1]);
        assert_eq!(outer, 25.0);
        assert_eq!(hole, -9.0);
        assert_eq!(ones[0].cells, 16);
        assert_eq!(ones[0].rings[0].len(), 5, "corners only, closed");
        let twos: Vec<_> = polys.iter().filter(|p| p.label == 2).collect();
        assert_eq!(twos.len(), 2);
        assert!(twos.iter().all(|p| ring_area(&p.rings[0]) == 1.0));
    }

    #[test]
    fn a_raised_flag_stops_the_tracer() {
        let flag = std::sync::atomic::AtomicBool::new(true);
        let l = vec![1i64; 16];
        assert_eq!(
            trace(&l, [4, 4], None, &Control::new().with_cancel(&flag)),
            Err(ContourError::Cancelled)
        );
    }
}
