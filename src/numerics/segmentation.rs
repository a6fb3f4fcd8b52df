//! Seeded segmentation by geodesic Voronoi cells, geodesic balls and shape
//! offsets (seed §1.4.1, §3.4, §3.5).
//!
//! # Seeded segmentation
//! With labelled seed sets `S_l` and the geodesic distances `U_l = d(·, S_l)`
//! of one metric, the segmentation is the Voronoi partition
//! `ℓ(x) = argmin_l U_l(x)` (seed eq. 1.19). Its confidence is the margin
//! `U_(2)(x) - U_(1)(x)` between the distance to the nearest seed and the
//! distance to the nearest seed of *another* label: 0 on the boundaries
//! between cells, large deep inside a cell. [`voronoi`] combines the per-label
//! maps (one eikonal solve per label, see `ops::grid_segment`).
//!
//! # Offsets
//! The dilation of a shape `A` by `r` is the geodesic ball `{x : d(x, A) <= r}`;
//! its erosion is the complement of the dilation of the complement,
//! `{x ∈ A : d(x, A^c) > r}`. [`offset_euclidean`] computes both with the exact
//! EDT (distance between cell centres); geodesic offsets and offsets around
//! obstacles use an eikonal solve from the shape (see `ops::grid_offset`).

use super::edt::{self, EdtError, EdtOptions};
use super::{Control, Grid};

/// A geodesic Voronoi segmentation.
#[derive(Debug, Clone, PartialEq)]
pub struct Voronoi {
    /// Label of the nearest seed set, `-1` where no seed reaches.
    pub labels: Vec<i32>,
    /// Distance to the nearest seed (`+inf` where none reaches).
    pub nearest: Vec<f64>,
    /// Distance to the nearest seed of another label (`+inf` with one label).
    pub second: Vec<f64>,
}

impl Voronoi {
    /// The confidence `second - nearest` (`+inf` where only one label reaches,
    /// `NaN` never: 0 where no label reaches).
    pub fn confidence(&self) -> Vec<f64> {
        self.nearest
            .iter()
            .zip(&self.second)
            .map(|(&a, &b)| if a.is_finite() { b - a } else { 0.0 })
            .collect()
    }
}

/// Combines per-label distance maps `maps[k]` (label `ids[k]`) into the
/// Voronoi labels, the nearest and the second-nearest (other label)
/// distances. Ties go to the first map.
pub fn voronoi(maps: &[Vec<f64>], ids: &[i32]) -> Voronoi {
    let n = maps.first().map_or(0, Vec::len);
    let mut labels = vec![-1; n];
    let mut nearest = vec![f64::INFINITY; n];
    let mut second = vec![f64::INFINITY; n];
    for (map, &id) in maps.iter().zip(ids) {
        for i in 0..n {
            let d = map[i];
            if d < nearest[i] {
                second[i] = nearest[i];
                nearest[i] = d;
                labels[i] = id;
            } else if d < second[i] {
                second[i] = d;
            }
        }
    }
    Voronoi {
        labels,
        nearest,
        second,
    }
}

/// Dice coefficient `2 |A ∩ B| / (|A| + |B|)` of two masks (1 when both are empty).
pub fn dice(a: &[bool], b: &[bool]) -> f64 {
    let inter = a.iter().zip(b).filter(|(&x, &y)| x && y).count();
    let total = a.iter().filter(|&&x| x).count() + b.iter().filter(|&&x| x).count();
    if total == 0 {
        1.0
    } else {
        2.0 * inter as f64 / total as f64
    }
}

/// Dilation (`r >= 0` grows) or erosion of a shape by the Euclidean distance
/// `r` between cell centres, with the exact EDT. Cells beyond the grid are
/// not part of the world: erosion only eats from the shape's boundary inside
/// the grid.
pub fn offset_euclidean(
    grid: &Grid,
    mask: &[bool],
    r: f64,
    dilate: bool,
    control: &Control<'_>,
) -> Result<(Vec<bool>, Vec<f64>), EdtError> {
    let r2 = r * r * (1.0 + 1e-12);
    if dilate {
        let d = edt::edt_squared(grid, mask, &EdtOptions::default(), control)?.distance;
        let out = d.iter().map(|&v| v <= r2).collect();
        Ok((out, d.into_iter().map(f64::sqrt).collect()))
    } else {
        let inv: Vec<bool> = mask.iter().map(|&m| !m).collect();
        let d = edt::edt_squared(grid, &inv, &EdtOptions::default(), control)?.distance;
        let out = d.iter().map(|&v| v > r2).collect();
        Ok((out, d.into_iter().map(f64::sqrt).collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voronoi_keeps_the_second_label_and_offsets_match_disc_areas() {
        let v = voronoi(&[vec![1.0, 5.0, 2.0], vec![3.0, 4.0, 2.0]], &[7, 9]);
        assert_eq!(v.labels, vec![7, 9, 7]);
        assert_eq!(v.nearest, vec![1.0, 4.0, 2.0]);
        assert_eq!(v.second, vec![3.0, 5.0, 2.0]);
        assert_eq!(v.confidence(), vec![2.0, 1.0, 0.0]);
        assert_eq!(dice(&[true, false], &[true, true]), 2.0 / 3.0);

        let n = 200;
        let grid = Grid::unit(&[n, n]).unwrap();
        let (c, r0) = (100.0, 30.0);
        let disc: Vec<bool> = (0..n * n)
            .map(|k| (((k / n) as f64 - c).powi(2) + ((k % n) as f64 - c).powi(2)).sqrt() <= r0)
            .collect();
        let pi = std::f64::consts::PI;
        let (m, d) = offset_euclidean(&grid, &disc, 20.0, true, &Control::new()).unwrap();
        let area = m.iter().filter(|&&b| b).count() as f64;
        assert!(
            (area / (pi * 50.0 * 50.0) - 1.0).abs() < 0.01,
            "dilation: {area}"
        );
        assert_eq!(d[100 * n + 100], 0.0);
        // Erosion of the cell-centre set: the first outside centres lie in
        // (30, 31], so the eroded radius is in (17.5, 18.5].
        let (m, _) = offset_euclidean(&grid, &disc, 12.5, false, &Control::new()).unwrap();
        let area = m.iter().filter(|&&b| b).count() as f64;
        assert!(
            area > pi * 17.4 * 17.4 && area < pi * 18.5 * 18.5,
            "erosion: {area}"
        );
    }
}
