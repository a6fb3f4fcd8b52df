//! STL, ASCII (`solid … facet … vertex x y z … endsolid`) or binary (80-byte
//! header, `u32` triangle count, 50 bytes per triangle). STL stores three
//! positions per triangle; vertices with bit-identical coordinates are
//! welded into one (counted in [`super::MeshReport::welded_vertices`]).

use std::collections::HashMap;

use super::{parse_f64, text_lines, MeshFormat, MeshIoError, MeshLimits, RawMesh};

const F: MeshFormat = MeshFormat::Stl;

/// True if the bytes are a binary STL: the declared triangle count matches
/// the length exactly.
pub(crate) fn is_binary(bytes: &[u8]) -> bool {
    bytes.len() >= 84 && {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
        84 + 50 * n == bytes.len() as u64
    }
}

struct Welder {
    raw: RawMesh,
    map: HashMap<[u64; 3], u32>,
    corners: usize,
}

impl Welder {
    fn vertex(&mut self, p: [f64; 3]) -> u32 {
        self.corners += 1;
        // +0.0 and -0.0 weld together.
        let key = p.map(|c| if c == 0.0 { 0 } else { c.to_bits() });
        let next = self.raw.positions.len() as u32;
        let id = *self.map.entry(key).or_insert(next);
        if id == next {
            self.raw.positions.push(p);
        }
        id
    }

    fn finish(mut self) -> RawMesh {
        self.raw.welded = self.corners - self.raw.positions.len();
        self.raw
    }
}

pub(crate) fn read(bytes: &[u8], limits: &MeshLimits) -> Result<RawMesh, MeshIoError> {
    let looks_ascii = bytes.iter().take(512).all(|b| b.is_ascii())
        && String::from_utf8_lossy(&bytes[..bytes.len().min(512)])
            .trim_start()
            .starts_with("solid");
    if !is_binary(bytes) && looks_ascii {
        return read_ascii(bytes, limits);
    }
    if bytes.len() < 84 {
        return Err(MeshIoError::corrupt(
            F,
            None,
            "shorter than the 84-byte binary header",
        ));
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
    limits.check(F, 3 * n, n)?;
    if 84 + 50 * n != bytes.len() as u64 {
        return Err(MeshIoError::corrupt(
            F,
            None,
            format!(
                "binary STL declares {n} triangles ({} bytes) but has {} bytes",
                84 + 50 * n,
                bytes.len()
            ),
        ));
    }
    let mut w = Welder {
        raw: RawMesh {
            positions: Vec::with_capacity(n as usize / 2 + 3),
            triangles: Vec::with_capacity(n as usize),
            welded: 0,
        },
        map: HashMap::with_capacity(n as usize / 2 + 3),
        corners: 0,
    };
    for rec in bytes[84..].chunks_exact(50) {
        let f = |o: usize| f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]) as f64;
        let mut t = [0u32; 3];
        for (k, slot) in t.iter_mut().enumerate() {
            let o = 12 + 12 * k;
            *slot = w.vertex([f(o), f(o + 4), f(o + 8)]);
        }
        w.raw.triangles.push(t);
    }
    Ok(w.finish())
}

fn read_ascii(bytes: &[u8], limits: &MeshLimits) -> Result<RawMesh, MeshIoError> {
    let mut w = Welder {
        raw: RawMesh::default(),
        map: HashMap::new(),
        corners: 0,
    };
    let mut corner: Vec<u32> = Vec::with_capacity(3);
    for (line, s) in text_lines(bytes) {
        let mut it = s.split_ascii_whitespace();
        match it.next() {
            Some("vertex") => {
                let mut p = [0.0; 3];
                for c in p.iter_mut() {
                    let tok = it.next().ok_or_else(|| {
                        MeshIoError::corrupt(F, Some(line), "a vertex needs 3 coordinates")
                    })?;
                    *c = parse_f64(F, line, tok)?;
                }
                if w.raw.positions.len() >= limits.max_vertices {
                    limits.check(F, w.raw.positions.len() as u64 + 1, 0)?;
                }
                corner.push(w.vertex(p));
            }
            Some("outer") => corner.clear(),
            Some("endloop") => {
                if corner.len() < 3 {
                    return Err(MeshIoError::corrupt(
                        F,
                        Some(line),
                        "a facet needs 3 vertices",
                    ));
                }
                if w.raw.triangles.len() + corner.len() - 2 > limits.max_faces {
                    limits.check(F, 0, (w.raw.triangles.len() + corner.len()) as u64)?;
                }
                for k in 1..corner.len() - 1 {
                    w.raw.triangles.push([corner[0], corner[k], corner[k + 1]]);
                }
                corner.clear();
            }
            _ => {}
        }
    }
    Ok(w.finish())
}
