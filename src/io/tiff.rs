//! TIFF through the `tiff` crate (the `image` crate cannot read
//! single-channel float TIFFs).
//!
//! Decoding: grey 8/16/32/64-bit samples (unsigned, signed or float), and
//! grey with alpha (alpha dropped), keep their values: u8 → u8, u16 → u16,
//! i8/i16/i32 → i32, u32/i64 → i64, f16/f32 → f32, f64 → f64 (u64 is
//! refused). RGB and RGBA (8/16-bit integer or float) become f32 grey through
//! the Rec. 709 luma of [`super::raster`]. A single page gives `(rows, cols)`;
//! several pages of the same size and sample type give a volume `(pages,
//! rows, cols)`. The photometric interpretation `WhiteIsZero` is not
//! inverted.
//!
//! Each page's declared size is checked against [`Limits`] (cumulated over
//! the pages read so far) before it is decoded; the `tiff` crate's own
//! decoding-buffer limit is set to `limits.max_bytes`.

use std::io::Cursor;

use ::tiff::decoder::{Decoder, DecodingResult, Limits as TiffLimits};
use ::tiff::encoder::{colortype, TiffEncoder};
use ::tiff::{ColorType, TiffError};
use ndarray::{ArrayD, IxDyn};

use super::raster::LUMA_709;
use super::{ArrayData, Format, IoError, Limits};

fn map_err(e: TiffError) -> IoError {
    match e {
        TiffError::LimitsExceeded | TiffError::IntSizeError => IoError::TooLarge {
            what: "TIFF image".into(),
            reason: e.to_string(),
        },
        TiffError::UnsupportedError(e) => IoError::unsupported(Format::Tiff, e.to_string()),
        TiffError::IoError(e) => {
            IoError::corrupt(Format::Tiff, format!("truncated or unreadable: {e}"))
        }
        other => IoError::corrupt(Format::Tiff, other.to_string()),
    }
}

/// The decoded values of the pages read so far, in one typed buffer.
#[derive(Debug)]
enum Pages {
    U8(Vec<u8>),
    U16(Vec<u16>),
    I32(Vec<i32>),
    I64(Vec<i64>),
    F32(Vec<f32>),
    F64(Vec<f64>),
}

impl Pages {
    fn name(&self) -> &'static str {
        match self {
            Pages::U8(_) => "u8",
            Pages::U16(_) => "u16",
            Pages::I32(_) => "i32",
            Pages::I64(_) => "i64",
            Pages::F32(_) => "f32",
            Pages::F64(_) => "f64",
        }
    }

    /// Appends a page of the same type; `Err` with both type names otherwise.
    fn append(&mut self, page: Pages) -> Result<(), (&'static str, &'static str)> {
        match (self, page) {
            (Pages::U8(a), Pages::U8(b)) => a.extend(b),
            (Pages::U16(a), Pages::U16(b)) => a.extend(b),
            (Pages::I32(a), Pages::I32(b)) => a.extend(b),
            (Pages::I64(a), Pages::I64(b)) => a.extend(b),
            (Pages::F32(a), Pages::F32(b)) => a.extend(b),
            (Pages::F64(a), Pages::F64(b)) => a.extend(b),
            (a, b) => return Err((a.name(), b.name())),
        }
        Ok(())
    }

    fn into_array(self, shape: &[usize]) -> Result<ArrayData, IoError> {
        let dim = IxDyn(shape);
        let bad = |e: ndarray::ShapeError| {
            IoError::corrupt(Format::Tiff, format!("pixels do not fill {shape:?}: {e}"))
        };
        Ok(match self {
            Pages::U8(v) => ArrayData::U8(ArrayD::from_shape_vec(dim, v).map_err(bad)?),
            Pages::U16(v) => ArrayData::U16(ArrayD::from_shape_vec(dim, v).map_err(bad)?),
            Pages::I32(v) => ArrayData::I32(ArrayD::from_shape_vec(dim, v).map_err(bad)?),
            Pages::I64(v) => ArrayData::I64(ArrayD::from_shape_vec(dim, v).map_err(bad)?),
            Pages::F32(v) => ArrayData::F32(ArrayD::from_shape_vec(dim, v).map_err(bad)?),
            Pages::F64(v) => ArrayData::F64(ArrayD::from_shape_vec(dim, v).map_err(bad)?),
        })
    }
}

/// Channels of a supported colour type, and whether it is colour (RGB).
fn channels(colour: ColorType) -> Result<(usize, bool), IoError> {
    let (n, rgb) = match colour {
        ColorType::Gray(_) => (1, false),
        ColorType::GrayA(_) => (2, false),
        ColorType::RGB(_) => (3, true),
        ColorType::RGBA(_) => (4, true),
        other => {
            return Err(IoError::unsupported(
                Format::Tiff,
                format!("colour type {other:?} (supported: grey, grey+alpha, RGB, RGBA)"),
            ))
        }
    };
    let bits = colour.bit_depth();
    if ![8, 16, 32, 64].contains(&bits) {
        return Err(IoError::unsupported(
            Format::Tiff,
            format!("{bits}-bit samples (supported: 8, 16, 32, 64)"),
        ));
    }
    Ok((n, rgb))
}

fn luma<T: Copy>(raw: &[T], n: usize, f: impl Fn(T) -> f32) -> Vec<f32> {
    raw.chunks_exact(n)
        .map(|p| LUMA_709[0] * f(p[0]) + LUMA_709[1] * f(p[1]) + LUMA_709[2] * f(p[2]))
        .collect()
}

fn first<T: Copy>(raw: &[T], n: usize) -> Vec<T> {
    raw.iter().step_by(n).copied().collect()
}

/// Converts one decoded page of `cells` pixels.
fn page(result: DecodingResult, colour: ColorType, cells: usize) -> Result<Pages, IoError> {
    let (n, rgb) = channels(colour)?;
    let len = match &result {
        DecodingResult::U8(v) => v.len(),
        DecodingResult::U16(v) => v.len(),
        DecodingResult::U32(v) => v.len(),
        DecodingResult::U64(v) => v.len(),
        DecodingResult::F16(v) => v.len(),
        DecodingResult::F32(v) => v.len(),
        DecodingResult::F64(v) => v.len(),
        DecodingResult::I8(v) => v.len(),
        DecodingResult::I16(v) => v.len(),
        DecodingResult::I32(v) => v.len(),
        DecodingResult::I64(v) => v.len(),
    };
    if Some(len) != cells.checked_mul(n) {
        return Err(IoError::unsupported(
            Format::Tiff,
            format!(
                "the page decoded to {len} samples, not {cells} pixels × {n} channels \
                 (planar configuration?)"
            ),
        ));
    }
    let unsupported = |what: &str| {
        IoError::unsupported(Format::Tiff, format!("{what} samples in {colour:?} pages"))
    };
    Ok(if rgb {
        match result {
            DecodingResult::U8(v) => Pages::F32(luma(&v, n, f32::from)),
            DecodingResult::U16(v) => Pages::F32(luma(&v, n, f32::from)),
            DecodingResult::F32(v) => Pages::F32(luma(&v, n, |x| x)),
            // Luma of doubles, kept in f32 like every colour image.
            DecodingResult::F64(v) => Pages::F32(luma(&v, n, |x| x as f32)),
            _ => return Err(unsupported("integer 32/64-bit or signed")),
        }
    } else {
        match result {
            DecodingResult::U8(v) => Pages::U8(first(&v, n)),
            DecodingResult::U16(v) => Pages::U16(first(&v, n)),
            DecodingResult::U32(v) => Pages::I64(first(&v, n).into_iter().map(i64::from).collect()),
            DecodingResult::I8(v) => Pages::I32(first(&v, n).into_iter().map(i32::from).collect()),
            DecodingResult::I16(v) => Pages::I32(first(&v, n).into_iter().map(i32::from).collect()),
            DecodingResult::I32(v) => Pages::I32(first(&v, n)),
            DecodingResult::I64(v) => Pages::I64(first(&v, n)),
            DecodingResult::F16(v) => {
                Pages::F32(first(&v, n).into_iter().map(|x| x.to_f32()).collect())
            }
            DecodingResult::F32(v) => Pages::F32(first(&v, n)),
            DecodingResult::F64(v) => Pages::F64(first(&v, n)),
            DecodingResult::U64(_) => return Err(unsupported("unsigned 64-bit")),
        }
    })
}

/// Bytes per returned element, as far as the header tells (the sample
/// format is only known after decoding; u32 pages are re-checked as i64).
fn item_size(colour: ColorType) -> usize {
    match colour {
        ColorType::RGB(_) | ColorType::RGBA(_) => 4,
        other => usize::from(other.bit_depth() / 8).max(1),
    }
}

/// Decodes a TIFF file, every page.
pub(crate) fn decode(bytes: &[u8], limits: &Limits) -> Result<ArrayData, IoError> {
    let mut tiff_limits = TiffLimits::default();
    tiff_limits.decoding_buffer_size = limits.max_bytes;
    let mut decoder = Decoder::new(Cursor::new(bytes))
        .map_err(map_err)?
        .with_limits(tiff_limits);
    let (width, height) = decoder.dimensions().map_err(map_err)?;
    let colour = decoder.colortype().map_err(map_err)?;
    let (rows, cols) = (height as usize, width as usize);
    let cells = rows
        .checked_mul(cols)
        .filter(|&c| c > 0)
        .ok_or_else(|| IoError::corrupt(Format::Tiff, format!("image size {width}×{height}")))?;
    let mut pages: Option<Pages> = None;
    let mut count = 0usize;
    loop {
        let (w, h) = decoder.dimensions().map_err(map_err)?;
        let c = decoder.colortype().map_err(map_err)?;
        if (w, h, c) != (width, height, colour) {
            return Err(IoError::unsupported(
                Format::Tiff,
                format!(
                    "page {count} is {w}×{h} {c:?} but page 0 is {width}×{height} {colour:?}; \
                     a multi-page TIFF must hold pages of one size and type"
                ),
            ));
        }
        limits.check("TIFF image", &[count + 1, rows, cols], item_size(colour))?;
        let next = page(decoder.read_image().map_err(map_err)?, colour, cells)?;
        if matches!(next, Pages::I64(_)) {
            limits.check("TIFF image", &[count + 1, rows, cols], 8)?;
        }
        match &mut pages {
            None => pages = Some(next),
            Some(all) => all.append(next).map_err(|(a, b)| {
                IoError::unsupported(
                    Format::Tiff,
                    format!("page {count} holds {b} samples but the previous pages hold {a}"),
                )
            })?,
        }
        count += 1;
        if !decoder.more_images() {
            break;
        }
        decoder.next_image().map_err(map_err)?;
    }
    let pages = pages.ok_or_else(|| IoError::corrupt(Format::Tiff, "no image"))?;
    if count == 1 {
        pages.into_array(&[rows, cols])
    } else {
        pages.into_array(&[count, rows, cols])
    }
}

/// Encodes an array as an uncompressed 32-bit float grey TIFF
/// (`SampleFormat` IEEE float, one sample per pixel).
///
/// A 2D array `(rows, cols)` becomes one page of `cols × rows` pixels; a 3D
/// array `(pages, rows, cols)` becomes a multi-page TIFF, one page per index
/// along axis 0 (a `(1, rows, cols)` array is therefore read back as 2D).
/// Every dtype is converted to f32 (f64 is rounded to nearest; booleans are
/// 0 and 1; i32/i64 beyond 2^24 lose precision).
///
/// # Errors
///
/// [`IoError::Encode`] for other numbers of axes, empty arrays or sides
/// beyond `u32::MAX`.
pub fn encode_tiff_f32(array: &ArrayData) -> Result<Vec<u8>, IoError> {
    let shape = array.shape().to_vec();
    let (pages, rows, cols) = match shape[..] {
        [rows, cols] => (1, rows, cols),
        [pages, rows, cols] => (pages, rows, cols),
        _ => {
            return Err(IoError::Encode(format!(
                "a float TIFF needs a 2D or 3D array, got shape {shape:?}"
            )))
        }
    };
    let side = |n: usize| {
        u32::try_from(n).ok().filter(|&n| n > 0).ok_or_else(|| {
            IoError::Encode(format!(
                "TIFF sides must be 1..=u32::MAX, got shape {shape:?}"
            ))
        })
    };
    let (w, h) = (side(cols)?, side(rows)?);
    side(pages)?;
    let values: Vec<f32> = match array {
        ArrayData::F32(a) => a.iter().copied().collect(),
        // Rounded to nearest f32, as documented.
        ArrayData::F64(a) => a.iter().map(|&v| v as f32).collect(),
        other => super::to_f64_vec(other)
            .into_iter()
            .map(|v| v as f32)
            .collect(),
    };
    let mut out = Vec::new();
    let enc_err = |e: TiffError| IoError::Encode(format!("TIFF: {e}"));
    {
        let mut encoder = TiffEncoder::new(Cursor::new(&mut out)).map_err(enc_err)?;
        for page in values.chunks(rows * cols) {
            encoder
                .write_image::<colortype::Gray32Float>(w, h, page)
                .map_err(enc_err)?;
        }
    }
    Ok(out)
}
