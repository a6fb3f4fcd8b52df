//! NumPy `.npy` files, versions 1.0, 2.0 and 3.0.
//!
//! A file is the magic `\x93NUMPY`, a version `(major, minor)`, the length of
//! a header (u16 LE in v1, u32 LE in v2/v3), the header itself, a Python dict
//! literal such as `{'descr': '<f8', 'fortran_order': False, 'shape': (3, 4), }`,
//! and the raw elements. The header is parsed here (no `eval`): the declared
//! shape is checked against [`Limits`] and the payload length against
//! `shape × itemsize` before anything is allocated.
//!
//! Supported element types (any byte order `<`, `>`, `|`, `=`): `b1` → bool,
//! `u1` → u8, `u2` → u16, `i4` → i32, `i8` → i64, `f4` → f32, `f8` → f64, and,
//! converted losslessly, `i1`/`i2` → i32 and `u4` → i64. Fortran-ordered
//! arrays are transposed into C order. 1 to 3 axes.

use ndarray::{ArrayD, IxDyn, ShapeBuilder};

use super::{ArrayData, DType, Format, IoError, Limits};

/// The first six bytes of every `.npy` file.
pub const MAGIC: &[u8] = b"\x93NUMPY";

/// Most axes a decoded array may have (a 2D or 3D grid)...
const MAX_NDIM: usize = 3;

/// ...or one more when the last one holds the components of a symmetric
/// tensor per cell: 3 (`m11, m12, m22`, 2D) or 6 (`m11, m12, m13, m22, m23,
/// m33`, 3D). A 3D tensor field is an array of shape `(n0, n1, n2, 6)`.
fn tensor_components_axis(shape: &[usize]) -> bool {
    shape.len() == MAX_NDIM + 1 && matches!(shape[MAX_NDIM], 3 | 6)
}

fn corrupt(reason: impl Into<String>) -> IoError {
    IoError::corrupt(Format::Npy, reason)
}

fn unsupported(reason: impl Into<String>) -> IoError {
    IoError::unsupported(Format::Npy, reason)
}

/// A value of the header dict.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    Str(String),
    Bool(bool),
    Tuple(Vec<usize>),
    /// Anything else (a list for structured dtypes, `None`, ...).
    Other(String),
}

/// A tiny parser for the Python literal of an NPY header.
struct Parser<'a> {
    s: &'a [u8],
    pos: usize,
}

impl<'a> Parser<'a> {
    fn skip_ws(&mut self) {
        while self
            .s
            .get(self.pos)
            .is_some_and(|c| c.is_ascii_whitespace())
        {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_ws();
        self.s.get(self.pos).copied()
    }

    fn expect(&mut self, c: u8) -> Result<(), IoError> {
        match self.peek() {
            Some(x) if x == c => {
                self.pos += 1;
                Ok(())
            }
            other => Err(corrupt(format!(
                "header: expected '{}' at byte {} of the header, found {}",
                c as char,
                self.pos,
                other.map_or("the end".to_string(), |x| format!("'{}'", x.escape_ascii()))
            ))),
        }
    }

    fn string(&mut self) -> Result<String, IoError> {
        let quote = self.peek().filter(|&q| q == b'\'' || q == b'"');
        let quote = quote.ok_or_else(|| {
            corrupt(format!(
                "header: expected a quoted string at byte {}",
                self.pos
            ))
        })?;
        self.pos += 1;
        let start = self.pos;
        while let Some(&c) = self.s.get(self.pos) {
            if c == quote {
                let text = String::from_utf8_lossy(&self.s[start..self.pos]).into_owned();
                self.pos += 1;
                return Ok(text);
            }
            self.pos += 1;
        }
        Err(corrupt("header: unterminated string"))
    }

    fn tuple(&mut self) -> Result<Vec<usize>, IoError> {
        self.expect(b'(')?;
        let mut dims = Vec::new();
        loop {
            match self.peek() {
                Some(b')') => {
                    self.pos += 1;
                    return Ok(dims);
                }
                Some(c) if c.is_ascii_digit() => {
                    let start = self.pos;
                    while self.s.get(self.pos).is_some_and(u8::is_ascii_digit) {
                        self.pos += 1;
                    }
                    let digits = String::from_utf8_lossy(&self.s[start..self.pos]);
                    let n: usize = digits.parse().map_err(|_| {
                        corrupt(format!(
                            "header: shape entry {digits} does not fit in usize"
                        ))
                    })?;
                    // Python 2 long suffix.
                    if matches!(self.s.get(self.pos), Some(b'L' | b'l')) {
                        self.pos += 1;
                    }
                    dims.push(n);
                    match self.peek() {
                        Some(b',') => self.pos += 1,
                        Some(b')') => {}
                        _ => return Err(corrupt("header: expected ',' or ')' in 'shape'")),
                    }
                }
                Some(b'-') => return Err(corrupt("header: negative entry in 'shape'")),
                _ => return Err(corrupt("header: 'shape' must be a tuple of integers")),
            }
        }
    }

    fn value(&mut self) -> Result<Value, IoError> {
        match self.peek() {
            Some(b'\'' | b'"') => Ok(Value::Str(self.string()?)),
            Some(b'(') => Ok(Value::Tuple(self.tuple()?)),
            Some(_) => {
                // A bare word (True, False, None) or a nested literal: take it
                // up to the next top-level ',' or '}'.
                let start = self.pos;
                let mut depth = 0usize;
                while let Some(&c) = self.s.get(self.pos) {
                    match c {
                        b'[' | b'(' | b'{' => depth += 1,
                        b']' | b')' => depth = depth.saturating_sub(1),
                        b'}' if depth == 0 => break,
                        b'}' => depth -= 1,
                        b',' if depth == 0 => break,
                        _ => {}
                    }
                    self.pos += 1;
                }
                let word = String::from_utf8_lossy(&self.s[start..self.pos])
                    .trim()
                    .to_string();
                Ok(match word.as_str() {
                    "True" => Value::Bool(true),
                    "False" => Value::Bool(false),
                    _ => Value::Other(word),
                })
            }
            None => Err(corrupt("header: ends before a value")),
        }
    }

    fn dict(&mut self) -> Result<Vec<(String, Value)>, IoError> {
        self.expect(b'{')?;
        let mut entries = Vec::new();
        loop {
            if self.peek() == Some(b'}') {
                self.pos += 1;
                break;
            }
            let key = self.string()?;
            self.expect(b':')?;
            let value = self.value()?;
            entries.push((key, value));
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(b'}') => {}
                _ => return Err(corrupt("header: expected ',' or '}' after a value")),
            }
        }
        if self.peek().is_some() {
            return Err(corrupt("header: unexpected text after the closing '}'"));
        }
        Ok(entries)
    }
}

/// The element type stored in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stored {
    Bool,
    U8,
    U16,
    U32,
    I8,
    I16,
    I32,
    I64,
    F32,
    F64,
}

impl Stored {
    fn size(self) -> usize {
        match self {
            Stored::Bool | Stored::U8 | Stored::I8 => 1,
            Stored::U16 | Stored::I16 => 2,
            Stored::U32 | Stored::I32 | Stored::F32 => 4,
            Stored::I64 | Stored::F64 => 8,
        }
    }

    /// The dtype it is returned as.
    fn dtype(self) -> DType {
        match self {
            Stored::Bool => DType::Bool,
            Stored::U8 => DType::U8,
            Stored::U16 => DType::U16,
            Stored::I8 | Stored::I16 | Stored::I32 => DType::I32,
            Stored::U32 | Stored::I64 => DType::I64,
            Stored::F32 => DType::F32,
            Stored::F64 => DType::F64,
        }
    }
}

/// The parsed header.
#[derive(Debug, Clone, PartialEq)]
struct Header {
    stored: Stored,
    little_endian: bool,
    fortran_order: bool,
    shape: Vec<usize>,
}

fn parse_descr(descr: &str) -> Result<(Stored, bool), IoError> {
    let (order, code) = match descr.as_bytes().first() {
        Some(&c @ (b'<' | b'>' | b'|' | b'=')) => (c, &descr[1..]),
        _ => (b'=', descr),
    };
    let stored = match code {
        "b1" | "?" => Stored::Bool,
        "u1" | "B" => Stored::U8,
        "u2" => Stored::U16,
        "u4" => Stored::U32,
        "i1" | "b" => Stored::I8,
        "i2" => Stored::I16,
        "i4" => Stored::I32,
        "i8" => Stored::I64,
        "f4" => Stored::F32,
        "f8" => Stored::F64,
        _ => {
            return Err(unsupported(format!(
                "dtype '{descr}' (supported: b1, u1, u2, u4, i1, i2, i4, i8, f4, f8)"
            )))
        }
    };
    let little_endian = match order {
        b'<' => true,
        b'>' => false,
        b'=' => cfg!(target_endian = "little"),
        // '|': byte order not applicable, only for 1-byte types.
        _ if stored.size() == 1 => true,
        _ => {
            return Err(corrupt(format!(
                "dtype '{descr}': byte order '|' on a multi-byte type"
            )))
        }
    };
    Ok((stored, little_endian))
}

/// Splits a file into its parsed header and the payload.
fn split(bytes: &[u8]) -> Result<(Header, &[u8]), IoError> {
    if !bytes.starts_with(MAGIC) {
        return Err(corrupt("missing the magic string \\x93NUMPY"));
    }
    let (major, minor) = match bytes.get(6..8) {
        Some(&[major, minor]) => (major, minor),
        _ => return Err(corrupt("truncated before the version bytes")),
    };
    let (len_size, header_len) = match major {
        1 => match bytes.get(8..10) {
            Some(&[a, b]) => (2, usize::from(u16::from_le_bytes([a, b]))),
            _ => return Err(corrupt("truncated before the header length")),
        },
        2 | 3 => match bytes.get(8..12) {
            Some(&[a, b, c, d]) => {
                let len = u32::from_le_bytes([a, b, c, d]);
                let len = usize::try_from(len)
                    .map_err(|_| corrupt(format!("header length {len} does not fit")))?;
                (4, len)
            }
            _ => return Err(corrupt("truncated before the header length")),
        },
        _ => {
            return Err(unsupported(format!(
                "format version {major}.{minor} (supported: 1.0, 2.0, 3.0)"
            )))
        }
    };
    let start: usize = 8 + len_size;
    let end = start
        .checked_add(header_len)
        .ok_or_else(|| corrupt("header length overflows"))?;
    let text = bytes.get(start..end).ok_or_else(|| {
        corrupt(format!(
            "header declares {header_len} bytes but the file has only {} after the preamble",
            bytes.len().saturating_sub(start)
        ))
    })?;
    let entries = Parser { s: text, pos: 0 }.dict()?;
    let find = |key: &str| {
        entries
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v)
            .ok_or_else(|| corrupt(format!("header: missing key '{key}'")))
    };
    let (stored, little_endian) = match find("descr")? {
        Value::Str(descr) => parse_descr(descr)?,
        other => {
            return Err(unsupported(format!(
                "structured or non-string dtype {other:?} in 'descr'"
            )))
        }
    };
    let fortran_order = match find("fortran_order")? {
        Value::Bool(b) => *b,
        other => {
            return Err(corrupt(format!(
                "header: 'fortran_order' must be True or False, got {other:?}"
            )))
        }
    };
    let shape = match find("shape")? {
        Value::Tuple(shape) => shape.clone(),
        other => {
            return Err(corrupt(format!(
                "header: 'shape' must be a tuple, got {other:?}"
            )))
        }
    };
    let header = Header {
        stored,
        little_endian,
        fortran_order,
        shape,
    };
    Ok((header, &bytes[end..]))
}

/// Reads `N`-byte elements, little (`little`) or big endian, with `from`
/// taking the little-endian bytes.
pub(crate) fn elems<T, const N: usize>(
    payload: &[u8],
    little: bool,
    from: impl Fn([u8; N]) -> T,
) -> Vec<T> {
    payload
        .chunks_exact(N)
        .map(|chunk| {
            let mut b = [0u8; N];
            // `chunks_exact` yields exactly N bytes.
            b.copy_from_slice(chunk);
            if !little {
                b.reverse();
            }
            from(b)
        })
        .collect()
}

fn shaped<T>(data: Vec<T>, shape: &[usize], fortran: bool) -> Result<ArrayD<T>, IoError>
where
    T: Clone,
{
    let dim = IxDyn(shape);
    let array = if fortran {
        ArrayD::from_shape_vec(dim.f(), data).map(|a| a.as_standard_layout().into_owned())
    } else {
        ArrayD::from_shape_vec(dim, data)
    };
    array.map_err(|e| corrupt(format!("payload does not match shape {shape:?}: {e}")))
}

/// Decodes a `.npy` file.
pub(crate) fn decode(bytes: &[u8], limits: &Limits) -> Result<ArrayData, IoError> {
    let (header, payload) = split(bytes)?;
    let shape = &header.shape;
    if shape.is_empty() {
        return Err(unsupported(
            "0-dimensional array (a scalar); 1 to 3 axes are supported",
        ));
    }
    if shape.len() > MAX_NDIM && !tensor_components_axis(shape) {
        return Err(unsupported(format!(
            "{} axes (shape {shape:?}); 1 to {MAX_NDIM} are supported, or 4 with a trailing tensor axis of 3 or 6 components",
            shape.len()
        )));
    }
    limits.check("NPY array", shape, header.stored.dtype().size())?;
    // Cannot overflow: checked against max_bytes just above, and stored
    // sizes never exceed returned sizes.
    let cells: usize = shape.iter().product();
    let expected = cells * header.stored.size();
    if payload.len() != expected {
        let what = if payload.len() < expected {
            "truncated"
        } else {
            "trailing bytes"
        };
        return Err(corrupt(format!(
            "{what}: the header declares shape {shape:?} of {}-byte elements = {expected} \
             payload bytes, but the file holds {}",
            header.stored.size(),
            payload.len()
        )));
    }
    let le = header.little_endian;
    let f = header.fortran_order;
    Ok(match header.stored {
        Stored::Bool => ArrayData::Bool(shaped(elems(payload, le, |[b]| b != 0), shape, f)?),
        Stored::U8 => ArrayData::U8(shaped(payload.to_vec(), shape, f)?),
        Stored::U16 => ArrayData::U16(shaped(elems(payload, le, u16::from_le_bytes), shape, f)?),
        Stored::U32 => ArrayData::I64(shaped(
            elems(payload, le, |b| i64::from(u32::from_le_bytes(b))),
            shape,
            f,
        )?),
        Stored::I8 => ArrayData::I32(shaped(
            elems(payload, le, |b| i32::from(i8::from_le_bytes(b))),
            shape,
            f,
        )?),
        Stored::I16 => ArrayData::I32(shaped(
            elems(payload, le, |b| i32::from(i16::from_le_bytes(b))),
            shape,
            f,
        )?),
        Stored::I32 => ArrayData::I32(shaped(elems(payload, le, i32::from_le_bytes), shape, f)?),
        Stored::I64 => ArrayData::I64(shaped(elems(payload, le, i64::from_le_bytes), shape, f)?),
        Stored::F32 => ArrayData::F32(shaped(elems(payload, le, f32::from_le_bytes), shape, f)?),
        Stored::F64 => ArrayData::F64(shaped(elems(payload, le, f64::from_le_bytes), shape, f)?),
    })
}

/// The NPY `descr` of a dtype, little endian.
fn descr(dtype: DType) -> &'static str {
    match dtype {
        DType::Bool => "|b1",
        DType::U8 => "|u1",
        DType::U16 => "<u2",
        DType::I32 => "<i4",
        DType::I64 => "<i8",
        DType::F32 => "<f4",
        DType::F64 => "<f8",
    }
}

/// Encodes an array as NPY: format 1.0 (2.0 if the header would exceed
/// 65535 bytes), little endian, C order, any dtype and any number of axes.
/// The preamble plus header is padded with spaces and a final `\n` to a
/// multiple of 64 bytes, as NumPy does.
///
/// # Examples
///
/// ```
/// use geodex::io::{encode_npy, ArrayData};
/// let a = ArrayData::U8(ndarray::ArrayD::zeros(vec![2, 2]));
/// let bytes = encode_npy(&a)?;
/// assert!(bytes.starts_with(b"\x93NUMPY\x01\x00"));
/// assert_eq!(bytes.len(), 128 + 4); // preamble + header padded to 64 bytes, then 4 elements
/// # Ok::<(), geodex::io::IoError>(())
/// ```
pub fn encode_npy(array: &ArrayData) -> Result<Vec<u8>, IoError> {
    let shape = array.shape();
    let dims: Vec<String> = shape.iter().map(usize::to_string).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {shape_text}, }}",
        descr(array.dtype())
    );
    let v1 = header.len() + 1 + 10 <= usize::from(u16::MAX);
    let preamble = if v1 { 10 } else { 12 };
    let total = (preamble + header.len() + 1).div_ceil(64) * 64;
    while preamble + header.len() + 1 < total {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(total + array.nbytes());
    out.extend_from_slice(MAGIC);
    if v1 {
        out.extend_from_slice(&[1, 0]);
        let len = u16::try_from(header.len())
            .map_err(|_| IoError::Encode("NPY header too long".into()))?;
        out.extend_from_slice(&len.to_le_bytes());
    } else {
        out.extend_from_slice(&[2, 0]);
        let len = u32::try_from(header.len())
            .map_err(|_| IoError::Encode("NPY header too long".into()))?;
        out.extend_from_slice(&len.to_le_bytes());
    }
    out.extend_from_slice(header.as_bytes());
    match array {
        ArrayData::Bool(a) => out.extend(a.iter().map(|&v| u8::from(v))),
        ArrayData::U8(a) => out.extend(a.iter().copied()),
        ArrayData::U16(a) => a.iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::I32(a) => a.iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::I64(a) => a.iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::F32(a) => a.iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::F64(a) => a.iter().for_each(|v| out.extend(v.to_le_bytes())),
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Builds an NPY v1 file from a header dict and a payload.
    fn npy(dict: &str, payload: &[u8]) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.extend_from_slice(&[1, 0]);
        let len = u16::try_from(dict.len()).expect("short header");
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(dict.as_bytes());
        out.extend_from_slice(payload);
        out
    }

    #[test]
    fn header_parser_accepts_numpy_variants() {
        let text = b"{'descr': '>i8', \"fortran_order\": True, 'shape': (3L, 4,), }  \n";
        let entries = Parser { s: text, pos: 0 }.dict().expect("parses");
        assert_eq!(entries.len(), 3);
        assert_eq!(entries[2].1, Value::Tuple(vec![3, 4]));
        assert_eq!(entries[1].1, Value::Bool(true));
    }

    #[test]
    fn big_endian_and_fortran_order_are_read_correctly() {
        // Shape (2, 3) in Fortran order: the file holds columns one after the
        // other. Values a[i][j] = 10 i + j.
        let column_major = [0i32, 10, 1, 11, 2, 12];
        let payload: Vec<u8> = column_major.iter().flat_map(|v| v.to_be_bytes()).collect();
        let bytes = npy(
            "{'descr': '>i4', 'fortran_order': True, 'shape': (2, 3), }\n",
            &payload,
        );
        let a = decode(&bytes, &Limits::default()).expect("decodes");
        let ArrayData::I32(a) = a else {
            panic!("expected i32, got {:?}", a.dtype())
        };
        assert_eq!(a.shape(), &[2, 3]);
        assert_eq!(a.as_slice(), Some(&[0, 1, 2, 10, 11, 12][..]));
    }

    #[test]
    fn narrow_integers_widen_losslessly() {
        let bytes = npy(
            "{'descr': '<i2', 'fortran_order': False, 'shape': (2,), }\n",
            &[0x00, 0x80, 0xff, 0x7f],
        );
        let a = decode(&bytes, &Limits::default()).expect("decodes");
        assert_eq!(
            a,
            ArrayData::I32(ArrayD::from_shape_vec(vec![2], vec![-32768, 32767]).expect("shape"))
        );
        let bytes = npy(
            "{'descr': '<u4', 'fortran_order': False, 'shape': (1,), }\n",
            &u32::MAX.to_le_bytes(),
        );
        let a = decode(&bytes, &Limits::default()).expect("decodes");
        assert_eq!(a.get_f64(0), Some(f64::from(u32::MAX)));
    }

    #[test]
    fn bad_headers_are_refused_with_reasons() {
        let cases: [(&str, &str); 6] = [
            (
                "{'descr': '<c16', 'fortran_order': False, 'shape': (2,), }",
                "dtype '<c16'",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (), }",
                "0-dimensional",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 1, 1, 1), }",
                "4 axes",
            ),
            (
                "{'descr': '<f8', 'shape': (2,), }",
                "missing key 'fortran_order'",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (-2,), }",
                "negative",
            ),
            (
                "{'descr': [('a', '<f8')], 'fortran_order': False, 'shape': (2,), }",
                "structured",
            ),
        ];
        for (dict, needle) in cases {
            let err = decode(&npy(dict, &[0; 16]), &Limits::default()).expect_err(dict);
            assert!(err.to_string().contains(needle), "{dict}: {err}");
        }
    }

    #[test]
    fn a_fourth_axis_is_only_a_tensor_component_axis() {
        for (shape, ok) in [
            (vec![2, 3, 4, 6], true),
            (vec![2, 3, 4, 3], true),
            (vec![2, 3, 4, 2], false),
            (vec![2, 3, 4, 5, 6], false),
        ] {
            let a = ArrayData::F64(ArrayD::zeros(shape.clone()));
            let bytes = encode_npy(&a).expect("encodes");
            match decode(&bytes, &Limits::default()) {
                Ok(b) => assert!(ok && b.shape() == shape.as_slice(), "{shape:?}"),
                Err(e) => assert!(!ok && e.to_string().contains("axes"), "{shape:?}: {e}"),
            }
        }
    }

    #[test]
    fn header_is_padded_to_64_bytes() {
        for shape in [vec![1], vec![3, 4], vec![100_000, 2, 7]] {
            let a = ArrayData::F32(ArrayD::zeros(shape));
            let bytes = encode_npy(&a).expect("encodes");
            let (header, payload) = split(&bytes).expect("splits");
            assert_eq!((bytes.len() - payload.len()) % 64, 0);
            assert_eq!(bytes[bytes.len() - payload.len() - 1], b'\n');
            assert_eq!(header.shape, a.shape());
        }
    }
}
