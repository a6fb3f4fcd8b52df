//! OFF: `OFF`, then `nv nf ne`, `nv` lines `x y z`, `nf` lines `k i₁ … i_k`
//! (0-based; trailing colour values ignored). `COFF`/`NOFF` headers accepted.

use super::{parse_f64, text_lines, MeshFormat, MeshIoError, MeshLimits, RawMesh};

const F: MeshFormat = MeshFormat::Off;

pub(crate) fn read(bytes: &[u8], limits: &MeshLimits) -> Result<RawMesh, MeshIoError> {
    let mut lines = text_lines(bytes);
    let (l0, head) = lines
        .next()
        .ok_or_else(|| MeshIoError::corrupt(F, None, "empty file"))?;
    let mut rest = head;
    for magic in ["COFF", "NOFF", "OFF"] {
        if let Some(r) = head.strip_prefix(magic) {
            rest = r.trim();
            break;
        }
    }
    if rest.len() == head.len() {
        return Err(MeshIoError::corrupt(F, Some(l0), "missing OFF header"));
    }
    let (lc, counts) = if rest.is_empty() {
        lines
            .next()
            .ok_or_else(|| MeshIoError::corrupt(F, None, "missing vertex and face counts"))?
    } else {
        (l0, rest)
    };
    let nums: Vec<u64> = counts
        .split_ascii_whitespace()
        .map(|t| t.parse::<u64>())
        .collect::<Result<_, _>>()
        .map_err(|_| MeshIoError::corrupt(F, Some(lc), format!("bad counts '{counts}'")))?;
    if nums.len() < 2 {
        return Err(MeshIoError::corrupt(
            F,
            Some(lc),
            "expected 'vertices faces edges'",
        ));
    }
    let (nv, nf) = (nums[0], nums[1]);
    limits.check(F, nv, nf)?;
    // A file cannot hold more records than it has bytes.
    let cap = bytes.len() as u64 / 2;
    let mut raw = RawMesh {
        positions: Vec::with_capacity(nv.min(cap) as usize),
        triangles: Vec::with_capacity(nf.min(cap) as usize),
        welded: 0,
    };
    for _ in 0..nv {
        let (line, s) = lines
            .next()
            .ok_or_else(|| MeshIoError::corrupt(F, None, format!("expected {nv} vertices")))?;
        let mut it = s.split_ascii_whitespace();
        let mut p = [0.0; 3];
        for c in p.iter_mut() {
            let tok = it.next().ok_or_else(|| {
                MeshIoError::corrupt(F, Some(line), "a vertex needs 3 coordinates")
            })?;
            *c = parse_f64(F, line, tok)?;
        }
        raw.positions.push(p);
    }
    let mut poly = Vec::new();
    for _ in 0..nf {
        let (line, s) = lines
            .next()
            .ok_or_else(|| MeshIoError::corrupt(F, None, format!("expected {nf} faces")))?;
        let mut it = s.split_ascii_whitespace();
        let k: usize = it.next().and_then(|t| t.parse().ok()).ok_or_else(|| {
            MeshIoError::corrupt(F, Some(line), "a face starts with its vertex count")
        })?;
        poly.clear();
        for _ in 0..k {
            let i: i64 = it.next().and_then(|t| t.parse().ok()).ok_or_else(|| {
                MeshIoError::corrupt(F, Some(line), format!("expected {k} vertex indices"))
            })?;
            poly.push(i);
        }
        raw.push_polygon(F, Some(line), &poly, limits)?;
    }
    Ok(raw)
}
