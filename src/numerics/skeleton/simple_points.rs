//! Simple points of a 3D binary image in the (26, 6) connectivity: the
//! local test behind the topology-preserving thinning of
//! [`super::thinning_3d`].
//!
//! A cell's 3×3×3 neighbourhood is a 27-bit mask: position
//! `p = 9 (d0 + 1) + 3 (d1 + 1) + (d2 + 1)` holds the offset `(d0, d1, d2)`,
//! so every test below is a few bit operations on `u32`s.

/// Position of the centre in the 3×3×3 neighbourhood, whose position
/// `p = 9 (d0 + 1) + 3 (d1 + 1) + (d2 + 1)` is the offset `(d0, d1, d2)`.
pub(super) const CENTRE: usize = 13;

/// The offset `(d0, d1, d2) ∈ {-1, 0, 1}³` of position `p` of the 3×3×3 neighbourhood.
pub(super) const fn cube_pos(p: usize) -> [isize; 3] {
    [
        (p / 9) as isize - 1,
        ((p / 3) % 3) as isize - 1,
        (p % 3) as isize - 1,
    ]
}

/// Adjacency of the 27 positions as bit masks: `ADJ26[p]` has the positions
/// at Chebyshev distance 1 from `p` (26-adjacency), `ADJ6[p]` those at
/// Manhattan distance 1 (6-adjacency).
const fn cube_adjacency(six: bool) -> [u32; 27] {
    let mut adj = [0u32; 27];
    let mut p = 0;
    while p < 27 {
        let a = cube_pos(p);
        let mut q = 0;
        while q < 27 {
            let b = cube_pos(q);
            let d = [
                (a[0] - b[0]).abs(),
                (a[1] - b[1]).abs(),
                (a[2] - b[2]).abs(),
            ];
            let cheb = if d[0] > d[1] { d[0] } else { d[1] };
            let cheb = if cheb > d[2] { cheb } else { d[2] };
            let manh = d[0] + d[1] + d[2];
            if p != q && cheb == 1 && (!six || manh == 1) {
                adj[p] |= 1 << q;
            }
            q += 1;
        }
        p += 1;
    }
    adj
}

/// 26-adjacency of the 27 positions (see [`cube_adjacency`]).
const ADJ26: [u32; 27] = cube_adjacency(false);
/// 6-adjacency of the 27 positions (see [`cube_adjacency`]).
pub(super) const ADJ6: [u32; 27] = cube_adjacency(true);

/// The 18-neighbourhood of the centre without it: every position but the
/// centre and the eight corners (offsets with three non-zero coordinates).
const N18: u32 = {
    let mut m = 0u32;
    let mut p = 0;
    while p < 27 {
        let d = cube_pos(p);
        let nz = (d[0] != 0) as u32 + (d[1] != 0) as u32 + (d[2] != 0) as u32;
        if nz == 1 || nz == 2 {
            m |= 1 << p;
        }
        p += 1;
    }
    m
};

/// The component of `set` (bit mask of positions) that contains the
/// positions of `seed`, under the adjacency `adj`.
fn grow(seed: u32, set: u32, adj: &[u32; 27]) -> u32 {
    let mut comp = seed & set;
    let mut front = comp;
    while front != 0 {
        let mut next = 0u32;
        let mut bits = front;
        while bits != 0 {
            let q = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            next |= adj[q];
        }
        front = next & set & !comp;
        comp |= front;
    }
    comp
}

/// Whether the centre of a 3×3×3 neighbourhood is a simple point of the
/// foreground in the (26, 6) connectivity (Bertrand–Malandain 1994):
/// `nbhd` has bit `p` set when position `p` is foreground (the centre's bit
/// is ignored). With `X* = N26*(p) ∩ X` and `B = N18*(p) \ X`, the centre is
/// simple iff
/// * the topological number `T26 = #26-components of X*` is 1, and
/// * `T6 = #6-components of B that contain a 6-neighbour of p` is 1.
///
/// Removing a simple point from `X` changes neither the 26-components of `X`,
/// nor the 6-components of its complement, nor their tunnels.
pub(super) fn is_simple(nbhd: u32) -> bool {
    let all = ((1u32 << 27) - 1) & !(1 << CENTRE);
    let fg = nbhd & all;
    if fg == 0 {
        return false;
    }
    let first = fg & fg.wrapping_neg();
    if grow(first, fg, &ADJ26) != fg {
        return false;
    }
    let bg = N18 & !fg;
    let faces = ADJ6[CENTRE] & bg;
    if faces == 0 {
        return false;
    }
    let first = faces & faces.wrapping_neg();
    // One component iff the component of one free face reaches all free faces.
    grow(first, bg, &ADJ6) & faces == faces
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 27-bit neighbourhood with the given offsets set.
    fn cube(offsets: &[[isize; 3]]) -> u32 {
        offsets
            .iter()
            .map(|d| 1u32 << ((d[0] + 1) * 9 + (d[1] + 1) * 3 + d[2] + 1))
            .fold(0, |a, b| a | b)
    }

    /// All offsets of the neighbourhood but the centre that satisfy `f`.
    fn cube_where(f: impl Fn([isize; 3]) -> bool) -> u32 {
        (0..27)
            .filter(|&p| p != CENTRE && f(cube_pos(p)))
            .fold(0, |a, p| a | (1 << p))
    }

    #[test]
    fn simple_points_in_26_6_connectivity() {
        // Isolated voxel: removing it deletes a component.
        assert!(!is_simple(0));
        // End of a line (face, edge or corner neighbour): simple.
        assert!(is_simple(cube(&[[0, 0, 1]])));
        assert!(is_simple(cube(&[[0, 1, 1]])));
        assert!(is_simple(cube(&[[1, 1, 1]])));
        // Middle of a line, straight or bent: removing it splits the line.
        assert!(!is_simple(cube(&[[0, 0, -1], [0, 0, 1]])));
        assert!(!is_simple(cube(&[[-1, -1, -1], [1, 1, 1]])));
        assert!(!is_simple(cube(&[[0, -1, 0], [1, 1, 1]])));
        // A corner of a bent line whose two neighbours touch each other: simple.
        assert!(is_simple(cube(&[[0, 0, 1], [0, 1, 0]])));
        // The centre of a ring in a plane: removing it opens a tunnel through
        // the ring (the background above and below would join), not simple.
        let ring = cube_where(|d| d[0] == 0);
        assert!(!is_simple(ring));
        // Interior of a solid: removing it creates a cavity.
        assert!(!is_simple(cube_where(|_| true)));
        // Flat face of a solid (foreground on one side, including the face plane): simple.
        assert!(is_simple(cube_where(|d| d[0] >= 0)));
        // An edge and a corner of a solid cube: simple.
        assert!(is_simple(cube_where(|d| d[0] >= 0 && d[1] >= 0)));
        assert!(is_simple(cube_where(|d| d[0] >= 0
            && d[1] >= 0
            && d[2] >= 0)));
        // A ring broken at a face cell: removing the centre leaves a bent
        // line and no tunnel, simple. (Broken at a corner cell, the ring is
        // still closed through the 26-adjacent face cells.)
        assert!(is_simple(ring & !cube(&[[0, 1, 0]])));
        assert!(!is_simple(ring & !cube(&[[0, 1, 1]])));
        // The centre of a solid pierced by a background line through it: the
        // two background faces are not
        // 6-connected in N18, removing the centre would join them (a tunnel).
        assert!(!is_simple(cube_where(|d| !(d[0] == 0 && d[1] == 0))));
        // The same with a background bridge in N18 joining them: simple.
        assert!(is_simple(cube_where(|d| {
            !(d[1] == 0 && (d[0] == 0 || d[0] == 1))
        })));
    }
}
