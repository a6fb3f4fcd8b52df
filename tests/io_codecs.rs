//! Codec tests: round trips for every format and dtype (inputs produced by
//! the `image`, `tiff`, `nifti` and `ndarray-npy` crates, independently of
//! our encoders), exact values where the format is lossless, size limits
//! enforced before allocation, and no panic on arbitrary bytes.

use std::io::Cursor;
use std::sync::OnceLock;

use geodex::io::{
    decode, encode_nifti, encode_npy, encode_png16, encode_tiff_f32, render_png, ArrayData,
    Decoded, Format, IoError, Limits, RenderOptions,
};
use image::{DynamicImage, ImageBuffer, ImageFormat, Luma, LumaA, Rgb, Rgba};
use ndarray::{ArrayD, IxDyn, ShapeBuilder};
use ndarray_npy::WriteNpyExt;
use proptest::prelude::*;

fn ok(bytes: &[u8]) -> Decoded {
    decode(bytes, None, &Limits::default()).expect("decodes")
}

fn f32s(a: &ArrayData) -> &[f32] {
    match a {
        ArrayData::F32(a) => a.as_slice().expect("standard layout"),
        other => panic!("expected f32, got {:?}", other.dtype()),
    }
}

/// A small ramp with distinct values per cell: `v[i] = f(i)` in C order.
fn ramp<T>(shape: &[usize], f: impl Fn(usize) -> T) -> ArrayD<T> {
    let n = shape.iter().product();
    ArrayD::from_shape_vec(IxDyn(shape), (0..n).map(f).collect()).expect("shape")
}

fn every_dtype(shape: &[usize]) -> Vec<ArrayData> {
    vec![
        ArrayData::Bool(ramp(shape, |i| i % 3 == 0)),
        ArrayData::U8(ramp(shape, |i| (i * 7 % 256) as u8)),
        ArrayData::U16(ramp(shape, |i| (i * 977 % 65536) as u16)),
        ArrayData::I32(ramp(shape, |i| i as i32 * -12345 + 7)),
        ArrayData::I64(ramp(shape, |i| (i as i64 - 3) << 40)),
        ArrayData::F32(ramp(shape, |i| i as f32 * 0.1 - 1.5)),
        ArrayData::F64(ramp(shape, |i| (i as f64).sqrt() * std::f64::consts::PI)),
    ]
}

fn png_of(image: DynamicImage) -> Vec<u8> {
    let mut out = Vec::new();
    image
        .write_to(&mut Cursor::new(&mut out), ImageFormat::Png)
        .expect("png");
    out
}

// ---------------------------------------------------------------- NPY

#[test]
fn npy_round_trips_every_dtype_and_rank() {
    for shape in [&[5][..], &[3, 4], &[2, 3, 4]] {
        for a in every_dtype(shape) {
            let bytes = encode_npy(&a).expect("encodes");
            let back = ok(&bytes);
            assert_eq!(back.format, Format::Npy);
            assert_eq!(back.spacing, None);
            assert_eq!(back.array, a, "{:?} {shape:?}", a.dtype());
        }
    }
}

#[test]
fn npy_written_by_ndarray_npy_is_read_including_fortran_order() {
    let c = ramp(&[3, 4], |i| i as f64 * 0.5);
    let mut bytes = Vec::new();
    c.write_npy(&mut bytes).expect("write");
    assert_eq!(ok(&bytes).array, ArrayData::F64(c.clone()));

    // The same values in a Fortran-layout array: written with
    // fortran_order True, read back in C order with the same logical values.
    let f = ArrayD::from_shape_vec(IxDyn(&[3, 4]).f(), {
        let mut v = Vec::new();
        for j in 0..4 {
            for i in 0..3 {
                v.push(c[[i, j]]);
            }
        }
        v
    })
    .expect("shape");
    assert_eq!(f, c);
    let mut fbytes = Vec::new();
    f.write_npy(&mut fbytes).expect("write");
    assert!(String::from_utf8_lossy(&fbytes[..128]).contains("'fortran_order': True"));
    assert_eq!(ok(&fbytes).array, ArrayData::F64(c));

    let labels = ramp(&[2, 2, 2], |i| i as i64 - 4);
    let mut lbytes = Vec::new();
    labels.write_npy(&mut lbytes).expect("write");
    assert_eq!(ok(&lbytes).array, ArrayData::I64(labels));
}

#[test]
fn truncated_npy_is_corrupt_with_byte_counts() {
    let bytes = encode_npy(&ArrayData::F64(ramp(&[4, 4], |i| i as f64))).expect("encodes");
    let err = decode(&bytes[..bytes.len() - 3], None, &Limits::default()).expect_err("short");
    match err {
        IoError::Corrupt { format, reason } => {
            assert_eq!(format, Format::Npy);
            assert!(reason.contains("truncated"), "{reason}");
            assert!(reason.contains("128") && reason.contains("125"), "{reason}");
        }
        other => panic!("expected Corrupt, got {other:?}"),
    }
    let mut long = bytes.clone();
    long.push(0);
    assert!(matches!(
        decode(&long, None, &Limits::default()),
        Err(IoError::Corrupt { reason, .. }) if reason.contains("trailing")
    ));
    // Cut inside the header.
    assert!(matches!(
        decode(&bytes[..40], None, &Limits::default()),
        Err(IoError::Corrupt { .. })
    ));
}

#[test]
fn npy_claiming_a_huge_shape_is_too_large_before_reading() {
    let dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (100000, 100000), }";
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.extend_from_slice(&[0; 16]);
    match decode(&bytes, None, &Limits::default()) {
        Err(IoError::TooLarge { reason, .. }) => {
            assert!(reason.contains("10000000000 cells"), "{reason}")
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    // Byte limit as well as cell limit; overflow of the product.
    let limits = Limits {
        max_cells: 1000,
        max_bytes: 100,
    };
    let a = encode_npy(&ArrayData::F64(ArrayD::zeros(IxDyn(&[4, 4])))).expect("encodes");
    assert!(matches!(
        decode(&a, None, &limits),
        Err(IoError::TooLarge { .. })
    ));
    let dict =
        "{'descr': '|u1', 'fortran_order': False, 'shape': (4294967296, 4294967296, 4294967296), }";
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    assert!(matches!(
        decode(&bytes, None, &Limits::default()),
        Err(IoError::TooLarge { .. })
    ));
}

// ---------------------------------------------------------------- PNG / JPEG

#[test]
fn png_grey_8_and_16_bit_are_exact_with_rows_on_axis_0() {
    // 5 wide, 3 high: shape (3, 5), pixel (x, y) at [y, x].
    let g8 = ImageBuffer::from_fn(5, 3, |x, y| Luma([(10 * y + x) as u8]));
    let d = ok(&png_of(DynamicImage::ImageLuma8(g8)));
    assert_eq!(d.format, Format::Png);
    let ArrayData::U8(a) = d.array else {
        panic!("expected u8")
    };
    assert_eq!(a.shape(), &[3, 5]);
    assert_eq!(a[[2, 4]], 24);

    let g16 = ImageBuffer::from_fn(4, 2, |x, y| Luma([(x * 16411 + y * 7) as u16 + 3]));
    let expected: Vec<u16> = g16.as_raw().clone();
    let d = ok(&png_of(DynamicImage::ImageLuma16(g16)));
    let ArrayData::U16(a) = d.array else {
        panic!("expected u16")
    };
    assert_eq!(a.shape(), &[2, 4]);
    assert_eq!(a.as_slice(), Some(&expected[..]));

    // Grey + alpha: alpha dropped.
    let ga = ImageBuffer::from_fn(2, 2, |x, _| LumaA([x as u8 * 100, 7]));
    let d = ok(&png_of(DynamicImage::ImageLumaA8(ga)));
    assert_eq!(
        d.array,
        ArrayData::U8(ArrayD::from_shape_vec(vec![2, 2], vec![0, 100, 0, 100]).expect("shape"))
    );
}

#[test]
fn png_colour_becomes_rec709_luma_on_raw_values() {
    // Y = 0.2126 R + 0.7152 G + 0.0722 B.
    let rgb = ImageBuffer::from_fn(2, 1, |x, _| {
        if x == 0 {
            Rgb([200u8, 100, 50])
        } else {
            Rgb([255, 255, 255])
        }
    });
    let y = ok(&png_of(DynamicImage::ImageRgb8(rgb))).array;
    let expected = 0.2126 * 200.0 + 0.7152 * 100.0 + 0.0722 * 50.0; // 117.65
    assert_eq!(y.shape(), &[1, 2]);
    assert!((f32s(&y)[0] - expected).abs() < 1e-4, "{:?}", f32s(&y));
    assert!((f32s(&y)[1] - 255.0).abs() < 1e-3);

    let rgba16 = ImageBuffer::from_pixel(1, 1, Rgba([60000u16, 30000, 1000, 5]));
    let y = ok(&png_of(DynamicImage::ImageRgba16(rgba16))).array;
    let expected = 0.2126 * 60000.0 + 0.7152 * 30000.0 + 0.0722 * 1000.0;
    assert!((f32s(&y)[0] - expected).abs() < 1e-2, "{:?}", f32s(&y));
}

#[test]
fn png16_encoder_is_exact_on_u16_values() {
    let a = ArrayData::U16(ramp(&[3, 7], |i| (i * 3121 % 65536) as u16));
    let png = encode_png16(&a, Some((0.0, 65535.0))).expect("encodes");
    assert_eq!(ok(&png).array, a);
    // Default range: min..max mapped onto 0..65535.
    let f = ArrayData::F64(ramp(&[1, 3], |i| 10.0 + 5.0 * i as f64));
    let back = ok(&encode_png16(&f, None).expect("encodes")).array;
    assert_eq!(
        back,
        ArrayData::U16(ArrayD::from_shape_vec(vec![1, 3], vec![0, 32768, 65535]).expect("shape"))
    );
}

#[test]
fn jpeg_grey_and_colour_decode_close_to_the_source() {
    // A smooth gradient at quality 100: the error bound is 3 grey levels.
    let g = ImageBuffer::from_fn(32, 16, |x, y| Luma([(4 * x + 2 * y) as u8]));
    let mut jpg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 100)
        .encode_image(&g)
        .expect("jpeg");
    let d = ok(&jpg);
    assert_eq!(d.format, Format::Jpeg);
    let ArrayData::U8(a) = d.array else {
        panic!("expected u8")
    };
    assert_eq!(a.shape(), &[16, 32]);
    let max_err = a
        .indexed_iter()
        .map(|(i, &v)| (i32::from(v) - (4 * i[1] + 2 * i[0]) as i32).abs())
        .max()
        .expect("non-empty");
    assert!(max_err <= 3, "max error {max_err}");

    let c = ImageBuffer::from_pixel(8, 8, Rgb([200u8, 100, 50]));
    let mut jpg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 100)
        .encode_image(&c)
        .expect("jpeg");
    let y = ok(&jpg).array;
    assert_eq!(y.shape(), &[8, 8]);
    // Chroma subsampling and YCbCr rounding move the luma by a few levels.
    assert!(
        f32s(&y).iter().all(|v| (v - 117.65).abs() < 3.0),
        "{:?}",
        &f32s(&y)[..4]
    );
}

#[test]
fn corrupt_and_truncated_png_are_corrupt() {
    let png = png_of(DynamicImage::ImageLuma8(ImageBuffer::from_fn(
        16,
        16,
        |x, y| Luma([(x ^ y) as u8]),
    )));
    let mut bad = png.clone();
    // Flip a byte inside the IDAT data: CRC mismatch or inflate error.
    let idat = bad.windows(4).position(|w| w == b"IDAT").expect("has IDAT");
    bad[idat + 6] ^= 0x55;
    assert!(
        matches!(
            decode(&bad, None, &Limits::default()),
            Err(IoError::Corrupt {
                format: Format::Png,
                ..
            })
        ),
        "{:?}",
        decode(&bad, None, &Limits::default())
    );
    for cut in [8, 20, 40, png.len() - 13] {
        assert!(
            matches!(
                decode(&png[..cut], None, &Limits::default()),
                Err(IoError::Corrupt { .. })
            ),
            "cut {cut}: {:?}",
            decode(&png[..cut], None, &Limits::default())
        );
    }
}

/// A PNG chunk with its CRC.
fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut out = (data.len() as u32).to_be_bytes().to_vec();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let mut crc = flate2::Crc::new();
    crc.update(kind);
    crc.update(data);
    out.extend_from_slice(&crc.sum().to_be_bytes());
    out
}

#[test]
fn png_header_claiming_100000_squared_pixels_is_too_large() {
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]); // 8-bit grey, deflate, no filter, no interlace
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(chunk(b"IHDR", &ihdr));
    png.extend(chunk(
        b"IDAT",
        &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    ));
    png.extend(chunk(b"IEND", &[]));
    match decode(&png, None, &Limits::default()) {
        Err(IoError::TooLarge { what, .. }) => assert!(what.contains("Png"), "{what}"),
        other => panic!("expected TooLarge, got {other:?}"),
    }
    // Within the cell limit but not within a tight byte limit.
    let limits = Limits {
        max_cells: usize::MAX,
        max_bytes: 1 << 20,
    };
    assert!(matches!(
        decode(&png, Some(Format::Png), &limits),
        Err(IoError::TooLarge { .. })
    ));
}

// ---------------------------------------------------------------- TIFF

fn tiff_with<F>(write: F) -> Vec<u8>
where
    F: FnOnce(&mut tiff::encoder::TiffEncoder<&mut Cursor<Vec<u8>>>),
{
    let mut cursor = Cursor::new(Vec::new());
    {
        let mut enc = tiff::encoder::TiffEncoder::new(&mut cursor).expect("encoder");
        write(&mut enc);
    }
    cursor.into_inner()
}

#[test]
fn tiff_grey_types_are_exact() {
    use tiff::encoder::colortype;
    let (w, h) = (5u32, 3u32);
    let n = (w * h) as usize;
    let v8: Vec<u8> = (0..n).map(|i| (i * 17) as u8).collect();
    let v16: Vec<u16> = (0..n).map(|i| (i * 4099) as u16).collect();
    let mut v32: Vec<f32> = (0..n).map(|i| i as f32 * 0.37 - 2.0).collect();
    v32[1] = f32::INFINITY;
    v32[2] = f32::NAN;
    v32[3] = f32::MIN_POSITIVE / 4.0; // subnormal
    let v64: Vec<f64> = (0..n).map(|i| (i as f64).ln_1p() / 3.0).collect();

    let t = tiff_with(|e| e.write_image::<colortype::Gray8>(w, h, &v8).expect("write"));
    let d = ok(&t);
    assert_eq!(d.format, Format::Tiff);
    assert_eq!(
        d.array,
        ArrayData::U8(ArrayD::from_shape_vec(vec![3, 5], v8).expect("shape"))
    );

    let t = tiff_with(|e| {
        e.write_image::<colortype::Gray16>(w, h, &v16)
            .expect("write")
    });
    assert_eq!(
        ok(&t).array,
        ArrayData::U16(ArrayD::from_shape_vec(vec![3, 5], v16).expect("shape"))
    );

    let t = tiff_with(|e| {
        e.write_image::<colortype::Gray32Float>(w, h, &v32)
            .expect("write")
    });
    let back = ok(&t).array;
    assert_eq!(back.shape(), &[3, 5]);
    let bits: Vec<u32> = f32s(&back).iter().map(|v| v.to_bits()).collect();
    let want: Vec<u32> = v32.iter().map(|v| v.to_bits()).collect();
    assert_eq!(bits, want, "float TIFF must be bit-exact");

    let t = tiff_with(|e| {
        e.write_image::<colortype::Gray64Float>(w, h, &v64)
            .expect("write")
    });
    assert_eq!(
        ok(&t).array,
        ArrayData::F64(ArrayD::from_shape_vec(vec![3, 5], v64).expect("shape"))
    );

    let rgb = [200u8, 100, 50, 0, 0, 255];
    let t = tiff_with(|e| e.write_image::<colortype::RGB8>(2, 1, &rgb).expect("write"));
    let y = ok(&t).array;
    assert!((f32s(&y)[0] - 117.65).abs() < 1e-4 && (f32s(&y)[1] - 0.0722 * 255.0).abs() < 1e-4);
}

#[test]
fn tiff_float_encoder_round_trips_2d_and_multipage_3d() {
    let a2 = ArrayData::F32(ramp(&[4, 6], |i| i as f32 / 3.0 - 1.0));
    assert_eq!(ok(&encode_tiff_f32(&a2).expect("encodes")).array, a2);

    let a3 = ArrayData::F32(ramp(&[3, 4, 6], |i| (i as f32).sin()));
    let d = ok(&encode_tiff_f32(&a3).expect("encodes"));
    assert_eq!(d.array.shape(), &[3, 4, 6], "pages are axis 0");
    assert_eq!(d.array, a3);

    // f64 input is rounded to f32.
    let f = ArrayData::F64(ramp(&[2, 2], |i| 0.1 * i as f64));
    let back = ok(&encode_tiff_f32(&f).expect("encodes")).array;
    assert_eq!(
        f32s(&back),
        &[0.0, 0.1f64 as f32, 0.2f64 as f32, (0.1f64 * 3.0) as f32]
    );

    assert!(matches!(
        encode_tiff_f32(&ArrayData::F32(ArrayD::zeros(IxDyn(&[5])))),
        Err(IoError::Encode(_))
    ));
}

#[test]
fn tiff_pages_of_different_sizes_are_refused() {
    use tiff::encoder::colortype;
    let t = tiff_with(|e| {
        e.write_image::<colortype::Gray8>(2, 2, &[1, 2, 3, 4])
            .expect("write");
        e.write_image::<colortype::Gray8>(3, 1, &[1, 2, 3])
            .expect("write");
    });
    match decode(&t, None, &Limits::default()) {
        Err(IoError::Unsupported { reason, .. }) => assert!(reason.contains("page 1"), "{reason}"),
        other => panic!("expected Unsupported, got {other:?}"),
    }
}

/// Rewrites the ImageWidth and ImageLength entries of a little-endian
/// TIFF's first IFD.
fn patch_tiff_size(tiff: &mut [u8], width: u32, height: u32) {
    let ifd = u32::from_le_bytes(tiff[4..8].try_into().expect("4 bytes")) as usize;
    let count = u16::from_le_bytes([tiff[ifd], tiff[ifd + 1]]) as usize;
    for k in 0..count {
        let e = ifd + 2 + 12 * k;
        let tag = u16::from_le_bytes([tiff[e], tiff[e + 1]]);
        let value = match tag {
            256 => width,
            257 => height,
            _ => continue,
        };
        // Store as LONG (type 4), count 1.
        tiff[e + 2..e + 4].copy_from_slice(&4u16.to_le_bytes());
        tiff[e + 4..e + 8].copy_from_slice(&1u32.to_le_bytes());
        tiff[e + 8..e + 12].copy_from_slice(&value.to_le_bytes());
    }
}

#[test]
fn tiff_claiming_a_huge_size_is_too_large() {
    use tiff::encoder::colortype;
    let mut t = tiff_with(|e| {
        e.write_image::<colortype::Gray32Float>(2, 2, &[0.0; 4])
            .expect("write")
    });
    patch_tiff_size(&mut t, 100_000, 100_000);
    assert!(t.starts_with(b"II*\0"));
    match decode(&t, None, &Limits::default()) {
        Err(IoError::TooLarge { .. }) => {}
        other => panic!("expected TooLarge, got {other:?}"),
    }
}

// ---------------------------------------------------------------- NIfTI

/// Writes `data` with the `nifti` crate (axis 0 = i) and the given pixdim,
/// as `.nii` or `.nii.gz`, and returns the file's bytes. (A macro: the
/// writer's element bound names `bytemuck::Pod`, not a dependency here.)
macro_rules! nifti_file {
    ($data:expr, $pixdim:expr, $gz:expr, $tune:expr) => {{
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join(if $gz { "v.nii.gz" } else { "v.nii" });
        let p: [f32; 3] = $pixdim;
        let mut header = nifti::NiftiHeader {
            pixdim: [1.0, p[0], p[1], p[2], 1.0, 1.0, 1.0, 1.0],
            ..Default::default()
        };
        let tune: &dyn Fn(&mut nifti::NiftiHeader) = &$tune;
        tune(&mut header);
        nifti::writer::WriterOptions::new(&path)
            .reference_header(&header)
            .write_nifti($data)
            .expect("nifti write");
        std::fs::read(&path).expect("read back")
    }};
}

#[test]
fn nifti_from_the_nifti_crate_keeps_axis_order_and_spacing() {
    // v[i, j, k] = 100 i + 10 j + k on (nx, ny, nz) = (4, 3, 2).
    let v = ArrayD::from_shape_fn(IxDyn(&[4, 3, 2]), |i| {
        (100 * i[0] + 10 * i[1] + i[2]) as f32
    });
    for gz in [false, true] {
        let bytes = nifti_file!(&v, [0.5, 0.75, 2.5], gz, |_| {});
        assert_eq!(Format::sniff(&bytes), Some(Format::Nifti));
        let d = ok(&bytes);
        assert_eq!(d.format, Format::Nifti);
        assert_eq!(d.spacing, Some(vec![0.5, 0.75, 2.5]), "pixdim[1..=3]");
        assert_eq!(d.array, ArrayData::F32(v.clone()), "gz = {gz}");
    }
}

#[test]
fn nifti_dtypes_map_to_the_nearest_array_dtype() {
    let shape = [3, 2, 2];
    let u8v = ramp(&shape, |i| i as u8 * 20);
    let i16v = ramp(&shape, |i| i as i16 * -1000 + 3);
    let u16v = ramp(&shape, |i| i as u16 * 5000);
    let i32v = ramp(&shape, |i| i as i32 * -100_000);
    let f64v = ramp(&shape, |i| i as f64 / 7.0);
    assert_eq!(
        ok(&nifti_file!(&u8v, [1.0; 3], false, |_| {})).array,
        ArrayData::U8(u8v.clone())
    );
    assert_eq!(
        ok(&nifti_file!(&i16v, [1.0; 3], false, |_| {})).array,
        ArrayData::I32(i16v.mapv(i32::from))
    );
    assert_eq!(
        ok(&nifti_file!(&u16v, [1.0; 3], false, |_| {})).array,
        ArrayData::U16(u16v)
    );
    assert_eq!(
        ok(&nifti_file!(&i32v, [1.0; 3], false, |_| {})).array,
        ArrayData::I32(i32v)
    );
    assert_eq!(
        ok(&nifti_file!(&f64v, [1.0; 3], true, |_| {})).array,
        ArrayData::F64(f64v)
    );

    // scl_slope = 2, scl_inter = 1 on u8: f32 values 2 x + 1.
    // (Patched into the file: the writer resets the scaling of raw data.)
    let mut bytes = nifti_file!(&u8v, [1.0; 3], false, |_| {});
    bytes[112..116].copy_from_slice(&2f32.to_le_bytes());
    bytes[116..120].copy_from_slice(&1f32.to_le_bytes());
    let scaled = ok(&bytes);
    assert_eq!(
        scaled.array,
        ArrayData::F32(u8v.mapv(|x| 2.0 * f32::from(x) + 1.0))
    );
}

#[test]
fn nifti_big_endian_is_read() {
    let v = ramp(&[2, 3, 2], |i| i as f32 - 0.5);
    let bytes = nifti_file!(&v, [1.0, 2.0, 3.0], false, |h| {
        h.endianness = nifti::Endianness::Big;
    });
    assert_eq!(&bytes[0..4], &348i32.to_be_bytes(), "written big endian");
    let d = ok(&bytes);
    assert_eq!(d.array, ArrayData::F32(v));
    assert_eq!(d.spacing, Some(vec![1.0, 2.0, 3.0]));
}

#[test]
fn nifti_encoder_round_trips_every_dtype() {
    for a in every_dtype(&[4, 3, 2]) {
        let bytes = encode_nifti(&a, Some(&[0.5, 1.0, 2.0])).expect("encodes");
        let d = ok(&bytes);
        let want = match &a {
            ArrayData::Bool(b) => ArrayData::U8(b.mapv(u8::from)),
            other => other.clone(),
        };
        assert_eq!(d.array, want, "{:?}", a.dtype());
        assert_eq!(d.spacing, Some(vec![0.5, 1.0, 2.0]));
    }
    // The nifti crate reads our files with the same axis order.
    let a = ramp(&[4, 3, 2], |i| i as f32);
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("ours.nii");
    std::fs::write(
        &path,
        encode_nifti(&ArrayData::F32(a.clone()), None).expect("encodes"),
    )
    .expect("write");
    let obj = nifti::ReaderOptions::new()
        .read_file(&path)
        .expect("nifti reads it");
    use nifti::{IntoNdArray, NiftiObject};
    let theirs = obj.into_volume().into_ndarray::<f32>().expect("ndarray");
    assert_eq!(theirs, a);
}

#[test]
fn nifti_truncated_or_huge_is_refused_before_reading() {
    let a = ArrayData::F32(ramp(&[8, 8, 8], |i| i as f32));
    let bytes = encode_nifti(&a, None).expect("encodes");
    match decode(&bytes[..bytes.len() - 1], None, &Limits::default()) {
        Err(IoError::Corrupt { reason, .. }) => {
            assert!(
                reason.contains("2048") && reason.contains("2047"),
                "{reason}"
            )
        }
        other => panic!("expected Corrupt, got {other:?}"),
    }
    // dim = (30000, 30000, 30000): 2.7e13 cells.
    let mut huge = bytes.clone();
    for k in 1..=3 {
        huge[40 + 2 * k..42 + 2 * k].copy_from_slice(&30000i16.to_le_bytes());
    }
    assert!(matches!(
        decode(&huge, None, &Limits::default()),
        Err(IoError::TooLarge { .. })
    ));
    // Gzipped: refused from the header, before inflating the payload.
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, &huge).expect("gzip");
    let gz = gz.finish().expect("gzip");
    assert_eq!(Format::sniff(&gz), Some(Format::Nifti));
    assert!(matches!(
        decode(&gz, None, &Limits::default()),
        Err(IoError::TooLarge { .. })
    ));
    // A gzip stream that is not NIfTI.
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, b"hello").expect("gzip");
    let gz = gz.finish().expect("gzip");
    assert!(matches!(
        decode(&gz, None, &Limits::default()),
        Err(IoError::Corrupt { .. })
    ));
}

// ---------------------------------------------------------------- render

#[test]
fn render_png_gives_an_rgb_image_of_the_array_size() {
    let u = ramp(&[6, 9], |i| if i == 5 { f64::INFINITY } else { i as f64 });
    let png = render_png(&ArrayData::F64(u), &RenderOptions::default()).expect("renders");
    let img = image::load_from_memory(&png).expect("png");
    assert_eq!((img.width(), img.height()), (9, 6));
    assert_eq!(img.color(), image::ColorType::Rgb8);
}

// ---------------------------------------------------------------- robustness

/// One small valid file of every format and flavour.
fn samples() -> &'static Vec<Vec<u8>> {
    static SAMPLES: OnceLock<Vec<Vec<u8>>> = OnceLock::new();
    SAMPLES.get_or_init(|| {
        use tiff::encoder::colortype;
        let mut s = Vec::new();
        for a in every_dtype(&[3, 4]) {
            s.push(encode_npy(&a).expect("npy"));
        }
        s.push(png_of(DynamicImage::ImageLuma8(ImageBuffer::from_fn(
            7,
            5,
            |x, y| Luma([(x * y) as u8]),
        ))));
        s.push(png_of(DynamicImage::ImageRgb16(ImageBuffer::from_fn(
            5,
            3,
            |x, _| Rgb([x as u16 * 999, 7, 65535]),
        ))));
        let mut jpg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 80)
            .encode_image(&ImageBuffer::from_fn(9, 7, |x, y| {
                Rgb([x as u8 * 20, y as u8 * 30, 99])
            }))
            .expect("jpeg");
        s.push(jpg);
        s.push(tiff_with(|e| {
            e.write_image::<colortype::Gray16>(3, 2, &[1, 2, 3, 4, 5, 6])
                .expect("tiff")
        }));
        s.push(encode_tiff_f32(&ArrayData::F32(ramp(&[2, 3, 4], |i| i as f32))).expect("tiff"));
        let vol = ArrayData::I32(ramp(&[3, 2, 2], |i| i as i32));
        let nii = encode_nifti(&vol, None).expect("nifti");
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut gz, &nii).expect("gzip");
        s.push(gz.finish().expect("gzip"));
        s.push(nii);
        s
    })
}

const HINTS: [Option<Format>; 6] = [
    None,
    Some(Format::Npy),
    Some(Format::Png),
    Some(Format::Jpeg),
    Some(Format::Tiff),
    Some(Format::Nifti),
];

/// Small limits so that a mutated header cannot make a test allocate much.
const FUZZ_LIMITS: Limits = Limits {
    max_cells: 1 << 16,
    max_bytes: 1 << 20,
};

#[test]
fn every_sample_decodes() {
    for (k, s) in samples().iter().enumerate() {
        assert!(
            decode(s, None, &FUZZ_LIMITS).is_ok(),
            "sample {k}: {:?}",
            decode(s, None, &FUZZ_LIMITS)
        );
    }
}

proptest! {
    // 256 cases by default; set PROPTEST_CASES for a longer fuzzing run.
    #![proptest_config(ProptestConfig::default())]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600), hint in 0usize..6) {
        let _ = decode(&bytes, HINTS[hint], &FUZZ_LIMITS);
    }

    #[test]
    fn random_bytes_after_a_magic_never_panic(
        which in 0usize..6,
        tail in proptest::collection::vec(any::<u8>(), 0..600),
    ) {
        let magic: [&[u8]; 6] = [
            b"\x93NUMPY\x01\x00", b"\x89PNG\r\n\x1a\n", &[0xFF, 0xD8, 0xFF], b"II*\0", b"MM\0*", &[0x1F, 0x8B, 8, 0],
        ];
        let mut bytes = magic[which].to_vec();
        bytes.extend(tail);
        let _ = decode(&bytes, None, &FUZZ_LIMITS);
    }

    #[test]
    fn truncated_valid_files_never_panic_and_fail(which in 0usize..64, cut in 0.0f64..1.0) {
        let s = &samples()[which % samples().len()];
        let n = (cut * s.len() as f64) as usize;
        // Every strict prefix is refused (no format here accepts a short file).
        let result = decode(&s[..n], None, &FUZZ_LIMITS);
        prop_assert!(result.is_err(), "prefix {n}/{} of sample {} decoded", s.len(), which % samples().len());
    }

    #[test]
    fn mutated_valid_files_never_panic(
        which in 0usize..64,
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        hint in 0usize..6,
    ) {
        let mut s = samples()[which % samples().len()].clone();
        for (at, byte) in flips {
            let i = at.index(s.len());
            s[i] = byte;
        }
        let _ = decode(&s, HINTS[hint], &FUZZ_LIMITS);
    }
}

/// `declared_size` reads the size a file announces without decoding its
/// payload: a gzipped 256³ NIfTI of zeros (a few KB on the wire) declares
/// 16.8 MB, and the answer comes from the header alone (a truncated
/// payload does not matter); a PNG and an NPY declare their shapes too.
#[test]
fn declared_sizes_come_from_headers() {
    use std::io::Write;
    let n = 256;
    let zeros = ArrayData::U8(ndarray::ArrayD::zeros(ndarray::IxDyn(&[n, n, n])));
    let nii = geodex::io::encode_nifti(&zeros, Some(&[1.0, 1.0, 1.0])).expect("nifti");
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    gz.write_all(&nii).expect("gzip");
    let bomb = gz.finish().expect("gzip");
    assert!(bomb.len() < 100_000, "{} bytes", bomb.len());
    let limits = Limits::default();
    let declared = geodex::io::declared_size(&bomb, None, &limits).expect("probe");
    assert_eq!(declared, Some((n * n * n, n * n * n)));
    // Only the header is read: the first kilobyte is enough.
    let head =
        geodex::io::declared_size(&nii[..1024], Some(Format::Nifti), &limits).expect("probe");
    assert_eq!(head, Some((n * n * n, n * n * n)));
    let f = ArrayData::F64(ndarray::ArrayD::zeros(ndarray::IxDyn(&[30, 40])));
    let npy = encode_npy(&f).expect("npy");
    assert_eq!(
        geodex::io::declared_size(&npy, None, &limits).expect("probe"),
        Some((1200, 9600))
    );
    let mut png = Vec::new();
    DynamicImage::ImageLuma8(ImageBuffer::new(50, 20))
        .write_to(&mut Cursor::new(&mut png), ImageFormat::Png)
        .expect("png");
    assert_eq!(
        geodex::io::declared_size(&png, None, &limits).expect("probe"),
        Some((1000, 1000))
    );
    // The probe leaves normal decoding alone on this thread.
    assert!(decode(&npy, None, &limits).is_ok());
    // A file over the limits is refused by the probe as by the decoder.
    let small = Limits {
        max_cells: 100,
        max_bytes: 800,
    };
    assert!(matches!(
        geodex::io::declared_size(&npy, None, &small),
        Err(IoError::TooLarge { .. })
    ));
}
