//! Wavefront OBJ: `v x y z [w]` and `f a b c ...` records (`a`, `a/t`,
//! `a/t/n`, `a//n`; 1-based, negative indices relative to the end).
//! Everything else (normals, texture coordinates, groups, materials) is ignored.

use super::{parse_f64, text_lines, MeshFormat, MeshIoError, MeshLimits, RawMesh};

const F: MeshFormat = MeshFormat::Obj;

pub(crate) fn read(bytes: &[u8], limits: &MeshLimits) -> Result<RawMesh, MeshIoError> {
    let mut raw = RawMesh::default();
    let mut poly: Vec<i64> = Vec::new();
    for (line, s) in text_lines(bytes) {
        let mut it = s.split_ascii_whitespace();
        match it.next() {
            Some("v") => {
                let mut p = [0.0; 3];
                for c in p.iter_mut() {
                    let tok = it.next().ok_or_else(|| {
                        MeshIoError::corrupt(F, Some(line), "a vertex needs 3 coordinates")
                    })?;
                    *c = parse_f64(F, line, tok)?;
                }
                if raw.positions.len() >= limits.max_vertices {
                    limits.check(F, raw.positions.len() as u64 + 1, 0)?;
                }
                raw.positions.push(p);
            }
            Some("f") => {
                poly.clear();
                for tok in it {
                    let first = tok.split('/').next().unwrap_or_default();
                    let i: i64 = first.parse().map_err(|_| {
                        MeshIoError::corrupt(
                            F,
                            Some(line),
                            format!("'{tok}' is not a vertex index"),
                        )
                    })?;
                    let n = raw.positions.len() as i64;
                    let idx = match i {
                        0 => {
                            return Err(MeshIoError::corrupt(
                                F,
                                Some(line),
                                "OBJ indices start at 1, got 0",
                            ))
                        }
                        i if i > 0 => i - 1,
                        i => n + i,
                    };
                    poly.push(idx);
                }
                raw.push_polygon(F, Some(line), &poly, limits)?;
            }
            _ => {}
        }
    }
    Ok(raw)
}
