//! PLY (ASCII, binary little and big endian) through `ply-rs-bw`: the
//! `vertex` element's `x y z` (any numeric type) and the `face` element's
//! `vertex_indices` (or `vertex_index`) list. Other elements and properties
//! are read and ignored. The header is parsed first and its element counts
//! are checked against the limits before the payload is read.

use std::io::{BufReader, Cursor};

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{Property, PropertyAccess};

use super::{MeshFormat, MeshIoError, MeshLimits, RawMesh};

const F: MeshFormat = MeshFormat::Ply;

/// One PLY element, keeping only what a mesh needs.
#[derive(Debug, Default)]
struct Record {
    xyz: [f64; 3],
    indices: Vec<i64>,
    distance: Option<f64>,
    label: Option<f64>,
    value: Option<f64>,
    bad: bool,
}

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(x) => x.into(),
        Property::UChar(x) => x.into(),
        Property::Short(x) => x.into(),
        Property::UShort(x) => x.into(),
        Property::Int(x) => x.into(),
        Property::UInt(x) => x.into(),
        Property::Float(x) => x.into(),
        Property::Double(x) => x,
        _ => return None,
    })
}

fn list(p: Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
        Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
        Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
        Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
        Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
        Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
        _ => return None,
    })
}

impl PropertyAccess for Record {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, p: Property) {
        match name {
            "x" | "y" | "z" => {
                let k = usize::from(name == "y") + 2 * usize::from(name == "z");
                match scalar(&p) {
                    Some(v) => self.xyz[k] = v,
                    None => self.bad = true,
                }
            }
            "distance" => self.distance = scalar(&p),
            "label" => self.label = scalar(&p),
            "value" => self.value = scalar(&p),
            "vertex_indices" | "vertex_index" => match list(p) {
                Some(v) => self.indices = v,
                None => self.bad = true,
            },
            _ => {}
        }
    }
}

/// Per-vertex `distance` and `label` properties of a PLY file (results
/// written by geodex), when present.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VertexValues {
    /// The `distance` property.
    pub distance: Option<Vec<f64>>,
    /// The `label` property.
    pub label: Option<Vec<i32>>,
    /// The `value` property (an image mesh's value per vertex).
    pub value: Option<Vec<f64>>,
}

/// Reads the per-vertex `distance`, `label` and `value` of a PLY file.
pub fn vertex_values(bytes: &[u8]) -> Result<VertexValues, MeshIoError> {
    Ok(parse(bytes, &MeshLimits::default())?.1)
}

pub(crate) fn read(bytes: &[u8], limits: &MeshLimits) -> Result<RawMesh, MeshIoError> {
    Ok(parse(bytes, limits)?.0)
}

fn parse(bytes: &[u8], limits: &MeshLimits) -> Result<(RawMesh, VertexValues), MeshIoError> {
    let mut reader = BufReader::new(Cursor::new(bytes));
    let parser = Parser::<Record>::new();
    let header = parser
        .read_header(&mut reader)
        .map_err(|e| MeshIoError::corrupt(F, None, format!("header: {e}")))?;
    let count = |name: &str| header.elements.get(name).map_or(0, |e| e.count);
    let (nv, nf) = (count("vertex"), count("face"));
    limits.check(F, nv as u64, nf as u64)?;
    // Binary payloads need at least 12 bytes per vertex, 1 per face.
    if nv.saturating_mul(3) > bytes.len() || nf > bytes.len() {
        return Err(MeshIoError::corrupt(
            F,
            None,
            format!(
                "declares {nv} vertices and {nf} faces in a {}-byte file",
                bytes.len()
            ),
        ));
    }
    let vdef = header
        .elements
        .get("vertex")
        .ok_or_else(|| MeshIoError::corrupt(F, None, "no 'vertex' element"))?;
    for p in ["x", "y", "z"] {
        if !vdef.properties.contains_key(p) {
            return Err(MeshIoError::corrupt(
                F,
                None,
                format!("vertex has no '{p}' property"),
            ));
        }
    }
    let mut raw = RawMesh::default();
    let mut values = VertexValues::default();
    for (name, def) in &header.elements {
        let recs = parser
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(|e| MeshIoError::corrupt(F, None, format!("element '{name}': {e}")))?;
        match name.as_str() {
            "vertex" => {
                raw.positions.reserve_exact(recs.len());
                for r in &recs {
                    if r.bad {
                        return Err(MeshIoError::corrupt(
                            F,
                            None,
                            "vertex coordinates must be scalars",
                        ));
                    }
                    raw.positions.push(r.xyz);
                }
                if vdef.properties.contains_key("distance") {
                    values.distance = Some(
                        recs.iter()
                            .map(|r| r.distance.unwrap_or(f64::NAN))
                            .collect(),
                    );
                }
                if vdef.properties.contains_key("value") {
                    values.value = Some(recs.iter().map(|r| r.value.unwrap_or(f64::NAN)).collect());
                }
                if vdef.properties.contains_key("label") {
                    values.label = Some(
                        recs.iter()
                            .map(|r| r.label.unwrap_or(-1.0) as i32)
                            .collect(),
                    );
                }
            }
            "face" => {
                for r in recs {
                    if r.bad {
                        return Err(MeshIoError::corrupt(
                            F,
                            None,
                            "vertex_indices must be an integer list",
                        ));
                    }
                    raw.push_polygon(F, None, &r.indices, limits)?;
                }
            }
            _ => {}
        }
    }
    Ok((raw, values))
}
