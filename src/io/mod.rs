//! Codecs between bytes and arrays: the layer between the numerical core and
//! the service. Decoders check declared sizes against [`Limits`] *before*
//! allocating, and never panic on malformed input.
//!
//! * [`array`]: [`ArrayData`], an n-dimensional array of one of the supported dtypes.
//! * [`npy`]: NumPy `.npy` (read and write, every dtype).
//! * [`raster`]: PNG and JPEG through the `image` crate (read), 16-bit PNG (write).
//! * [`tiff`]: TIFF through the `tiff` crate (read grey/colour/float, multi-page;
//!   write 32-bit float).
//! * [`nifti`]: NIfTI-1 `.nii` / `.nii.gz` (read, write).
//! * [`render`]: colour-mapped 8-bit PNG previews for people (colour bar,
//!   slices and montages, label overlays, tensor glyphs); [`canvas`]: the
//!   pixels and the bitmap font they are drawn with.
//! * [`mesh`]: triangle meshes (OBJ, PLY, OFF, STL in; PLY, OBJ, JSON out).
//!
//! # Axis conventions
//!
//! Images are returned as `(rows, cols)` = `(height, width)`: axis 0 runs down
//! the image. Multi-page TIFFs are `(pages, rows, cols)`. NIfTI volumes are
//! returned as `(nx, ny, nz)`: axis 0 is the NIfTI `i` (x) axis, the one stored
//! fastest in the file, and [`Decoded::spacing`] is `(dx, dy, dz)`.
//!
//! # Examples
//!
//! ```
//! use geodex::io::{decode, encode_npy, ArrayData, Format, Limits};
//! use ndarray::ArrayD;
//!
//! let a = ArrayData::F64(ArrayD::from_shape_vec(vec![2, 3], vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0])?);
//! let bytes = encode_npy(&a)?;
//! let back = decode(&bytes, None, &Limits::default())?;
//! assert_eq!(back.format, Format::Npy);
//! assert_eq!(back.array, a);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod array;
pub mod canvas;
pub mod mesh;
pub mod mesh_picture;
pub mod nifti;
pub mod npy;
pub mod raster;
pub mod render;
pub mod tiff;

pub use array::{ArrayData, DType};
pub use nifti::encode_nifti;
pub use npy::encode_npy;
pub use raster::encode_png16;
pub use render::{
    default_iso_lines, render_png, render_png_over, Colormap, IsoLines, Overlay, RenderOptions,
    RenderStyle, View,
};
pub use tiff::encode_tiff_f32;

/// A file format the codecs know.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// NumPy `.npy` (f32, f64, u8, u16, bool, i32, i64; 1D to 3D).
    Npy,
    /// PNG, 8 or 16 bit, grey or colour (converted to grey).
    Png,
    /// JPEG (converted to grey).
    Jpeg,
    /// TIFF, including 32-bit float.
    Tiff,
    /// NIfTI-1 `.nii` or `.nii.gz` volume.
    Nifti,
}

impl Format {
    /// Every format, in a fixed order.
    pub const ALL: [Format; 5] = [
        Format::Npy,
        Format::Png,
        Format::Jpeg,
        Format::Tiff,
        Format::Nifti,
    ];

    /// The format named by an HTTP media type (`Content-Type`), parameters
    /// and case ignored.
    ///
    /// * `Ok(Some(format))` for a specific type: `application/x-npy`
    ///   (also `application/npy`), `image/png`, `image/jpeg` (also
    ///   `image/jpg`, `image/pjpeg`), `image/tiff`, `application/x-nifti`
    ///   (also `application/x-nifti-1`, `image/x-nifti`), and
    ///   `application/gzip` / `application/x-gzip` (only gzipped NIfTI is
    ///   supported, so they mean NIfTI).
    /// * `Ok(None)` for `application/octet-stream` or an empty string: the
    ///   caller should let [`decode`] detect the format from magic bytes.
    /// * `Err(IoError::UnknownFormat)` for anything else.
    ///
    /// # Examples
    ///
    /// ```
    /// use geodex::io::Format;
    /// assert_eq!(Format::from_media_type("image/PNG; charset=binary")?, Some(Format::Png));
    /// assert_eq!(Format::from_media_type("application/octet-stream")?, None);
    /// assert!(Format::from_media_type("text/html").is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn from_media_type(media_type: &str) -> Result<Option<Format>, IoError> {
        let essence = media_type
            .split(';')
            .next()
            .unwrap_or_default()
            .trim()
            .to_ascii_lowercase();
        Ok(Some(match essence.as_str() {
            "" | "application/octet-stream" => return Ok(None),
            "application/x-npy" | "application/npy" => Format::Npy,
            "image/png" => Format::Png,
            "image/jpeg" | "image/jpg" | "image/pjpeg" => Format::Jpeg,
            "image/tiff" | "image/tif" => Format::Tiff,
            "application/x-nifti"
            | "application/x-nifti-1"
            | "image/x-nifti"
            | "application/gzip"
            | "application/x-gzip" => Format::Nifti,
            _ => {
                return Err(IoError::UnknownFormat(format!(
                    "media type '{essence}' is not one of application/x-npy, image/png, \
                     image/jpeg, image/tiff, application/x-nifti, application/gzip, \
                     application/octet-stream"
                )))
            }
        }))
    }

    /// The media type to send this format with. NIfTI is `application/x-nifti`
    /// (uncompressed `.nii`, as [`encode_nifti`] writes it).
    pub fn media_type(self) -> &'static str {
        match self {
            Format::Npy => "application/x-npy",
            Format::Png => "image/png",
            Format::Jpeg => "image/jpeg",
            Format::Tiff => "image/tiff",
            Format::Nifti => "application/x-nifti",
        }
    }

    /// The usual file extension, without the dot (`nii` for NIfTI).
    pub fn extension(self) -> &'static str {
        match self {
            Format::Npy => "npy",
            Format::Png => "png",
            Format::Jpeg => "jpg",
            Format::Tiff => "tif",
            Format::Nifti => "nii",
        }
    }

    /// The format of a file name or a bare extension (`"scan.nii.gz"`,
    /// `".tiff"`, `"npy"`), case ignored; `None` if unknown.
    ///
    /// # Examples
    ///
    /// ```
    /// use geodex::io::Format;
    /// assert_eq!(Format::from_extension("brain.NII.GZ"), Some(Format::Nifti));
    /// assert_eq!(Format::from_extension(".tiff"), Some(Format::Tiff));
    /// assert_eq!(Format::from_extension("jpeg"), Some(Format::Jpeg));
    /// assert_eq!(Format::from_extension("notes.txt"), None);
    /// ```
    pub fn from_extension(name: &str) -> Option<Format> {
        let lower = name.trim().to_ascii_lowercase();
        let lower = lower.strip_suffix(".gz").map_or(lower.as_str(), |stem| {
            // Only NIfTI is read gzipped.
            if stem.ends_with("nii") {
                "nii"
            } else {
                "\0"
            }
        });
        let ext = lower.rsplit('.').next().unwrap_or_default();
        Some(match ext {
            "npy" => Format::Npy,
            "png" => Format::Png,
            "jpg" | "jpeg" | "jpe" => Format::Jpeg,
            "tif" | "tiff" => Format::Tiff,
            "nii" => Format::Nifti,
            _ => return None,
        })
    }

    /// The format announced by the first bytes of a file, if any: NPY
    /// `\x93NUMPY`, PNG `\x89PNG\r\n\x1a\n`, JPEG `FF D8 FF`, TIFF `II*\0` /
    /// `MM\0*` (and BigTIFF `II+\0` / `MM\0+`), NIfTI-1 (`sizeof_hdr` = 348 in
    /// either byte order and magic `n+1\0` or `ni1\0` at offset 344) and gzip
    /// `1F 8B` (taken to be a gzipped NIfTI-1 file).
    pub fn sniff(bytes: &[u8]) -> Option<Format> {
        if bytes.starts_with(npy::MAGIC) {
            Some(Format::Npy)
        } else if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            Some(Format::Png)
        } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
            Some(Format::Jpeg)
        } else if [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"]
            .iter()
            .any(|m| bytes.starts_with(*m))
        {
            Some(Format::Tiff)
        } else if nifti::is_gzip(bytes) || nifti::is_nifti1_header(bytes) {
            Some(Format::Nifti)
        } else {
            None
        }
    }
}

/// Size limits checked against a file's declared dimensions before any allocation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest number of array elements.
    pub max_cells: usize,
    /// Largest decoded size in bytes (of the returned array, and of any
    /// intermediate buffer a decoder needs, e.g. the RGB pixels of a colour
    /// image or the decompressed bytes of a `.nii.gz`).
    pub max_bytes: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_cells: 512 * 512 * 512,
            max_bytes: 2 << 30,
        }
    }
}

thread_local! {
    /// Set while [`declared_size`] runs a decoder on this thread.
    static PROBING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// What [`Limits::check`] was asked about while probing: (cells, bytes).
    static DECLARED: std::cell::Cell<Option<(usize, usize)>> = const { std::cell::Cell::new(None) };
}

/// Ends probing on this thread, however the decoder returns.
struct ProbeGuard;

impl Drop for ProbeGuard {
    fn drop(&mut self) {
        PROBING.with(|p| p.set(false));
    }
}

/// The size an encoded array declares, `(cells, bytes)` at its stored
/// element size, read from its header without decoding the payload: the
/// decoder runs until its [`Limits::check`] (which every decoder calls
/// before allocating the array) and stops there. A file that is malformed
/// or over `limits` before that point gives the error [`decode`] would.
/// Used to admit a decode by its memory before running it.
///
/// # Examples
///
/// ```
/// use geodex::io::{declared_size, encode_npy, ArrayData, Limits};
/// let a = ArrayData::F64(ndarray::ArrayD::zeros(ndarray::IxDyn(&[30, 40])));
/// let npy = encode_npy(&a)?;
/// assert_eq!(declared_size(&npy, None, &Limits::default())?, Some((1200, 9600)));
/// # Ok::<(), geodex::io::IoError>(())
/// ```
pub fn declared_size(
    bytes: &[u8],
    hint: Option<Format>,
    limits: &Limits,
) -> Result<Option<(usize, usize)>, IoError> {
    DECLARED.with(|d| d.set(None));
    PROBING.with(|p| p.set(true));
    let result = {
        let _guard = ProbeGuard;
        decode(bytes, hint, limits)
    };
    match (DECLARED.with(std::cell::Cell::take), result) {
        (Some(size), _) => Ok(Some(size)),
        (None, Err(e)) => Err(e),
        (None, Ok(_)) => Ok(None),
    }
}

impl Limits {
    /// Checks a declared shape against the limits: the number of cells and
    /// `cells × item_size` bytes (overflow counts as too large). `what`
    /// names the thing in the error (`"NPY array"`). Under
    /// [`declared_size`] the first check records the size and stops the
    /// decoder.
    pub fn check(&self, what: &str, shape: &[usize], item_size: usize) -> Result<(), IoError> {
        let too_large = |reason: String| IoError::TooLarge {
            what: what.to_string(),
            reason,
        };
        let cells = shape
            .iter()
            .try_fold(1usize, |acc, &n| acc.checked_mul(n))
            .ok_or_else(|| too_large(format!("shape {shape:?} overflows the address space")))?;
        if cells > self.max_cells {
            return Err(too_large(format!(
                "shape {shape:?} has {cells} cells, more than the limit of {}",
                self.max_cells
            )));
        }
        let bytes = cells
            .checked_mul(item_size)
            .ok_or_else(|| too_large(format!("shape {shape:?} × {item_size} bytes overflows")))?;
        if bytes > self.max_bytes {
            return Err(too_large(format!(
                "shape {shape:?} of {item_size}-byte elements needs {bytes} bytes, more than \
                 the limit of {}",
                self.max_bytes
            )));
        }
        if PROBING.with(std::cell::Cell::get) && DECLARED.with(std::cell::Cell::get).is_none() {
            DECLARED.with(|d| d.set(Some((cells, bytes))));
            return Err(too_large("probed: the decoder stops here".into()));
        }
        Ok(())
    }
}

/// A decoded array with what its file said about it.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    /// The values, in standard layout.
    pub array: ArrayData,
    /// Physical spacing per axis, if the format carries one (NIfTI).
    pub spacing: Option<Vec<f64>>,
    /// The format that was read.
    pub format: Format,
}

/// Why bytes could not be decoded or encoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IoError {
    /// The bytes are not in any supported format.
    #[error("unrecognised file format: {0}")]
    UnknownFormat(String),
    /// The file is corrupt or truncated.
    #[error("corrupt {format:?} file: {reason}")]
    Corrupt {
        /// The format it claimed to be.
        format: Format,
        /// What is wrong.
        reason: String,
    },
    /// The file is valid but holds something we do not support.
    #[error("unsupported {format:?} content: {reason}")]
    Unsupported {
        /// The format.
        format: Format,
        /// What is not supported.
        reason: String,
    },
    /// The declared size exceeds the limits.
    #[error("{what} exceeds the limit: {reason}")]
    TooLarge {
        /// What is too large.
        what: String,
        /// The numbers.
        reason: String,
    },
    /// The array cannot be written in the requested format.
    #[error("cannot encode: {0}")]
    Encode(String),
}

impl IoError {
    /// Shorthand for [`IoError::Corrupt`].
    pub(crate) fn corrupt(format: Format, reason: impl Into<String>) -> Self {
        IoError::Corrupt {
            format,
            reason: reason.into(),
        }
    }

    /// Shorthand for [`IoError::Unsupported`].
    pub(crate) fn unsupported(format: Format, reason: impl Into<String>) -> Self {
        IoError::Unsupported {
            format,
            reason: reason.into(),
        }
    }
}

/// Decodes a file. `hint` forces a format; otherwise it is detected from the
/// first bytes (see [`Format::sniff`]).
///
/// Returned arrays have 1 to 3 axes (NPY may be 1D; images are 2D; multi-page
/// TIFF and NIfTI are 3D, or 2D when they hold one page / slice). Callers that
/// need a 2D or 3D grid check the number of axes themselves.
///
/// # Errors
///
/// [`IoError::UnknownFormat`] when no hint is given and the magic bytes match
/// nothing; [`IoError::TooLarge`] when the declared shape exceeds `limits`
/// (checked before the payload is allocated); [`IoError::Corrupt`] for
/// malformed or truncated files; [`IoError::Unsupported`] for valid files
/// with content we do not handle (complex dtypes, 4D volumes, ...).
pub fn decode(bytes: &[u8], hint: Option<Format>, limits: &Limits) -> Result<Decoded, IoError> {
    let format = match hint {
        Some(format) => format,
        None => Format::sniff(bytes).ok_or_else(|| {
            let head: Vec<String> = bytes.iter().take(8).map(|b| format!("{b:02x}")).collect();
            IoError::UnknownFormat(format!(
                "the first bytes ({}) match none of NPY, PNG, JPEG, TIFF, NIfTI-1 or gzip",
                head.join(" ")
            ))
        })?,
    };
    let (array, spacing) = match format {
        Format::Npy => (npy::decode(bytes, limits)?, None),
        Format::Png | Format::Jpeg => (raster::decode(bytes, format, limits)?, None),
        Format::Tiff => (tiff::decode(bytes, limits)?, None),
        Format::Nifti => {
            let (array, spacing) = nifti::decode(bytes, limits)?;
            (array, Some(spacing))
        }
    };
    Ok(Decoded {
        array,
        spacing,
        format,
    })
}

/// The 2D plane an image encoder writes: a 2D array, or a 3D array whose
/// axis 0 has length 1 (how the core stores 2D grids). Returns
/// `(rows, cols, values as f64 in C order)`.
pub(crate) fn plane_f64(
    array: &ArrayData,
    what: &str,
) -> Result<(usize, usize, Vec<f64>), IoError> {
    let shape = array.shape();
    let (rows, cols) = match *shape {
        [rows, cols] | [1, rows, cols] => (rows, cols),
        _ => {
            return Err(IoError::Encode(format!(
                "{what} needs a 2D array (or 3D with one slice along axis 0), got shape {shape:?}"
            )))
        }
    };
    Ok((rows, cols, to_f64_vec(array)))
}

/// The values in C (logical) order as f64 (true = 1).
pub(crate) fn to_f64_vec(array: &ArrayData) -> Vec<f64> {
    match array {
        ArrayData::Bool(a) => a.iter().map(|&v| f64::from(u8::from(v))).collect(),
        ArrayData::U8(a) => a.iter().map(|&v| f64::from(v)).collect(),
        ArrayData::U16(a) => a.iter().map(|&v| f64::from(v)).collect(),
        ArrayData::I32(a) => a.iter().map(|&v| f64::from(v)).collect(),
        ArrayData::I64(a) => a.iter().map(|&v| v as f64).collect(),
        ArrayData::F32(a) => a.iter().map(|&v| f64::from(v)).collect(),
        ArrayData::F64(a) => a.iter().copied().collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn media_types_round_trip() {
        for f in Format::ALL {
            assert_eq!(Format::from_media_type(f.media_type()), Ok(Some(f)));
            assert_eq!(Format::from_extension(f.extension()), Some(f));
        }
        assert_eq!(
            Format::from_media_type("application/gzip"),
            Ok(Some(Format::Nifti))
        );
        assert_eq!(
            Format::from_media_type(" Application/Octet-Stream "),
            Ok(None)
        );
        assert!(matches!(
            Format::from_media_type("image/gif"),
            Err(IoError::UnknownFormat(_))
        ));
        assert_eq!(Format::from_extension("a.b.nii.gz"), Some(Format::Nifti));
        assert_eq!(Format::from_extension("a.npy.gz"), None);
        assert_eq!(Format::from_extension("TIFF"), Some(Format::Tiff));
    }

    #[test]
    fn limits_check_counts_cells_and_bytes() {
        let limits = Limits {
            max_cells: 100,
            max_bytes: 400,
        };
        assert!(limits.check("x", &[10, 10], 4).is_ok());
        assert!(matches!(
            limits.check("x", &[10, 11], 1),
            Err(IoError::TooLarge { .. })
        ));
        assert!(matches!(
            limits.check("x", &[10, 10], 8),
            Err(IoError::TooLarge { .. })
        ));
        assert!(matches!(
            limits.check("x", &[usize::MAX, 3], 1),
            Err(IoError::TooLarge { .. })
        ));
    }

    #[test]
    fn unknown_bytes_are_unknown_format() {
        let err = decode(b"hello world", None, &Limits::default());
        assert!(matches!(err, Err(IoError::UnknownFormat(m)) if m.contains("68 65 6c")));
    }
}
