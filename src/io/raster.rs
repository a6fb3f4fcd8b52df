//! PNG and JPEG through the `image` crate.
//!
//! Decoding returns `(rows, cols)` = `(height, width)` arrays:
//!
//! * grey images keep their values: 8-bit → u8, 16-bit → u16 (alpha dropped);
//! * colour images become f32 grey through the Rec. 709 luma
//!   `Y = 0.2126 R + 0.7152 G + 0.0722 B`, computed in f32 on the raw stored
//!   values (0..255 or 0..65535, no gamma decoding); alpha is ignored.
//!
//! The header is read first and its dimensions are checked against
//! [`Limits`] before any pixel is decoded; the `image` crate's own limits
//! (width, height, allocation) are set from the same numbers.

use std::io::Cursor;

use image::{DynamicImage, ImageBuffer, ImageDecoder, ImageError, ImageFormat, ImageReader, Luma};
use ndarray::{ArrayD, IxDyn};

use super::{plane_f64, ArrayData, Format, IoError, Limits};

/// Rec. 709 luma weights of R, G and B.
pub const LUMA_709: [f32; 3] = [0.2126, 0.7152, 0.0722];

fn map_err(format: Format, e: ImageError) -> IoError {
    match e {
        ImageError::Limits(e) => IoError::TooLarge {
            what: format!("{format:?} image"),
            reason: e.to_string(),
        },
        ImageError::Unsupported(e) => IoError::unsupported(format, e.to_string()),
        ImageError::IoError(e) => IoError::corrupt(format, format!("truncated or unreadable: {e}")),
        other => IoError::corrupt(format, other.to_string()),
    }
}

/// Rec. 709 luma of interleaved pixels with `channels` ≥ 3 values each
/// (R, G, B first; anything after is ignored).
fn luma<T: Copy + Into<f32>>(raw: &[T], channels: usize) -> Vec<f32> {
    raw.chunks_exact(channels)
        .map(|p| LUMA_709[0] * p[0].into() + LUMA_709[1] * p[1].into() + LUMA_709[2] * p[2].into())
        .collect()
}

/// Every `channels`-th value starting at the first (drops alpha).
fn first_channel<T: Copy>(raw: &[T], channels: usize) -> Vec<T> {
    raw.iter().step_by(channels).copied().collect()
}

/// The PNG signature.
const PNG_SIGNATURE: &[u8; 8] = b"\x89PNG\r\n\x1a\n";

/// The PNG with only the chunks that make its pixels: the critical chunks
/// (`IHDR`, `PLTE`, `IDAT`, `IEND`: an upper-case first letter) and
/// `tRNS`. Every other ancillary chunk (`iCCP`, `zTXt`, `iTXt` can hold
/// compressed payloads of any size, and the decoder inflates some of them)
/// is dropped before decoding, so that a small file cannot make the decoder
/// allocate gigabytes for metadata that a distance map never uses.
///
/// `None` when nothing needs dropping, or when the chunk structure is broken
/// (the decoder then reports the damage itself).
fn png_pixels_only(bytes: &[u8]) -> Option<Vec<u8>> {
    let body = bytes.strip_prefix(PNG_SIGNATURE)?;
    let mut keep: Vec<&[u8]> = Vec::new();
    let mut dropped = false;
    let mut rest = body;
    while !rest.is_empty() {
        let len = usize::try_from(u32::from_be_bytes(rest.get(..4)?.try_into().ok()?)).ok()?;
        let total = len.checked_add(12)?;
        let chunk = rest.get(..total)?;
        let kind = &chunk[4..8];
        if kind[0].is_ascii_uppercase() || kind == b"tRNS" {
            keep.push(chunk);
        } else {
            dropped = true;
        }
        rest = &rest[total..];
        if kind == b"IEND" {
            break;
        }
    }
    if !dropped {
        return None;
    }
    let mut out = Vec::with_capacity(8 + keep.iter().map(|c| c.len()).sum::<usize>());
    out.extend_from_slice(PNG_SIGNATURE);
    for c in keep {
        out.extend_from_slice(c);
    }
    Some(out)
}

/// The longest JPEG side the decoder takes. zune-jpeg (under `image`)
/// counts a side's 8-pixel blocks as `(side + 7) / 8` in a `u16`, which
/// overflows above 65528 (a panic with overflow checks, wrong block counts
/// without): found by fuzzing (`fuzz/`), refused before decoding.
const JPEG_MAX_SIDE: u32 = u16::MAX as u32 - 7;

/// Decodes a PNG or JPEG file.
pub(crate) fn decode(bytes: &[u8], format: Format, limits: &Limits) -> Result<ArrayData, IoError> {
    let image_format = match format {
        Format::Png => ImageFormat::Png,
        Format::Jpeg => ImageFormat::Jpeg,
        other => {
            return Err(IoError::unsupported(
                other,
                "not a raster format of the image crate",
            ))
        }
    };
    // The pixel decoders accept files cut after the last pixel; a file
    // without its end marker is refused as truncated all the same.
    if format == Format::Png && !bytes.windows(8).any(|w| w == b"IEND\xAE\x42\x60\x82") {
        return Err(IoError::corrupt(
            format,
            format!(
                "truncated: {} bytes and no complete IEND chunk",
                bytes.len()
            ),
        ));
    }
    if format == Format::Jpeg {
        jpeg_complete(bytes).map_err(|reason| IoError::corrupt(format, reason))?;
    }
    let stripped;
    let bytes = if format == Format::Png {
        stripped = png_pixels_only(bytes);
        stripped.as_deref().unwrap_or(bytes)
    } else {
        bytes
    };
    let mut reader = ImageReader::with_format(Cursor::new(bytes), image_format);
    let side = u32::try_from(limits.max_cells).unwrap_or(u32::MAX);
    let mut image_limits = image::Limits::default();
    image_limits.max_image_width = Some(side);
    image_limits.max_image_height = Some(side);
    image_limits.max_alloc = Some(u64::try_from(limits.max_bytes).unwrap_or(u64::MAX));
    reader.limits(image_limits);
    let decoder = reader.into_decoder().map_err(|e| map_err(format, e))?;
    let (width, height) = decoder.dimensions();
    if format == Format::Jpeg && width.max(height) > JPEG_MAX_SIDE {
        return Err(IoError::unsupported(
            format,
            format!(
                "{width}×{height} pixels: sides above {JPEG_MAX_SIDE} pixels are not supported"
            ),
        ));
    }
    let shape = [height as usize, width as usize];
    let colour = decoder.color_type();
    let grey = !colour.has_color();
    let item = if grey {
        usize::from(colour.bytes_per_pixel() / colour.channel_count().max(1))
    } else {
        4
    };
    let what = format!("{format:?} image");
    limits.check(&what, &shape, item)?;
    // The decoder's own buffer (all channels) must fit too.
    let raw = decoder.total_bytes();
    if raw > u64::try_from(limits.max_bytes).unwrap_or(u64::MAX) {
        return Err(IoError::TooLarge {
            what,
            reason: format!(
                "{width}×{height} {colour:?} pixels need {raw} bytes to decode, more than the \
                 limit of {}",
                limits.max_bytes
            ),
        });
    }
    let image = DynamicImage::from_decoder(decoder).map_err(|e| map_err(format, e))?;
    let dim = IxDyn(&shape);
    let bad = |e: ndarray::ShapeError| {
        IoError::corrupt(format, format!("decoded pixels do not fill {shape:?}: {e}"))
    };
    Ok(match image {
        DynamicImage::ImageLuma8(b) => {
            ArrayData::U8(ArrayD::from_shape_vec(dim, b.into_raw()).map_err(bad)?)
        }
        DynamicImage::ImageLumaA8(b) => {
            ArrayData::U8(ArrayD::from_shape_vec(dim, first_channel(b.as_raw(), 2)).map_err(bad)?)
        }
        DynamicImage::ImageLuma16(b) => {
            ArrayData::U16(ArrayD::from_shape_vec(dim, b.into_raw()).map_err(bad)?)
        }
        DynamicImage::ImageLumaA16(b) => {
            ArrayData::U16(ArrayD::from_shape_vec(dim, first_channel(b.as_raw(), 2)).map_err(bad)?)
        }
        DynamicImage::ImageRgb8(b) => {
            ArrayData::F32(ArrayD::from_shape_vec(dim, luma(b.as_raw(), 3)).map_err(bad)?)
        }
        DynamicImage::ImageRgba8(b) => {
            ArrayData::F32(ArrayD::from_shape_vec(dim, luma(b.as_raw(), 4)).map_err(bad)?)
        }
        DynamicImage::ImageRgb16(b) => {
            ArrayData::F32(ArrayD::from_shape_vec(dim, luma(b.as_raw(), 3)).map_err(bad)?)
        }
        DynamicImage::ImageRgba16(b) => {
            ArrayData::F32(ArrayD::from_shape_vec(dim, luma(b.as_raw(), 4)).map_err(bad)?)
        }
        DynamicImage::ImageRgb32F(b) => {
            ArrayData::F32(ArrayD::from_shape_vec(dim, luma(b.as_raw(), 3)).map_err(bad)?)
        }
        DynamicImage::ImageRgba32F(b) => {
            ArrayData::F32(ArrayD::from_shape_vec(dim, luma(b.as_raw(), 4)).map_err(bad)?)
        }
        other => {
            return Err(IoError::unsupported(
                format,
                format!("pixel type {:?}", other.color()),
            ))
        }
    })
}

/// Walks the marker segments of a JPEG file up to its end-of-image marker
/// (`FF D9`), skipping segment payloads by their declared lengths and the
/// entropy-coded data after each start-of-scan (where `FF 00` is a stuffed
/// byte and `FF D0..D7` are restart markers). JPEG decoders pad a truncated
/// scan silently; this refuses such files. Data after the end-of-image
/// marker (e.g. an appended video) is ignored.
fn jpeg_complete(bytes: &[u8]) -> Result<(), String> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return Err("missing the start-of-image marker FF D8".into());
    }
    let mut pos = 2usize;
    loop {
        if bytes.get(pos) != Some(&0xFF) {
            return Err(if pos >= bytes.len() {
                format!(
                    "truncated: {} bytes and no end-of-image marker",
                    bytes.len()
                )
            } else {
                format!("expected a marker at byte {pos}")
            });
        }
        // Fill bytes.
        while bytes.get(pos) == Some(&0xFF) {
            pos += 1;
        }
        let marker = *bytes.get(pos).ok_or_else(|| {
            format!(
                "truncated: {} bytes and no end-of-image marker",
                bytes.len()
            )
        })?;
        pos += 1;
        match marker {
            0xD9 => return Ok(()),
            0x01 | 0xD0..=0xD7 => continue,
            _ => {}
        }
        let len = match bytes.get(pos..pos + 2) {
            Some(&[a, b]) => usize::from(u16::from_be_bytes([a, b])),
            _ => {
                return Err(format!(
                    "truncated in the length of segment FF {marker:02X}"
                ))
            }
        };
        if len < 2 || pos + len > bytes.len() {
            return Err(format!(
                "segment FF {marker:02X} at byte {} declares {len} bytes, {} remain",
                pos - 2,
                bytes.len() - pos
            ));
        }
        pos += len;
        if marker == 0xDA {
            // Entropy-coded data up to the next real marker.
            loop {
                match bytes.get(pos..pos + 2) {
                    Some(&[0xFF, next]) if next != 0x00 && !(0xD0..=0xD7).contains(&next) => break,
                    Some(_) => pos += 1,
                    None => {
                        return Err(format!(
                            "truncated inside the scan data: {} bytes and no end-of-image marker",
                            bytes.len()
                        ))
                    }
                }
            }
        }
    }
}

/// The linear map of [`encode_png16`]: `(lo, hi)` from `range`, or the
/// finite minimum and maximum of `values` (`(0, 1)` if none is finite).
pub(crate) fn value_range(
    values: &[f64],
    range: Option<(f64, f64)>,
) -> Result<(f64, f64), IoError> {
    if let Some((lo, hi)) = range {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(IoError::Encode(format!(
                "range ({lo}, {hi}) must be finite with low < high"
            )));
        }
        return Ok((lo, hi));
    }
    Ok(finite_min_max(values))
}

/// The finite minimum and maximum of `values`, `(0, 1)` if none is finite.
pub(crate) fn finite_min_max(values: &[f64]) -> (f64, f64) {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if lo <= hi {
        (lo, hi)
    } else {
        (0.0, 1.0)
    }
}

/// Encodes a 2D array (or a 3D array of shape `(1, rows, cols)`) as a
/// 16-bit grey PNG of `cols × rows` pixels.
///
/// Values are mapped linearly, `q = round((v - lo) / (hi - lo) · 65535)`
/// clamped to `0..=65535`, where `(lo, hi)` is `range` or, by default, the
/// finite minimum and maximum of the array; when `lo == hi` every finite
/// value maps to 0. `+inf` and NaN map to 65535, `-inf` to 0. The inverse is
/// `v ≈ lo + q (hi - lo) / 65535`; an array of u16 values with `range =
/// Some((0.0, 65535.0))` is stored exactly.
///
/// # Errors
///
/// [`IoError::Encode`] for other shapes, empty arrays, sides beyond
/// `u32::MAX`, or a `range` that is not finite with `lo < hi`.
pub fn encode_png16(array: &ArrayData, range: Option<(f64, f64)>) -> Result<Vec<u8>, IoError> {
    let (rows, cols, values) = plane_f64(array, "a 16-bit PNG")?;
    let (lo, hi) = value_range(&values, range)?;
    let scale = if hi > lo { 65535.0 / (hi - lo) } else { 0.0 };
    let q: Vec<u16> = values
        .iter()
        .map(|&v| {
            if v.is_nan() || v == f64::INFINITY {
                u16::MAX
            } else if v == f64::NEG_INFINITY {
                0
            } else {
                // Clamped to the u16 range, so the cast is exact.
                ((v - lo) * scale).round().clamp(0.0, 65535.0) as u16
            }
        })
        .collect();
    write_png(ImageBuffer::<Luma<u16>, _>::from_raw(
        side(cols)?,
        side(rows)?,
        q,
    ))
}

/// A PNG side length: non-zero and within u32.
pub(crate) fn side(n: usize) -> Result<u32, IoError> {
    u32::try_from(n)
        .ok()
        .filter(|&n| n > 0)
        .ok_or_else(|| IoError::Encode(format!("a PNG side must be 1..=u32::MAX pixels, got {n}")))
}

/// Writes an image buffer (`None` if its size was inconsistent) as PNG.
pub(crate) fn write_png<P>(
    image: Option<ImageBuffer<P, Vec<P::Subpixel>>>,
) -> Result<Vec<u8>, IoError>
where
    P: image::Pixel + image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
{
    let image =
        image.ok_or_else(|| IoError::Encode("pixel buffer does not match its size".into()))?;
    let mut out = Vec::new();
    image
        .write_to(&mut Cursor::new(&mut out), ImageFormat::Png)
        .map_err(|e| IoError::Encode(format!("PNG: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jpeg_sides_above_65528_are_refused_not_overflowed() {
        let (w, h) = (16u32, 8u32);
        let grey: Vec<u8> = (0..w * h).map(|i| (i * 7) as u8).collect();
        let mut jpeg = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::jpeg::JpegEncoder::new(&mut jpeg),
            &grey,
            w,
            h,
            image::ExtendedColorType::L8,
        )
        .unwrap();
        let sof = jpeg.windows(2).position(|m| m == [0xFF, 0xC0]).unwrap();
        for (side, sampling) in [(65535u16, 0x22u8), (65529, 0x11), (65528, 0x22)] {
            let mut bytes = jpeg.clone();
            // SOF0: marker, length, precision, height, width, components,
            // then (id, sampling factors, table) for the one grey component.
            bytes[sof + 5..sof + 7].copy_from_slice(&1u16.to_be_bytes());
            bytes[sof + 7..sof + 9].copy_from_slice(&side.to_be_bytes());
            bytes[sof + 11] = sampling;
            let result = decode(&bytes, Format::Jpeg, &Limits::default());
            if side > 65528 {
                assert!(
                    matches!(&result, Err(IoError::Unsupported { reason, .. }) if reason.contains("65528")),
                    "{side}: {result:?}"
                );
            } else {
                assert!(
                    !matches!(result, Err(IoError::Unsupported { .. })),
                    "{result:?}"
                );
            }
        }
    }

    #[test]
    fn luma_weights_sum_to_one() {
        let sum: f32 = LUMA_709.iter().sum();
        assert!((sum - 1.0).abs() < 1e-6, "{sum}");
        assert_eq!(luma(&[255u8, 255, 255, 7], 4), vec![255.0 * sum]);
    }

    /// A chunk with its length and CRC.
    fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
        let mut crc = flate2::Crc::new();
        crc.update(kind);
        crc.update(data);
        let mut c = (data.len() as u32).to_be_bytes().to_vec();
        c.extend_from_slice(kind);
        c.extend_from_slice(data);
        c.extend_from_slice(&crc.sum().to_be_bytes());
        c
    }

    #[test]
    fn ancillary_chunks_are_dropped_before_decoding() {
        let a = ArrayData::F64(
            ArrayD::from_shape_vec(vec![2, 3], vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]).expect("shape"),
        );
        let png = encode_png16(&a, None).expect("encodes");
        // An iCCP profile that inflates to 64 MiB, and a text chunk, after IHDR.
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        std::io::Write::write_all(&mut z, &vec![0u8; 64 << 20]).expect("compresses");
        let mut profile = b"bomb\0\0".to_vec();
        profile.extend(z.finish().expect("compresses"));
        let ihdr_end = 8 + 12 + 13;
        let mut bomb = png[..ihdr_end].to_vec();
        bomb.extend(chunk(b"iCCP", &profile));
        bomb.extend(chunk(b"tEXt", b"Comment\0hello"));
        bomb.extend_from_slice(&png[ihdr_end..]);
        let stripped = png_pixels_only(&bomb).expect("drops the two chunks");
        assert_eq!(stripped, png, "only the pixel chunks remain, byte for byte");
        assert_eq!(
            png_pixels_only(&png),
            None,
            "nothing to drop in a plain PNG"
        );
        let back = decode(&bomb, Format::Png, &Limits::default()).expect("decodes");
        let plain = decode(&png, Format::Png, &Limits::default()).expect("decodes");
        assert_eq!(back, plain);
    }

    #[test]
    fn png16_maps_the_range_and_special_values() {
        let a = ArrayData::F64(
            ArrayD::from_shape_vec(
                vec![1, 5],
                vec![1.0, 3.0, f64::INFINITY, f64::NAN, f64::NEG_INFINITY],
            )
            .expect("shape"),
        );
        let png = encode_png16(&a, None).expect("encodes");
        let back = decode(&png, Format::Png, &Limits::default()).expect("decodes");
        let ArrayData::U16(b) = back else {
            panic!("expected u16, got {:?}", back.dtype())
        };
        assert_eq!(b.as_slice(), Some(&[0, 65535, 65535, 65535, 0][..]));
        assert!(encode_png16(&a, Some((1.0, 1.0))).is_err());
        assert!(encode_png16(&ArrayData::F32(ArrayD::zeros(vec![2, 2, 2])), None).is_err());
    }
}
