//! Zhang–Suen thinning of a 2D binary image to a one-cell-thin set that
//! keeps its end points and its 8-connectivity (Zhang & Suen 1984).
//!
//! With `P2, …, P9` the eight neighbours of a cell clockwise from north,
//! `B` the number of them in the set and `A` the number of `0 → 1`
//! transitions in the cyclic sequence `P2, P3, …, P9, P2`, a cell is deleted
//! when `2 ≤ B ≤ 6` (neither an end point nor an interior cell), `A = 1`
//! (its neighbours in the set form one arc, so deleting it disconnects
//! nothing), and, in the first sub-pass, `P2·P4·P6 = 0` and `P4·P6·P8 = 0`
//! (a south-east boundary or north-west corner cell), in the second
//! `P2·P4·P8 = 0` and `P2·P6·P8 = 0`. Each sub-pass decides on the image as
//! it was before it and deletes all its cells at once; the two sub-passes
//! repeat until neither deletes anything.

/// Thins the set `m` of an `(n0, n1)` image whose border is empty, in place.
pub(super) fn thin_2d(m: &mut [bool], n0: usize, n1: usize) {
    let mut changed = true;
    let mut del = Vec::new();
    while changed {
        changed = false;
        for pass in 0..2 {
            del.clear();
            for i in 1..n0.saturating_sub(1) {
                for j in 1..n1 - 1 {
                    let c = i * n1 + j;
                    if m[c] && deletable(&neighbours(m, c, n1), pass) {
                        del.push(c);
                    }
                }
            }
            for &c in &del {
                m[c] = false;
            }
            changed |= !del.is_empty();
        }
    }
}

/// `P2, …, P9` of the interior cell `c` of an image of width `n1`: the
/// eight neighbours clockwise from north (`P2` at `c - n1`).
fn neighbours(m: &[bool], c: usize, n1: usize) -> [bool; 8] {
    [
        m[c - n1],
        m[c - n1 + 1],
        m[c + 1],
        m[c + n1 + 1],
        m[c + n1],
        m[c + n1 - 1],
        m[c - 1],
        m[c - n1 - 1],
    ]
}

/// The Zhang–Suen deletion test of a cell with neighbours `p = [P2, …, P9]`
/// in sub-pass `pass` (0 or 1), see the module docs.
fn deletable(p: &[bool; 8], pass: usize) -> bool {
    let b = p.iter().filter(|&&v| v).count();
    if !(2..=6).contains(&b) {
        return false;
    }
    let a = (0..8).filter(|&k| !p[k] && p[(k + 1) % 8]).count();
    if a != 1 {
        return false;
    }
    let (p2, p4, p6, p8) = (p[0], p[2], p[4], p[6]);
    if pass == 0 {
        !(p4 && p6 && (p2 || p8))
    } else {
        !(p2 && p8 && (p4 || p6))
    }
}
