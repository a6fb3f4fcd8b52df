//! glTF 2.0 binary (GLB) writer: the format web viewers (three.js,
//! Babylon.js, `<model-viewer>`) load without a converter.
//!
//! # Layout
//!
//! One scene, one node, one mesh with one triangle primitive. The binary
//! chunk holds, in this order and each 4-byte aligned:
//!
//! * `POSITION`: `f32` `VEC3`, with the `min` / `max` the format requires;
//! * `NORMAL`: unit `f32` `VEC3`, the area-weighted average of the normals
//!   of the faces around each vertex (`(0, 0, 1)` for an isolated vertex);
//! * `COLOR_0`, when there is a property: normalised `u8` `VEC4` colours of
//!   the first property (viridis over its finite range for a `double`
//!   property, the categorical palette of the PNG renderings for an `int`
//!   one, grey where a value is not finite or negative);
//! * one application-specific attribute per property, named `_` and the
//!   property's name in capitals (`_DISTANCE`, `_LABEL`, `_VALUE`), `f32`
//!   `SCALAR` (non-finite values stay NaN / ±inf);
//! * the indices, `u32` `SCALAR`, three per face, in the faces'
//!   orientation (glTF takes counter-clockwise as the front face).
//!
//! Positions are written in the mesh's own units and axes: glTF's "metres,
//! +Y up" is a convention for viewers, not something this writer can know.

use crate::io::render::{label_colour, Colormap};
use crate::numerics::mesh::TriMesh;

use super::write::VertexProperty;

/// `ARRAY_BUFFER` (vertex attributes).
const ARRAY_BUFFER: u32 = 34962;
/// `ELEMENT_ARRAY_BUFFER` (indices).
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// Component type `FLOAT`.
const FLOAT: u32 = 5126;
/// Component type `UNSIGNED_BYTE`.
const UNSIGNED_BYTE: u32 = 5121;
/// Component type `UNSIGNED_INT`.
const UNSIGNED_INT: u32 = 5125;
/// Colour of a vertex without a finite value or with a negative label.
const NO_VALUE: [u8; 3] = [128, 128, 128];

/// The binary chunk being assembled, with its views and accessors.
struct Builder {
    bin: Vec<u8>,
    views: Vec<serde_json::Value>,
    accessors: Vec<serde_json::Value>,
}

impl Builder {
    /// Appends `bytes` as a buffer view and an accessor over it; returns
    /// the accessor's index.
    fn push(&mut self, bytes: &[u8], target: u32, accessor: serde_json::Value) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let view = self.views.len();
        self.views.push(serde_json::json!({
            "buffer": 0,
            "byteOffset": self.bin.len(),
            "byteLength": bytes.len(),
            "target": target,
        }));
        self.bin.extend_from_slice(bytes);
        let mut accessor = accessor;
        accessor["bufferView"] = serde_json::json!(view);
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }
}

/// Area-weighted vertex normals (unit length; `(0, 0, 1)` where the faces
/// around a vertex cancel or there are none).
fn vertex_normals(mesh: &TriMesh) -> Vec<[f64; 3]> {
    let p = mesh.positions();
    let mut n = vec![[0.0; 3]; p.len()];
    for f in mesh.faces() {
        let [a, b, c] = f.map(|i| p[i as usize]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        // Twice the area times the unit normal.
        let w = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        for &i in f {
            for k in 0..3 {
                n[i as usize][k] += w[k];
            }
        }
    }
    for v in &mut n {
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        *v = if len > 0.0 && len.is_finite() {
            v.map(|x| x / len)
        } else {
            [0.0, 0.0, 1.0]
        };
    }
    n
}

/// The colour of every vertex after `prop` (see the [module](self) docs).
fn colours(prop: &VertexProperty<'_>, nv: usize) -> Vec<[u8; 3]> {
    match prop {
        VertexProperty::F64(_, x) => {
            let finite = x.iter().copied().filter(|v| v.is_finite());
            let lo = finite.clone().fold(f64::INFINITY, f64::min);
            let hi = finite.fold(f64::NEG_INFINITY, f64::max);
            let span = hi - lo;
            (0..nv)
                .map(|v| match x.get(v) {
                    Some(&d) if d.is_finite() => {
                        Colormap::Viridis.at(if span > 0.0 { (d - lo) / span } else { 0.0 })
                    }
                    _ => NO_VALUE,
                })
                .collect()
        }
        VertexProperty::I32(_, x) => (0..nv)
            .map(|v| match x.get(v) {
                Some(&l) if l >= 0 => label_colour(i64::from(l)),
                _ => NO_VALUE,
            })
            .collect(),
    }
}

/// Little-endian bytes of `f32` values.
fn f32_bytes(values: impl Iterator<Item = f32>) -> Vec<u8> {
    values.flat_map(f32::to_le_bytes).collect()
}

/// The mesh as a GLB file (see the [module](self) docs for the layout).
/// Properties shorter than the vertex count are padded with NaN / -1.
///
/// # Examples
///
/// ```
/// use geodex::io::mesh::glb::write_glb;
/// use geodex::numerics::mesh::TriMesh;
/// let mesh = TriMesh::new(
///     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///     vec![[0, 1, 2]],
/// )?;
/// let glb = write_glb(&mesh, &[]);
/// assert_eq!(&glb[..4], b"glTF");
/// assert_eq!(glb.len() % 4, 0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_glb(mesh: &TriMesh, props: &[VertexProperty<'_>]) -> Vec<u8> {
    let nv = mesh.num_vertices();
    let positions = mesh.positions();
    let mut b = Builder {
        bin: Vec::new(),
        views: Vec::new(),
        accessors: Vec::new(),
    };
    // The bounds of the f32 values actually written.
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in positions {
        for k in 0..3 {
            let c = p[k] as f32;
            lo[k] = lo[k].min(c);
            hi[k] = hi[k].max(c);
        }
    }
    let mut attributes = serde_json::Map::new();
    let pos = b.push(
        &f32_bytes(positions.iter().flat_map(|p| p.map(|c| c as f32))),
        ARRAY_BUFFER,
        serde_json::json!({
            "componentType": FLOAT, "count": nv, "type": "VEC3", "min": lo, "max": hi,
        }),
    );
    attributes.insert("POSITION".into(), pos.into());
    let normals = vertex_normals(mesh);
    let nor = b.push(
        &f32_bytes(normals.iter().flat_map(|n| n.map(|c| c as f32))),
        ARRAY_BUFFER,
        serde_json::json!({"componentType": FLOAT, "count": nv, "type": "VEC3"}),
    );
    attributes.insert("NORMAL".into(), nor.into());
    if let Some(first) = props.first() {
        let rgba: Vec<u8> = colours(first, nv)
            .into_iter()
            .flat_map(|[r, g, b]| [r, g, b, 255])
            .collect();
        let col = b.push(
            &rgba,
            ARRAY_BUFFER,
            serde_json::json!({
                "componentType": UNSIGNED_BYTE, "normalized": true, "count": nv, "type": "VEC4",
            }),
        );
        attributes.insert("COLOR_0".into(), col.into());
    }
    for prop in props {
        let (name, values): (&str, Vec<f32>) = match prop {
            VertexProperty::F64(name, x) => (
                name,
                (0..nv)
                    .map(|v| x.get(v).copied().unwrap_or(f64::NAN) as f32)
                    .collect(),
            ),
            VertexProperty::I32(name, x) => (
                name,
                (0..nv)
                    .map(|v| x.get(v).copied().unwrap_or(-1) as f32)
                    .collect(),
            ),
        };
        let acc = b.push(
            &f32_bytes(values.into_iter()),
            ARRAY_BUFFER,
            serde_json::json!({"componentType": FLOAT, "count": nv, "type": "SCALAR"}),
        );
        attributes.insert(format!("_{}", name.to_ascii_uppercase()), acc.into());
    }
    let mut primitive = serde_json::json!({ "attributes": attributes, "mode": 4 });
    if mesh.num_faces() > 0 {
        let idx = b.push(
            &mesh
                .faces()
                .iter()
                .flatten()
                .flat_map(|i| i.to_le_bytes())
                .collect::<Vec<u8>>(),
            ELEMENT_ARRAY_BUFFER,
            serde_json::json!({
                "componentType": UNSIGNED_INT, "count": 3 * mesh.num_faces(), "type": "SCALAR",
            }),
        );
        primitive["indices"] = idx.into();
    } else {
        // Points: a triangle primitive needs at least one face.
        primitive["mode"] = 0.into();
    }
    while !b.bin.len().is_multiple_of(4) {
        b.bin.push(0);
    }
    let document = serde_json::json!({
        "asset": {"version": "2.0", "generator": "geodex"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [primitive]}],
        "buffers": [{"byteLength": b.bin.len()}],
        "bufferViews": b.views,
        "accessors": b.accessors,
    });
    // Serialising a `Value` of numbers and strings cannot fail.
    let mut json = serde_json::to_vec(&document).unwrap_or_default();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + b.bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(b.bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b.bin);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> TriMesh {
        TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [2.0, 1.0, 0.5],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap()
    }

    /// Reads the file back with the `gltf` crate (an independent reader
    /// that validates the document) and compares every attribute.
    #[test]
    fn reads_back_with_an_independent_reader() {
        let mesh = square();
        let d = [0.0, 2.0, f64::INFINITY, 1.0];
        let l = [0, 1, -1, 3];
        let glb = write_glb(
            &mesh,
            &[
                VertexProperty::F64("distance", &d),
                VertexProperty::I32("label", &l),
            ],
        );
        let gltf = gltf::Gltf::from_slice(&glb).expect("valid GLB");
        let blob = gltf.blob.as_deref().expect("binary chunk");
        let doc = &gltf.document;
        let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
        assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
        let reader = prim.reader(|_| Some(blob));
        let p: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        assert_eq!(p.len(), 4);
        assert_eq!(p[2], [2.0, 1.0, 0.5]);
        let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        assert_eq!(idx, vec![0, 1, 2, 0, 2, 3]);
        for n in reader.read_normals().unwrap() {
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-6 && n[2] > 0.0, "{n:?}");
        }
        let c: Vec<[u8; 4]> = reader
            .read_colors(0)
            .unwrap()
            .into_rgba_u8()
            .collect::<Vec<_>>();
        assert_eq!(c[0][..3], Colormap::Viridis.at(0.0));
        assert_eq!(c[1][..3], Colormap::Viridis.at(1.0));
        assert_eq!(c[2][..3], NO_VALUE);
        // The custom attributes, read from their accessors' views.
        let custom = |name: &str| -> Vec<f32> {
            let (_, acc) = prim
                .attributes()
                .find(|(s, _)| s.to_string() == name)
                .unwrap_or_else(|| panic!("{name} missing"));
            let view = acc.view().unwrap();
            let bytes = &blob[view.offset()..view.offset() + view.length()];
            bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        };
        let dist = custom("_DISTANCE");
        assert_eq!(dist[..2], [0.0, 2.0]);
        assert!(dist[2].is_infinite());
        assert_eq!(custom("_LABEL"), vec![0.0, 1.0, -1.0, 3.0]);
        // Bounds as the format requires.
        let pos = prim.get(&gltf::Semantic::Positions).unwrap();
        assert_eq!(pos.min().unwrap(), serde_json::json!([0.0, 0.0, 0.0]));
        assert_eq!(pos.max().unwrap(), serde_json::json!([2.0, 1.0, 0.5]));
    }

    #[test]
    fn chunks_are_aligned_and_lengths_add_up() {
        let glb = write_glb(&square(), &[]);
        let word = |at: usize| u32::from_le_bytes([glb[at], glb[at + 1], glb[at + 2], glb[at + 3]]);
        assert_eq!(word(8) as usize, glb.len());
        let json_len = word(12) as usize;
        assert_eq!(json_len % 4, 0);
        assert_eq!(&glb[16..20], b"JSON");
        let bin_at = 20 + json_len;
        assert_eq!(&glb[bin_at + 4..bin_at + 8], b"BIN\0");
        assert_eq!(bin_at + 8 + word(bin_at) as usize, glb.len());
    }
}
