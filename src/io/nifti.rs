//! NIfTI-1 single-file volumes, `.nii` and gzipped `.nii.gz`.
//!
//! The 348-byte header is parsed by the `nifti` crate; the byte order is the
//! one in which `sizeof_hdr` reads 348. The declared dimensions are checked
//! against [`Limits`] before the payload is read (for `.nii.gz`, before it is
//! decompressed: only `vox_offset + payload` bytes are ever inflated).
//!
//! # Axis order and spacing
//!
//! NIfTI stores voxels with `i` (x) varying fastest. The array returned has
//! **axis 0 = `i`**, axis 1 = `j`, axis 2 = `k`: shape `(nx, ny, nz)` (in
//! standard C layout, so it is transposed relative to the file), and the
//! spacing is `(pixdim[1], pixdim[2], pixdim[3])` = `(dx, dy, dz)`, as stored
//! (not validated here; the operation layer refuses non-positive spacings).
//! Volumes with `dim[0]` > 3 are accepted when the extra dimensions are 1
//! (e.g. a 4D file with one time point); 1D and 2D files give 1D and 2D
//! arrays.
//!
//! # Data types and scaling
//!
//! u8 → u8, u16 → u16, i8/i16/i32 → i32, u32/i64 → i64, f32 → f32, f64 → f64.
//! When `scl_slope` is finite and non-zero, `scl_inter` finite and the pair
//! is not `(1, 0)`, values become `scl_slope · x + scl_inter`, in f32 for
//! u8/i8/i16/u16/f32 data and in f64 for i32/u32/i64/f64 data.

use std::io::Read;

use flate2::read::MultiGzDecoder;
use ndarray::{ArrayD, IxDyn, ShapeBuilder};

use super::npy::elems;
use super::{ArrayData, Format, IoError, Limits};

/// Size of the NIfTI-1 header.
const HEADER_SIZE: usize = 348;
/// Where the data starts when there is no extension.
const DATA_OFFSET: usize = 352;
/// Largest `vox_offset` accepted (header plus extensions).
const MAX_VOX_OFFSET: usize = 1 << 20;

fn corrupt(reason: impl Into<String>) -> IoError {
    IoError::corrupt(Format::Nifti, reason)
}

fn unsupported(reason: impl Into<String>) -> IoError {
    IoError::unsupported(Format::Nifti, reason)
}

/// True if the bytes start like a gzip stream.
pub(crate) fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0x1F, 0x8B])
}

/// True if the bytes start with a NIfTI-1 header: `sizeof_hdr` = 348 in
/// either byte order and the magic `n+1\0` (single file) or `ni1\0` (header
/// of a `.hdr`/`.img` pair) at offset 344.
pub(crate) fn is_nifti1_header(bytes: &[u8]) -> bool {
    let size_ok = bytes.get(0..4).is_some_and(|s| {
        s == 348i32.to_le_bytes().as_slice() || s == 348i32.to_be_bytes().as_slice()
    });
    let magic_ok = bytes
        .get(344..348)
        .is_some_and(|m| m == b"n+1\0" || m == b"ni1\0");
    size_ok && magic_ok
}

/// The stored element type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stored {
    U8,
    I8,
    I16,
    U16,
    I32,
    U32,
    I64,
    F32,
    F64,
}

impl Stored {
    fn from_code(code: i16) -> Result<Self, IoError> {
        Ok(match code {
            2 => Stored::U8,
            4 => Stored::I16,
            8 => Stored::I32,
            16 => Stored::F32,
            64 => Stored::F64,
            256 => Stored::I8,
            512 => Stored::U16,
            768 => Stored::U32,
            1024 => Stored::I64,
            other => {
                let name = match other {
                    1 => "binary",
                    32 => "complex64",
                    128 => "rgb24",
                    1280 => "uint64",
                    1536 => "float128",
                    1792 => "complex128",
                    2048 => "complex256",
                    2304 => "rgba32",
                    _ => "unknown",
                };
                return Err(unsupported(format!(
                    "datatype {other} ({name}); supported: uint8, int8, int16, uint16, int32, \
                     uint32, int64, float32, float64"
                )));
            }
        })
    }

    fn size(self) -> usize {
        match self {
            Stored::U8 | Stored::I8 => 1,
            Stored::I16 | Stored::U16 => 2,
            Stored::I32 | Stored::U32 | Stored::F32 => 4,
            Stored::I64 | Stored::F64 => 8,
        }
    }

    /// Bytes per returned element (with or without scaling).
    fn out_size(self, scaled: bool) -> usize {
        match self {
            Stored::U8 | Stored::I8 | Stored::I16 | Stored::U16 | Stored::F32 if scaled => 4,
            Stored::U8 => 1,
            Stored::U16 => 2,
            Stored::I8 | Stored::I16 | Stored::I32 | Stored::F32 => 4,
            Stored::U32 | Stored::I64 | Stored::F64 => 8,
        }
    }
}

/// What the header says, checked.
struct Layout {
    dims: Vec<usize>,
    spacing: Vec<f64>,
    stored: Stored,
    little_endian: bool,
    vox_offset: usize,
    /// `(slope, inter)` when scaling applies.
    scale: Option<(f64, f64)>,
}

impl Layout {
    fn payload_len(&self) -> usize {
        // Checked against the limits in `parse_header`, so no overflow.
        self.dims.iter().product::<usize>() * self.stored.size()
    }
}

fn parse_header(head: &[u8], limits: &Limits) -> Result<Layout, IoError> {
    if head.len() < HEADER_SIZE {
        return Err(corrupt(format!(
            "truncated header: {} bytes, a NIfTI-1 header has {HEADER_SIZE}",
            head.len()
        )));
    }
    let little_endian = match head.get(0..4) {
        Some(s) if s == 348i32.to_le_bytes().as_slice() => true,
        Some(s) if s == 348i32.to_be_bytes().as_slice() => false,
        Some(&[a, b, c, d]) => {
            let le = i32::from_le_bytes([a, b, c, d]);
            let be = i32::from_be_bytes([a, b, c, d]);
            return Err(if le == 540 || be == 540 {
                unsupported("NIfTI-2 (sizeof_hdr 540); only NIfTI-1 is read")
            } else {
                corrupt(format!(
                    "sizeof_hdr is {le} (little endian) / {be} (big endian), not 348"
                ))
            });
        }
        _ => return Err(corrupt("truncated header")),
    };
    match head.get(344..348) {
        Some(b"n+1\0") => {}
        Some(b"ni1\0") => {
            return Err(unsupported(
                "a header-only file (magic 'ni1', .hdr/.img pair); send a single-file .nii",
            ))
        }
        other => {
            return Err(corrupt(format!(
                "magic at offset 344 is {:?}, not \"n+1\\0\"",
                other.map(|m| m.escape_ascii().to_string())
            )))
        }
    }
    let header = ::nifti::NiftiHeader::from_reader(&head[..HEADER_SIZE])
        .map_err(|e| corrupt(format!("header: {e}")))?;
    let crate_little = header.endianness == ::nifti::Endianness::Little;
    if header.sizeof_hdr != 348 || crate_little != little_endian {
        return Err(corrupt(format!(
            "header byte order is ambiguous: sizeof_hdr says {}, dim[0] = {} says otherwise",
            if little_endian { "little" } else { "big" },
            header.dim[0]
        )));
    }
    let ndim = usize::from(header.dim[0]);
    if !(1..=7).contains(&ndim) {
        return Err(corrupt(format!(
            "dim[0] = {} is not in 1..=7",
            header.dim[0]
        )));
    }
    let mut dims = Vec::with_capacity(ndim);
    for (k, &d) in header.dim[1..=ndim].iter().enumerate() {
        // The field is a signed 16-bit integer in the standard.
        if d == 0 || d > i16::MAX as u16 {
            return Err(corrupt(format!(
                "dim[{}] = {} is not a positive size",
                k + 1,
                d as i16
            )));
        }
        dims.push(usize::from(d));
    }
    while dims.len() > 3 && dims.last() == Some(&1) {
        dims.pop();
    }
    if dims.len() > 3 {
        return Err(unsupported(format!(
            "{}D volume with dim = {dims:?}; only 1D to 3D (extra dimensions of size 1) are read",
            dims.len()
        )));
    }
    let stored = Stored::from_code(header.datatype)?;
    let (slope, inter) = (f64::from(header.scl_slope), f64::from(header.scl_inter));
    let scale =
        (slope.is_finite() && slope != 0.0 && inter.is_finite() && (slope, inter) != (1.0, 0.0))
            .then_some((slope, inter));
    limits.check("NIfTI volume", &dims, stored.out_size(scale.is_some()))?;
    let vox = header.vox_offset;
    if !(vox.is_finite() && vox >= HEADER_SIZE as f32 && vox <= MAX_VOX_OFFSET as f32) {
        return Err(corrupt(format!(
            "vox_offset = {vox} is not in {HEADER_SIZE}..={MAX_VOX_OFFSET}"
        )));
    }
    let spacing = header.pixdim[1..=dims.len()]
        .iter()
        .map(|&p| f64::from(p))
        .collect();
    Ok(Layout {
        dims,
        spacing,
        stored,
        little_endian,
        // Truncation of a finite value in range.
        vox_offset: vox as usize,
        scale,
    })
}

/// Decodes a `.nii` or `.nii.gz` file into `(array, spacing)`.
pub(crate) fn decode(bytes: &[u8], limits: &Limits) -> Result<(ArrayData, Vec<f64>), IoError> {
    if is_gzip(bytes) {
        let mut gz = MultiGzDecoder::new(bytes);
        let mut head = Vec::with_capacity(HEADER_SIZE);
        (&mut gz)
            .take(HEADER_SIZE as u64)
            .read_to_end(&mut head)
            .map_err(|e| corrupt(format!("gzip stream: {e}")))?;
        if !is_nifti1_header(&head) {
            return Err(corrupt(
                "the gzip stream does not start with a NIfTI-1 header",
            ));
        }
        let layout = parse_header(&head, limits)?;
        let payload = layout.payload_len();
        let total = layout.vox_offset + payload;
        let mut all = head;
        all.try_reserve_exact(total - HEADER_SIZE)
            .map_err(|e| IoError::TooLarge {
                what: "NIfTI volume".into(),
                reason: format!("cannot reserve {total} bytes: {e}"),
            })?;
        (&mut gz)
            .take((total - HEADER_SIZE) as u64)
            .read_to_end(&mut all)
            .map_err(|e| corrupt(format!("gzip stream: {e}")))?;
        // Read on to the end of the stream (bounded) so that gzip checks
        // its CRC and length trailer: a cut stream is corrupt even when the
        // voxels themselves are complete.
        std::io::copy(&mut gz.take(MAX_VOX_OFFSET as u64), &mut std::io::sink())
            .map_err(|e| corrupt(format!("gzip stream after the voxels: {e}")))?;
        let data = all.get(layout.vox_offset..total).ok_or_else(|| {
            corrupt(format!(
                "truncated: the header declares {payload} bytes of voxels at offset {}, but \
                 the decompressed stream has {} bytes in all",
                layout.vox_offset,
                all.len()
            ))
        })?;
        Ok((volume(&layout, data)?, layout.spacing.clone()))
    } else {
        let layout = parse_header(bytes, limits)?;
        let payload = layout.payload_len();
        let data = bytes
            .get(layout.vox_offset..layout.vox_offset + payload)
            .ok_or_else(|| {
                corrupt(format!(
                    "truncated: the header declares dim {:?} of {}-byte voxels = {payload} \
                     bytes at offset {}, but the file has {} bytes after that offset",
                    layout.dims,
                    layout.stored.size(),
                    layout.vox_offset,
                    bytes.len().saturating_sub(layout.vox_offset)
                ))
            })?;
        Ok((volume(&layout, data)?, layout.spacing.clone()))
    }
}

/// Builds the C-layout array with axis 0 = i from the F-ordered voxels.
fn volume(layout: &Layout, data: &[u8]) -> Result<ArrayData, IoError> {
    fn shaped<T: Clone>(v: Vec<T>, dims: &[usize]) -> Result<ArrayD<T>, IoError> {
        ArrayD::from_shape_vec(IxDyn(dims).f(), v)
            .map(|a| a.as_standard_layout().into_owned())
            .map_err(|e| corrupt(format!("voxels do not fill {dims:?}: {e}")))
    }
    let le = layout.little_endian;
    let dims = &layout.dims;
    if let Some((slope, inter)) = layout.scale {
        let as_f64: Vec<f64> = match layout.stored {
            Stored::U8 => data.iter().map(|&v| f64::from(v)).collect(),
            Stored::I8 => data.iter().map(|&v| f64::from(v as i8)).collect(),
            Stored::I16 => elems(data, le, |b| f64::from(i16::from_le_bytes(b))),
            Stored::U16 => elems(data, le, |b| f64::from(u16::from_le_bytes(b))),
            Stored::I32 => elems(data, le, |b| f64::from(i32::from_le_bytes(b))),
            Stored::U32 => elems(data, le, |b| f64::from(u32::from_le_bytes(b))),
            Stored::I64 => elems(data, le, |b| i64::from_le_bytes(b) as f64),
            Stored::F32 => elems(data, le, |b| f64::from(f32::from_le_bytes(b))),
            Stored::F64 => elems(data, le, f64::from_le_bytes),
        };
        let scaled = as_f64.into_iter().map(|x| slope * x + inter);
        return Ok(if layout.stored.out_size(true) == 4 {
            ArrayData::F32(shaped(scaled.map(|v| v as f32).collect(), dims)?)
        } else {
            ArrayData::F64(shaped(scaled.collect(), dims)?)
        });
    }
    Ok(match layout.stored {
        Stored::U8 => ArrayData::U8(shaped(data.to_vec(), dims)?),
        Stored::I8 => ArrayData::I32(shaped(
            data.iter().map(|&v| i32::from(v as i8)).collect(),
            dims,
        )?),
        Stored::I16 => ArrayData::I32(shaped(
            elems(data, le, |b| i32::from(i16::from_le_bytes(b))),
            dims,
        )?),
        Stored::U16 => ArrayData::U16(shaped(elems(data, le, u16::from_le_bytes), dims)?),
        Stored::I32 => ArrayData::I32(shaped(elems(data, le, i32::from_le_bytes), dims)?),
        Stored::U32 => ArrayData::I64(shaped(
            elems(data, le, |b| i64::from(u32::from_le_bytes(b))),
            dims,
        )?),
        Stored::I64 => ArrayData::I64(shaped(elems(data, le, i64::from_le_bytes), dims)?),
        Stored::F32 => ArrayData::F32(shaped(elems(data, le, f32::from_le_bytes), dims)?),
        Stored::F64 => ArrayData::F64(shaped(elems(data, le, f64::from_le_bytes), dims)?),
    })
}

/// Encodes a 1D to 3D array as a single-file NIfTI-1 volume (`.nii`,
/// uncompressed, little endian, `vox_offset` 352, no extension).
///
/// Axis 0 of the array is written as the NIfTI `i` axis (stored fastest), so
/// that [`super::decode`] returns the same array; `spacing` (default all 1)
/// goes to `pixdim[1..]` and to a diagonal `sform` (code 1). Booleans are
/// written as uint8 0/1, the other dtypes as their own NIfTI datatype.
///
/// # Errors
///
/// [`IoError::Encode`] when the array has 0 or more than 3 axes, a side is 0
/// or beyond 32767 (NIfTI-1 sizes are 16-bit), or `spacing` does not have one
/// finite positive value per axis.
///
/// # Examples
///
/// ```
/// use geodex::io::{decode, encode_nifti, ArrayData, Limits};
/// let a = ArrayData::F32(ndarray::ArrayD::zeros(vec![4, 3, 2]));
/// let nii = encode_nifti(&a, Some(&[0.5, 0.5, 2.0]))?;
/// let back = decode(&nii, None, &Limits::default())?;
/// assert_eq!(back.array, a);
/// assert_eq!(back.spacing, Some(vec![0.5, 0.5, 2.0]));
/// # Ok::<(), geodex::io::IoError>(())
/// ```
pub fn encode_nifti(array: &ArrayData, spacing: Option<&[f64]>) -> Result<Vec<u8>, IoError> {
    let shape = array.shape();
    if !(1..=3).contains(&shape.len()) {
        return Err(IoError::Encode(format!(
            "NIfTI output needs 1 to 3 axes, got shape {shape:?}"
        )));
    }
    let mut dim = [1i16; 8];
    dim[0] = shape.len() as i16; // 1..=3
    for (k, &n) in shape.iter().enumerate() {
        dim[k + 1] = i16::try_from(n).ok().filter(|&d| d > 0).ok_or_else(|| {
            IoError::Encode(format!(
                "NIfTI-1 sides must be 1..=32767, got shape {shape:?}"
            ))
        })?;
    }
    let ones = vec![1.0; shape.len()];
    let spacing = spacing.unwrap_or(&ones);
    if spacing.len() != shape.len() || spacing.iter().any(|h| !(h.is_finite() && *h > 0.0)) {
        return Err(IoError::Encode(format!(
            "spacing {spacing:?} must hold {} finite positive values",
            shape.len()
        )));
    }
    let (code, bits): (i16, i16) = match array {
        ArrayData::Bool(_) | ArrayData::U8(_) => (2, 8),
        ArrayData::U16(_) => (512, 16),
        ArrayData::I32(_) => (8, 32),
        ArrayData::I64(_) => (1024, 64),
        ArrayData::F32(_) => (16, 32),
        ArrayData::F64(_) => (64, 64),
    };
    let mut h = vec![0u8; DATA_OFFSET];
    let mut put = |at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
    put(0, &348i32.to_le_bytes());
    put(38, b"r");
    for (k, d) in dim.iter().enumerate() {
        put(40 + 2 * k, &d.to_le_bytes());
    }
    put(70, &code.to_le_bytes());
    put(72, &bits.to_le_bytes());
    let mut pixdim = [1f32; 8];
    for (k, &s) in spacing.iter().enumerate() {
        pixdim[k + 1] = s as f32;
    }
    for (k, p) in pixdim.iter().enumerate() {
        put(76 + 4 * k, &p.to_le_bytes());
    }
    put(108, &(DATA_OFFSET as f32).to_le_bytes());
    put(112, &1f32.to_le_bytes()); // scl_slope
    put(148, b"geodex");
    put(254, &1i16.to_le_bytes()); // sform_code: scanner
    for (row, at) in [280usize, 296, 312].into_iter().enumerate() {
        let mut srow = [0f32; 4];
        srow[row] = pixdim[row + 1];
        for (k, v) in srow.iter().enumerate() {
            put(at + 4 * k, &v.to_le_bytes());
        }
    }
    put(344, b"n+1\0");
    let mut out = h;
    out.reserve(array.nbytes());
    // Reversed axes in C order = axis 0 fastest = NIfTI's F order.
    match array {
        ArrayData::Bool(a) => out.extend(a.t().iter().map(|&v| u8::from(v))),
        ArrayData::U8(a) => out.extend(a.t().iter().copied()),
        ArrayData::U16(a) => a.t().iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::I32(a) => a.t().iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::I64(a) => a.t().iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::F32(a) => a.t().iter().for_each(|v| out.extend(v.to_le_bytes())),
        ArrayData::F64(a) => a.t().iter().for_each(|v| out.extend(v.to_le_bytes())),
    }
    Ok(out)
}
