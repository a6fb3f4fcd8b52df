//! Writes the seed corpus under `fuzz/corpus/<target>/` (run from `fuzz/`:
//! `cargo run --release --bin seeds`): small valid files of every format,
//! most made by geodex's own writers, and one request body per operation
//! taken from `api/examples.json`. AFL starts from these; `run.sh` then
//! replaces each folder by the minimised queue.

use std::io::{Cursor, Write};
use std::path::Path;

use geodex::io::mesh::write::{write_obj, write_ply, VertexProperty};
use geodex::io::{encode_nifti, encode_npy, encode_png16, encode_tiff_f32, ArrayData};
use geodex::numerics::mesh::TriMesh;
use ndarray::{ArrayD, IxDyn};

type Seeds = Vec<(String, Vec<u8>)>;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let sets: [(&str, Seeds); 10] = [
        ("png", png()?),
        ("jpeg", jpeg()?),
        ("tiff", tiff()?),
        ("npy", npy()?),
        ("nifti", nifti()?),
        ("obj", obj()?),
        ("ply", ply()?),
        ("off", off()),
        ("stl", stl()),
        ("json_bodies", json_bodies(root)?),
    ];
    for (target, seeds) in sets {
        let dir = root.join("corpus").join(target);
        std::fs::create_dir_all(&dir)?;
        for (name, bytes) in seeds {
            assert!(bytes.len() < 64 << 10, "{target}/{name} is too large");
            std::fs::write(dir.join(format!("seed-{name}")), bytes)?;
        }
    }
    Ok(())
}

fn ramp<T>(shape: &[usize], f: impl Fn(usize) -> T) -> ArrayD<T> {
    let n = shape.iter().product();
    ArrayD::from_shape_vec(IxDyn(shape), (0..n).map(f).collect()).expect("shape and length agree")
}

fn png() -> Result<Seeds, Box<dyn std::error::Error>> {
    let a = ArrayData::F64(ramp(&[6, 9], |i| i as f64 * 0.5));
    let mut out = vec![("u16.png".to_string(), encode_png16(&a, None)?)];
    let (w, h) = (7u32, 5u32);
    let grey: Vec<u8> = (0..w * h).map(|i| (i * 7) as u8).collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 5) as u8).collect();
    let rgba: Vec<u8> = (0..w * h * 4).map(|i| (i * 3) as u8).collect();
    let la: Vec<u8> = (0..w * h * 2).map(|i| (i * 11) as u8).collect();
    use image::ExtendedColorType as C;
    for (name, data, ty) in [
        ("l8.png", &grey, C::L8),
        ("rgb8.png", &rgb, C::Rgb8),
        ("rgba8.png", &rgba, C::Rgba8),
        ("la8.png", &la, C::La8),
    ] {
        let mut buf = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut buf),
            data,
            w,
            h,
            ty,
        )?;
        out.push((name.to_string(), buf));
    }
    Ok(out)
}

fn jpeg() -> Result<Seeds, Box<dyn std::error::Error>> {
    let (w, h) = (16u32, 12u32);
    let grey: Vec<u8> = (0..w * h).map(|i| (i * 7) as u8).collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 5) as u8).collect();
    let mut out = Vec::new();
    for (name, data, ty, q) in [
        ("grey.jpg", &grey, image::ExtendedColorType::L8, 50),
        ("rgb.jpg", &rgb, image::ExtendedColorType::Rgb8, 75),
    ] {
        let mut buf = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, q),
            data,
            w,
            h,
            ty,
        )?;
        out.push((name.to_string(), buf));
    }
    Ok(out)
}

fn tiff() -> Result<Seeds, Box<dyn std::error::Error>> {
    use tiff::encoder::{colortype, TiffEncoder};
    let mut out = vec![
        (
            "f32.tif".to_string(),
            encode_tiff_f32(&ArrayData::F32(ramp(&[5, 6], |i| i as f32 * 0.25)))?,
        ),
        (
            "f32-pages.tif".to_string(),
            encode_tiff_f32(&ArrayData::F32(ramp(&[2, 3, 4], |i| i as f32)))?,
        ),
    ];
    let (w, h) = (6u32, 4u32);
    let grey: Vec<u8> = (0..w * h).map(|i| (i * 9) as u8).collect();
    let grey16: Vec<u16> = (0..w * h).map(|i| (i * 999) as u16).collect();
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 5) as u8).collect();
    let mut buf = Cursor::new(Vec::new());
    TiffEncoder::new(&mut buf)?.write_image::<colortype::Gray8>(w, h, &grey)?;
    out.push(("u8.tif".to_string(), buf.into_inner()));
    let mut buf = Cursor::new(Vec::new());
    TiffEncoder::new(&mut buf)?.write_image::<colortype::Gray16>(w, h, &grey16)?;
    out.push(("u16.tif".to_string(), buf.into_inner()));
    let mut buf = Cursor::new(Vec::new());
    TiffEncoder::new(&mut buf)?.write_image::<colortype::RGB8>(w, h, &rgb)?;
    out.push(("rgb8.tif".to_string(), buf.into_inner()));
    Ok(out)
}

fn npy() -> Result<Seeds, Box<dyn std::error::Error>> {
    let arrays = [
        ("f64-2d", ArrayData::F64(ramp(&[3, 4], |i| i as f64 / 3.0))),
        ("f32-3d", ArrayData::F32(ramp(&[2, 2, 3], |i| i as f32))),
        ("u8-1d", ArrayData::U8(ramp(&[7], |i| i as u8))),
        ("u16-2d", ArrayData::U16(ramp(&[2, 3], |i| i as u16 * 300))),
        ("bool-2d", ArrayData::Bool(ramp(&[3, 3], |i| i % 2 == 0))),
        ("i32-2d", ArrayData::I32(ramp(&[2, 2], |i| i as i32 - 2))),
        ("i64-2d", ArrayData::I64(ramp(&[2, 2], |i| i as i64 * -7))),
    ];
    let mut out = Vec::new();
    for (name, a) in arrays {
        let bytes = encode_npy(&a)?;
        // The same header in Fortran order (same length: the padding absorbs it).
        let text = String::from_utf8_lossy(&bytes[..bytes.len().min(128)]).into_owned();
        if let Some(at) = text.find("'fortran_order': False") {
            let mut f = bytes.clone();
            f[at..at + 22].copy_from_slice(b"'fortran_order': True ");
            out.push((format!("{name}-fortran.npy"), f));
        }
        out.push((format!("{name}.npy"), bytes));
    }
    Ok(out)
}

fn nifti() -> Result<Seeds, Box<dyn std::error::Error>> {
    let volume = ArrayData::F32(ramp(&[3, 4, 2], |i| i as f32 * 0.5));
    let slice = ArrayData::U8(ramp(&[4, 5], |i| i as u8));
    let labels = ArrayData::I32(ramp(&[2, 2, 2], |i| i as i32));
    let mut out = Vec::new();
    for (name, a, spacing) in [
        ("f32-3d", &volume, Some(&[0.5, 1.0, 2.0][..])),
        ("u8-2d", &slice, None),
        ("i32-3d", &labels, Some(&[1.0, 1.0, 1.0][..])),
    ] {
        let nii = encode_nifti(a, spacing)?;
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        gz.write_all(&nii)?;
        out.push((format!("{name}.nii.gz"), gz.finish()?));
        out.push((format!("{name}.nii"), nii));
    }
    Ok(out)
}

/// A unit cube: 8 vertices, 12 triangles.
fn cube() -> Result<TriMesh, Box<dyn std::error::Error>> {
    let p: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            [
                f64::from(i & 1),
                f64::from((i >> 1) & 1),
                f64::from((i >> 2) & 1),
            ]
        })
        .collect();
    let f = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    Ok(TriMesh::new(p, f)?)
}

fn obj() -> Result<Seeds, Box<dyn std::error::Error>> {
    Ok(vec![
        ("cube.obj".into(), write_obj(&cube()?)),
        (
            "quads.obj".into(),
            b"# two quads\no sheet\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0.5\nv 2 1 0.5\n\
              vn 0 0 1\nvt 0 0\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf 2//1 5//1 6//1 3//1\n"
                .to_vec(),
        ),
        (
            "negative.obj".into(),
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf -4 -3 -2\nf -4 -2 -1\ns off\ng x\n".to_vec(),
        ),
    ])
}

fn ply() -> Result<Seeds, Box<dyn std::error::Error>> {
    let cube = cube()?;
    let distance: Vec<f64> = (0..8).map(|i| f64::from(i) * 0.5).collect();
    let label: Vec<i32> = (0..8).map(|i| i % 3).collect();
    let ascii = b"ply\nformat ascii 1.0\ncomment tetra\nelement vertex 4\n\
        property float x\nproperty float y\nproperty float z\nproperty double distance\n\
        element face 4\nproperty list uchar int vertex_indices\n\
        element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n\
        0 0 0 0\n1 0 0 1\n0 1 0 1\n0 0 1 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n0 1\n";
    let mut big_endian = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\n\
        property float x\nproperty float y\nproperty float z\n\
        element face 1\nproperty list uchar uint vertex_index\nend_header\n"
        .to_vec();
    for v in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        for c in v {
            big_endian.extend_from_slice(&c.to_be_bytes());
        }
    }
    big_endian.push(3);
    for i in [0u32, 1, 2] {
        big_endian.extend_from_slice(&i.to_be_bytes());
    }
    Ok(vec![
        ("cube.ply".into(), write_ply(&cube, &[])),
        (
            "cube-props.ply".into(),
            write_ply(
                &cube,
                &[
                    VertexProperty::F64("distance", &distance),
                    VertexProperty::I32("label", &label),
                ],
            ),
        ),
        ("tetra-ascii.ply".into(), ascii.to_vec()),
        ("triangle-be.ply".into(), big_endian),
    ])
}

fn off() -> Seeds {
    vec![
        (
            "tetra.off".into(),
            b"OFF\n# tetrahedron\n4 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
                .to_vec(),
        ),
        (
            "quad-colour.off".into(),
            b"COFF\n4 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n4 0 1 2 3 1 0 0\n"
                .to_vec(),
        ),
    ]
}

fn stl() -> Seeds {
    let tris = [
        [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]],
        [[0., 0., 0.], [0., 0., 1.], [1., 0., 0.]],
        [[0., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
        [[1., 0., 0.], [0., 0., 1.], [0., 1., 0.]],
    ];
    let mut binary = vec![0u8; 80];
    binary[..6].copy_from_slice(b"binary");
    binary.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    let mut ascii = String::from("solid tetra\n");
    for t in &tris {
        binary.extend_from_slice(&[0u8; 12]);
        ascii.push_str(" facet normal 0 0 0\n  outer loop\n");
        for v in t {
            for c in v {
                binary.extend_from_slice(&c.to_le_bytes());
            }
            ascii.push_str(&format!("   vertex {} {} {}\n", v[0], v[1], v[2]));
        }
        binary.extend_from_slice(&[0u8; 2]);
        ascii.push_str("  endloop\n endfacet\n");
    }
    ascii.push_str("endsolid tetra\n");
    vec![
        ("tetra-binary.stl".into(), binary),
        ("tetra-ascii.stl".into(), ascii.into_bytes()),
    ]
}

/// Every example request body of `api/examples.json` and `api/examples/`,
/// under the name of each operation that accepts it.
fn json_bodies(root: &Path) -> Result<Seeds, Box<dyn std::error::Error>> {
    let api = root.join("../api");
    let examples: serde_json::Value =
        serde_json::from_slice(&std::fs::read(api.join("examples.json"))?)?;
    let mut bodies: Vec<serde_json::Value> = examples
        .as_object()
        .into_iter()
        .flat_map(|m| m.values())
        .filter_map(|e| e.get("request").cloned())
        .filter(serde_json::Value::is_object)
        .collect();
    for file in std::fs::read_dir(api.join("examples"))? {
        let path = file?.path();
        if path.extension().is_some_and(|e| e == "json") {
            bodies.push(serde_json::from_slice(&std::fs::read(&path)?)?);
        }
    }
    let mut out = Vec::new();
    for entry in geodex::ops::registry::ENTRIES {
        let mut k = 0;
        for body in &bodies {
            let text = serde_json::to_string(body)?;
            if (entry.parse)(text.as_bytes()).is_ok() {
                let mut seed = format!("{}\n", entry.name).into_bytes();
                seed.extend_from_slice(text.as_bytes());
                out.push((format!("{}-{k}.json", entry.name), seed));
                k += 1;
            }
        }
        if k == 0 {
            eprintln!("no example body for {}", entry.name);
        }
    }
    Ok(out)
}
