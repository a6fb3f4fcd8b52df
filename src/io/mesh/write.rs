//! Mesh writers: binary little-endian PLY with per-vertex `double` and `int`
//! properties (distance, label), Wavefront OBJ (geometry), and JSON.

use std::fmt::Write as _;

use crate::numerics::mesh::TriMesh;

/// A per-vertex property to write.
#[derive(Debug, Clone, Copy)]
pub enum VertexProperty<'a> {
    /// A `double` property (`+inf` is written as is; JSON writes `null`).
    F64(&'a str, &'a [f64]),
    /// An `int` property.
    I32(&'a str, &'a [i32]),
}

impl VertexProperty<'_> {
    fn name(&self) -> &str {
        match self {
            VertexProperty::F64(n, _) | VertexProperty::I32(n, _) => n,
        }
    }
}

/// Binary little-endian PLY: `x y z` as `double`, then each property, then
/// faces as `uchar` count + `int` indices. Properties shorter than the
/// vertex count are padded with NaN / -1.
pub fn write_ply(mesh: &TriMesh, props: &[VertexProperty<'_>]) -> Vec<u8> {
    let nv = mesh.num_vertices();
    let mut head =
        String::from("ply\nformat binary_little_endian 1.0\ncomment written by geodex\n");
    let _ = writeln!(head, "element vertex {nv}");
    head.push_str("property double x\nproperty double y\nproperty double z\n");
    for p in props {
        let ty = match p {
            VertexProperty::F64(..) => "double",
            VertexProperty::I32(..) => "int",
        };
        let _ = writeln!(head, "property {ty} {}", p.name());
    }
    let _ = writeln!(head, "element face {}", mesh.num_faces());
    head.push_str("property list uchar int vertex_indices\nend_header\n");
    let row = 24
        + props
            .iter()
            .map(|p| match p {
                VertexProperty::F64(..) => 8,
                VertexProperty::I32(..) => 4,
            })
            .sum::<usize>();
    let mut out = Vec::with_capacity(head.len() + nv * row + 13 * mesh.num_faces());
    out.extend_from_slice(head.as_bytes());
    for (v, p) in mesh.positions().iter().enumerate() {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
        for prop in props {
            match prop {
                VertexProperty::F64(_, x) => {
                    out.extend_from_slice(&x.get(v).copied().unwrap_or(f64::NAN).to_le_bytes())
                }
                VertexProperty::I32(_, x) => {
                    out.extend_from_slice(&x.get(v).copied().unwrap_or(-1).to_le_bytes())
                }
            }
        }
    }
    for f in mesh.faces() {
        out.push(3);
        for &i in f {
            out.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    out
}

/// Wavefront OBJ: `v` and 1-based `f` records.
pub fn write_obj(mesh: &TriMesh) -> Vec<u8> {
    let mut s = String::with_capacity(40 * mesh.num_vertices() + 24 * mesh.num_faces());
    s.push_str("# written by geodex\n");
    for p in mesh.positions() {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    for f in mesh.faces() {
        let _ = writeln!(s, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    s.into_bytes()
}

/// JSON: `{"vertices": [[x, y, z], …], "faces": [[i, j, k], …],
/// "properties": {name: [...]}}`, non-finite values as `null`.
pub fn write_json(mesh: &TriMesh, props: &[VertexProperty<'_>]) -> serde_json::Value {
    let mut map = serde_json::Map::new();
    for p in props {
        let v = match p {
            VertexProperty::F64(_, x) => serde_json::Value::from(
                x.iter()
                    .map(|&d| {
                        if d.is_finite() {
                            serde_json::Value::from(d)
                        } else {
                            serde_json::Value::Null
                        }
                    })
                    .collect::<Vec<_>>(),
            ),
            VertexProperty::I32(_, x) => serde_json::Value::from(x.to_vec()),
        };
        map.insert(p.name().to_string(), v);
    }
    serde_json::json!({
        "vertices": mesh.positions(),
        "faces": mesh.faces(),
        "properties": map,
    })
}

/// The bytes of `mesh` in the format named by a file extension (`ply`,
/// the default without one, `obj`, `json` or `glb`), or why not.
pub fn encode_by_extension(
    mesh: &TriMesh,
    props: &[VertexProperty<'_>],
    path: &std::path::Path,
) -> Result<Vec<u8>, String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("ply")
        .to_ascii_lowercase();
    match ext.as_str() {
        "obj" => Ok(write_obj(mesh)),
        "json" => serde_json::to_vec(&write_json(mesh, props)).map_err(|e| e.to_string()),
        "ply" => Ok(write_ply(mesh, props)),
        "glb" => Ok(super::glb::write_glb(mesh, props)),
        other => Err(format!(
            "unknown mesh extension '.{other}': use .ply, .obj, .json or .glb"
        )),
    }
}
