//! PLY (ASCII, binary little and big endian): the `vertex` element's
//! `x y z` (any numeric type) and the `face` element's `vertex_indices` (or
//! `vertex_index`) list. Other elements and properties are read and
//! ignored. The header is parsed first (by `ply-rs-bw`) and its element
//! counts are checked against the limits before the payload is read; a
//! binary payload is read by `ply-rs-bw`, an ASCII one here (`ascii`).

use std::io::{BufReader, Cursor, Seek};

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{Encoding, Header, Property, PropertyAccess, PropertyType, ScalarType};

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

/// A record of an element the mesh does not use: read, then dropped (a
/// zero-sized type, so reading a million of them allocates nothing).
struct Skipped;

impl PropertyAccess for Skipped {
    fn new() -> Self {
        Skipped
    }

    fn set_property(&mut self, _name: &str, _p: Property) {}
}

/// The bytes of one binary value of `t`.
fn scalar_bytes(t: &ScalarType) -> usize {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// Refuses a header whose element counts cannot fit in `payload`, the
/// bytes after it, before any record is read: a binary record takes at
/// least its scalars and the length of each list (lists may be empty), an
/// ASCII record one line (binary records of no property take no bytes and
/// are not read). Without this, a 200-byte file declaring 10^12
/// records of an element with no properties (zero bytes each) kept the
/// reader looping, and allocating a record per turn, until memory ran out.
fn check_counts(header: &Header, payload: &[u8]) -> Result<(), MeshIoError> {
    let binary = !matches!(header.encoding, Encoding::Ascii);
    let (available, unit) = if binary {
        (payload.len(), "bytes")
    } else {
        let newlines = payload.iter().filter(|&&b| b == b'\n').count();
        let open_line = payload.last().is_some_and(|&b| b != b'\n');
        (newlines + usize::from(open_line), "lines")
    };
    let mut needed = 0usize;
    for (name, def) in &header.elements {
        if name == "face"
            && def.count > 0
            && !def.properties.contains_key("vertex_indices")
            && !def.properties.contains_key("vertex_index")
        {
            return Err(MeshIoError::corrupt(
                F,
                None,
                "face has no 'vertex_indices' property",
            ));
        }
        if binary && def.properties.is_empty() {
            // Its records take no bytes: none is read.
            continue;
        }
        let per_record = if binary {
            def.properties
                .values()
                .map(|p| match &p.data_type {
                    PropertyType::Scalar(t) | PropertyType::List(t, _) => scalar_bytes(t),
                })
                .sum()
        } else {
            1
        };
        needed = def
            .count
            .checked_mul(per_record)
            .and_then(|n| n.checked_add(needed))
            .filter(|&n| n <= available)
            .ok_or_else(|| {
                MeshIoError::corrupt(
                    F,
                    None,
                    format!(
                        "element '{name}' declares {} records, more than the {available} {unit} \
                         after the header can hold",
                        def.count
                    ),
                )
            })?;
    }
    Ok(())
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
    let start = reader
        .stream_position()
        .map_or(bytes.len(), |p| usize::try_from(p).unwrap_or(usize::MAX));
    check_counts(&header, bytes.get(start..).unwrap_or_default())?;
    let mut raw = RawMesh::default();
    let mut values = VertexValues::default();
    let binary = !matches!(header.encoding, Encoding::Ascii);
    if !binary {
        let body = bytes.get(start..).unwrap_or_default();
        let first_line = bytes[..start.min(bytes.len())]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1;
        ascii::read_body(&header, body, first_line, &mut raw, &mut values, limits)?;
        return Ok((raw, values));
    }
    let skipper = Parser::<Skipped>::new();
    for (name, def) in &header.elements {
        let element_error =
            |e: std::io::Error| MeshIoError::corrupt(F, None, format!("element '{name}': {e}"));
        if name != "vertex" && name != "face" {
            // Read past it (it may hold lists) without keeping its records.
            if def.count > 0 && !(binary && def.properties.is_empty()) {
                skipper
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(element_error)?;
            }
            continue;
        }
        let recs = parser
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(element_error)?;
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

/// The ASCII body, read here rather than by ply-rs (which builds a map of
/// properties per record: 0.45 s of the 0.7 s it took to read the
/// 437,645-vertex Stanford dragon). Same rules: one record per line, its
/// values in the order of the element's properties, each parsed as its
/// declared type (a list as its length, then its items), values after the
/// last property ignored.
mod ascii {
    use ply_rs_bw::ply::{Header, PropertyType, ScalarType};

    use super::{MeshIoError, MeshLimits, RawMesh, VertexValues, F};

    /// What a property of the `vertex` or `face` element is for.
    #[derive(Clone, Copy, PartialEq)]
    enum Role {
        Coordinate(usize),
        Distance,
        Label,
        Value,
        Indices,
        Ignored,
    }

    /// One value of type `t` (integers as integers: `1.5` is no `int`).
    fn scalar(t: &ScalarType, s: &str) -> Option<f64> {
        Some(match t {
            ScalarType::Char => s.parse::<i8>().ok()?.into(),
            ScalarType::UChar => s.parse::<u8>().ok()?.into(),
            ScalarType::Short => s.parse::<i16>().ok()?.into(),
            ScalarType::UShort => s.parse::<u16>().ok()?.into(),
            ScalarType::Int => s.parse::<i32>().ok()?.into(),
            ScalarType::UInt => s.parse::<u32>().ok()?.into(),
            ScalarType::Float => s.parse::<f32>().ok()?.into(),
            ScalarType::Double => s.parse::<f64>().ok()?,
        })
    }

    /// One integer list item of type `t` (`None` for a float list or a bad
    /// value); every integer type is exact in `f64`.
    fn index(t: &ScalarType, s: &str) -> Option<i64> {
        match t {
            ScalarType::Float | ScalarType::Double => None,
            _ => scalar(t, s).map(|v| v as i64),
        }
    }

    pub(super) fn read_body(
        header: &Header,
        body: &[u8],
        first_line: usize,
        raw: &mut RawMesh,
        values: &mut VertexValues,
        limits: &MeshLimits,
    ) -> Result<(), MeshIoError> {
        let mut lines = body.split(|&b| b == b'\n');
        let mut line_no = first_line - 1;
        let mut indices: Vec<i64> = Vec::with_capacity(8);
        for (name, def) in &header.elements {
            let element = name.as_str();
            let roles: Vec<(Role, &PropertyType)> = def
                .properties
                .iter()
                .map(|(p, d)| {
                    let role = match (element, p.as_str()) {
                        ("vertex", "x") => Role::Coordinate(0),
                        ("vertex", "y") => Role::Coordinate(1),
                        ("vertex", "z") => Role::Coordinate(2),
                        ("vertex", "distance") => Role::Distance,
                        ("vertex", "label") => Role::Label,
                        ("vertex", "value") => Role::Value,
                        ("face", "vertex_indices" | "vertex_index") => Role::Indices,
                        _ => Role::Ignored,
                    };
                    (role, &d.data_type)
                })
                .collect();
            let has = |r: Role| roles.iter().any(|(x, _)| *x == r);
            if element == "vertex" {
                raw.positions.reserve_exact(def.count);
                if has(Role::Distance) {
                    values.distance = Some(Vec::with_capacity(def.count));
                }
                if has(Role::Label) {
                    values.label = Some(Vec::with_capacity(def.count));
                }
                if has(Role::Value) {
                    values.value = Some(Vec::with_capacity(def.count));
                }
            }
            for i in 0..def.count {
                line_no += 1;
                let corrupt = |reason: String| {
                    MeshIoError::corrupt(F, Some(line_no), format!("element '{element}': {reason}"))
                };
                let line = lines.next().ok_or_else(|| {
                    corrupt(format!(
                        "the file ends after {i} of its {} records",
                        def.count
                    ))
                })?;
                let line = std::str::from_utf8(line)
                    .map_err(|_| corrupt("a record that is not text".into()))?;
                let mut tokens = line.split_ascii_whitespace();
                let mut next = |what: &str| {
                    tokens
                        .next()
                        .ok_or_else(|| corrupt(format!("the record ends before {what}")))
                };
                let (mut xyz, mut distance, mut label, mut value) =
                    ([0.0; 3], f64::NAN, -1.0, f64::NAN);
                indices.clear();
                for (role, ty) in &roles {
                    match ty {
                        PropertyType::Scalar(t) => {
                            let s = next("a value")?;
                            let v = scalar(t, s)
                                .ok_or_else(|| corrupt(format!("'{s}' is not a {t:?}")))?;
                            match role {
                                Role::Coordinate(k) => xyz[*k] = v,
                                Role::Distance => distance = v,
                                Role::Label => label = v,
                                Role::Value => value = v,
                                Role::Indices => {
                                    return Err(corrupt(
                                        "vertex_indices must be an integer list".into(),
                                    ))
                                }
                                Role::Ignored => {}
                            }
                        }
                        PropertyType::List(_, t) => {
                            let s = next("a list length")?;
                            let len: usize = s
                                .parse()
                                .map_err(|_| corrupt(format!("'{s}' is not a list length")))?;
                            match role {
                                Role::Indices => {
                                    for _ in 0..len {
                                        let s = next("the end of its list")?;
                                        indices.push(index(t, s).ok_or_else(|| {
                                            corrupt("vertex_indices must be an integer list".into())
                                        })?);
                                    }
                                }
                                Role::Coordinate(_) => {
                                    return Err(corrupt(
                                        "vertex coordinates must be scalars".into(),
                                    ))
                                }
                                _ => {
                                    for _ in 0..len {
                                        let s = next("the end of its list")?;
                                        scalar(t, s).ok_or_else(|| {
                                            corrupt(format!("'{s}' is not a {t:?}"))
                                        })?;
                                    }
                                }
                            }
                        }
                    }
                }
                match element {
                    "vertex" => {
                        raw.positions.push(xyz);
                        if let Some(d) = values.distance.as_mut() {
                            d.push(distance);
                        }
                        if let Some(l) = values.label.as_mut() {
                            l.push(label as i32);
                        }
                        if let Some(v) = values.value.as_mut() {
                            v.push(value);
                        }
                    }
                    "face" => raw.push_polygon(F, Some(line_no), &indices, limits)?,
                    _ => {}
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A binary little-endian triangle, with `extra` header lines after the
    /// face element and `tail` bytes after its payload.
    fn triangle(extra: &str, tail: &[u8]) -> Vec<u8> {
        let mut out = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
             property float y\nproperty float z\nelement face 1\n\
             property list uchar int vertex_indices\n{extra}end_header\n"
        )
        .into_bytes();
        for v in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
            for c in v {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        out.push(3);
        for i in [0i32, 1, 2] {
            out.extend_from_slice(&i.to_le_bytes());
        }
        out.extend_from_slice(tail);
        out
    }

    #[test]
    fn reads_a_binary_triangle() {
        let raw = read(&triangle("", b""), &MeshLimits::default()).unwrap();
        assert_eq!(raw.positions.len(), 3);
        assert_eq!(raw.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn elements_of_no_property_take_no_time_or_memory() {
        // 10^12 records of zero bytes: read one by one, they looped and
        // allocated until memory ran out.
        let bytes = triangle("element junk 1000000000000\n", b"");
        let raw = read(&bytes, &MeshLimits::default()).unwrap();
        assert_eq!(raw.triangles.len(), 1);
    }

    #[test]
    fn unknown_elements_are_skipped_lists_and_all() {
        let mut tail = Vec::new();
        for n in [2u8, 0, 1] {
            tail.push(n);
            tail.extend(std::iter::repeat_n(7u8, usize::from(n) * 2));
        }
        let bytes = triangle("element edge 3\nproperty list uchar short ends\n", &tail);
        let raw = read(&bytes, &MeshLimits::default()).unwrap();
        assert_eq!(raw.triangles.len(), 1);
    }

    #[test]
    fn counts_that_cannot_fit_in_the_file_are_refused_before_reading() {
        let cases = [
            triangle("element junk 1000000000\nproperty int a\n", b"1234"),
            triangle(
                "element junk 18446744073709551615\nproperty double a\n",
                b"",
            ),
            b"ply\nformat binary_big_endian 1.0\nelement vertex 1000000\nproperty double x\n\
              property double y\nproperty double z\nend_header\n0123456789abcdef01234567"
                .to_vec(),
            b"ply\nformat ascii 1.0\nelement vertex 1000000\nproperty float x\n\
              property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
                .to_vec(),
        ];
        for bytes in cases {
            match read(&bytes, &MeshLimits::default()) {
                Err(MeshIoError::Corrupt { reason, .. }) => {
                    assert!(reason.contains("more than the"), "{reason}")
                }
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn a_face_element_without_indices_is_refused() {
        let bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n\
              property float y\nproperty float z\nelement face 10\nend_header\n";
        match read(bytes, &MeshLimits::default()) {
            Err(MeshIoError::Corrupt { reason, .. }) => assert!(reason.contains("vertex_indices")),
            other => panic!("{other:?}"),
        }
    }

    /// The ASCII body: values in the order of the header's properties,
    /// each of its declared type, lists and unknown elements skipped, the
    /// per-vertex values kept, and a bad value named with its line.
    #[test]
    fn reads_an_ascii_body_property_by_property() {
        let text = "ply\nformat ascii 1.0\ncomment made by hand\n\
            element vertex 4\nproperty float x\nproperty list uchar int junk\n\
            property double y\nproperty float z\nproperty float distance\nproperty int label\n\
            element face 2\nproperty uchar flags\nproperty list uchar int vertex_indices\n\
            element edge 1\nproperty list uchar float w\nend_header\n\
            0 2 7 7 0 0 0.0 1\n1 0 0 0 1.5 1\n0 1 9 1 0 2.5 2\n1 0 1 1 3 2\n\
            0 3 0 1 2\n\
            1 3 1 3 2 extra values ignored\r\n\
            2 0.5 0.25\n";
        let (raw, values) = parse(text.as_bytes(), &MeshLimits::default()).expect("ascii");
        assert_eq!(
            raw.positions,
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 1.0]
            ]
        );
        assert_eq!(raw.triangles, vec![[0, 1, 2], [1, 3, 2]]);
        assert_eq!(values.distance, Some(vec![0.0, 1.5, 2.5, 3.0]));
        assert_eq!(values.label, Some(vec![1, 1, 2, 2]));
        assert_eq!(values.value, None);

        let bad = text.replace("1 0 0 0 1.5 1\n", "1 0 0 0 1.5 1.5\n");
        let e = parse(bad.as_bytes(), &MeshLimits::default()).expect_err("1.5 is no int");
        let msg = e.to_string();
        assert!(
            msg.contains("'1.5' is not a Int") && msg.contains("18"),
            "{msg}"
        );
        let short = text.replace("0 3 0 1 2\n", "0 3 0 1\n");
        let msg = parse(short.as_bytes(), &MeshLimits::default())
            .expect_err("short list")
            .to_string();
        assert!(
            msg.contains("the record ends before the end of its list"),
            "{msg}"
        );
        let blank = text.replace("2 0.5 0.25\n", "\n\n");
        let msg = parse(blank.as_bytes(), &MeshLimits::default())
            .expect_err("blank record")
            .to_string();
        assert!(
            msg.contains("element 'edge'") && msg.contains("23"),
            "{msg}"
        );
    }
}
