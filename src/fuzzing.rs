//! Entry points for fuzzing: one function per parser the service runs on
//! bytes from a client. The AFL targets in `fuzz/` call them, and
//! `tests/fuzz_corpus.rs` replays the saved corpus through them in the
//! normal `cargo test`, so both run the same code.
//!
//! Each function takes arbitrary bytes, runs the path the service runs on
//! an upload or a request body, with the service's default limits
//! ([`crate::config::ServeArgs::default`]), and ignores every error the
//! parser returns: those become 4xx answers. It panics only on a bug: a
//! panic inside a parser, or a broken invariant checked here (a file the
//! decoder accepts is refused by the size probe, a stored mesh does not
//! read back, a request's canonical JSON does not read back to itself).

use crate::config::ServeArgs;
use crate::http::routes::datasets::sniff_mismatch;
use crate::io::mesh::{ply, read_mesh, write, MeshFormat, MeshLimits};
use crate::io::{declared_size, decode, Format};
use crate::ops::registry::ENTRIES;

/// A fuzz target: arbitrary bytes in, a panic only on a bug.
pub type Target = fn(&[u8]);

/// Every fuzz target by name: the names of `fuzz/src/bin/*.rs` and of the
/// folders under `fuzz/corpus/`.
pub const TARGETS: &[(&str, Target)] = &[
    ("png", png),
    ("jpeg", jpeg),
    ("tiff", tiff),
    ("npy", npy),
    ("nifti", nifti),
    ("obj", obj),
    ("ply", ply),
    ("off", off),
    ("stl", stl),
    ("json_bodies", json_bodies),
];

/// A PNG upload (`Content-Type: image/png`).
pub fn png(bytes: &[u8]) {
    array_upload(bytes, Format::Png);
}

/// A JPEG upload (`Content-Type: image/jpeg`).
pub fn jpeg(bytes: &[u8]) {
    array_upload(bytes, Format::Jpeg);
}

/// A TIFF upload (`Content-Type: image/tiff`).
pub fn tiff(bytes: &[u8]) {
    array_upload(bytes, Format::Tiff);
}

/// An NPY upload (`Content-Type: application/x-npy`).
pub fn npy(bytes: &[u8]) {
    array_upload(bytes, Format::Npy);
}

/// A NIfTI-1 upload, plain or gzipped (`Content-Type: application/x-nifti`).
pub fn nifti(bytes: &[u8]) {
    array_upload(bytes, Format::Nifti);
}

/// An OBJ mesh upload.
pub fn obj(bytes: &[u8]) {
    mesh_upload(bytes, MeshFormat::Obj);
}

/// A PLY mesh upload.
pub fn ply(bytes: &[u8]) {
    mesh_upload(bytes, MeshFormat::Ply);
}

/// An OFF mesh upload.
pub fn off(bytes: &[u8]) {
    mesh_upload(bytes, MeshFormat::Off);
}

/// An STL mesh upload.
pub fn stl(bytes: &[u8]) {
    mesh_upload(bytes, MeshFormat::Stl);
}

/// A request body: the operation's name (`grid.distance`), a newline, then
/// the JSON body. The body is parsed as the endpoint parses it; a request
/// that parses is validated, and one that passes validation is turned into
/// its canonical JSON (what a job stores), which must parse again, pass
/// validation again and give the same canonical JSON.
pub fn json_bodies(input: &[u8]) {
    let Some(split) = input.iter().position(|&b| b == b'\n') else {
        return;
    };
    let (name, body) = (&input[..split], &input[split + 1..]);
    let Some(entry) = ENTRIES.iter().find(|e| e.name.as_bytes() == name) else {
        return;
    };
    let limits = crate::app::op_limits(&ServeArgs::default());
    let Ok(request) = (entry.parse)(body) else {
        return;
    };
    if request.validate(&limits).is_err() {
        return;
    }
    let canonical = match request.canonical_json() {
        Ok(c) => c,
        Err(e) => panic!("{}: a valid request has no canonical JSON: {e}", entry.name),
    };
    let again = match (entry.parse)(canonical.as_bytes()) {
        Ok(r) => r,
        Err(e) => panic!(
            "{}: canonical JSON {canonical} does not parse: {e}",
            entry.name
        ),
    };
    if let Err(e) = again.validate(&limits) {
        panic!(
            "{}: canonical JSON {canonical} fails validation: {e}",
            entry.name
        );
    }
    let twice = again.canonical_json();
    assert!(
        twice.as_deref().ok() == Some(canonical.as_str()),
        "{}: canonical JSON does not read back to the same request:\n{canonical}\n{twice:?}",
        entry.name
    );
}

/// What `POST /datasets` does with an array upload sent with the type of
/// `format`: refuse bytes whose magic names another format, probe the
/// declared size, decode.
fn array_upload(bytes: &[u8], format: Format) {
    if sniff_mismatch(bytes, Some(format)).is_some() {
        return;
    }
    let limits = crate::app::io_limits(&ServeArgs::default());
    let declared = declared_size(bytes, Some(format), &limits);
    let Ok(decoded) = decode(bytes, Some(format), &limits) else {
        return;
    };
    if let Err(e) = declared {
        panic!("the decoder accepts what the size probe refuses: {e}");
    }
    let cells: usize = decoded.array.shape().iter().product();
    assert!(
        cells <= limits.max_cells,
        "decoded {cells} cells, more than the limit"
    );
}

/// What `POST /meshes` does with a mesh upload of `format`, then what
/// reading the stored mesh does: it is stored as binary PLY and read back
/// (vertex values too), which must give the same mesh.
fn mesh_upload(bytes: &[u8], format: MeshFormat) {
    let limits = MeshLimits::default();
    let Ok(loaded) = read_mesh(bytes, Some(format), &limits) else {
        return;
    };
    let stored = write::write_ply(&loaded.mesh, &[]);
    let back = match read_mesh(&stored, Some(MeshFormat::Ply), &limits) {
        Ok(back) => back,
        Err(e) => panic!("a stored mesh does not read back: {e}"),
    };
    assert!(
        back.mesh.positions() == loaded.mesh.positions()
            && back.mesh.faces() == loaded.mesh.faces(),
        "a stored mesh reads back different"
    );
    if let Err(e) = ply::vertex_values(&stored) {
        panic!("the vertex values of a stored mesh do not read: {e}");
    }
}
