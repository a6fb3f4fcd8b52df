//! The one writer of the command line's array outputs: the format follows
//! the extension of the file name.
//!
//! | extension | what is written |
//! |---|---|
//! | `.npy` | the array as is ([`io::encode_npy`]) |
//! | `.tif`, `.tiff` | 32-bit float grey TIFF, multi-page in 3D ([`io::encode_tiff_f32`]) |
//! | `.png` | the colour-mapped picture of the service's `?format=png`: colour bar, iso-value lines on float maps, the label palette on integer labels, a `u8` `(rows, cols, 3)` array as RGB ([`io::render_png`]) |
//! | `.png16` | 16-bit grey PNG over the finite min..max ([`io::encode_png16`]) |
//!
//! Mesh outputs choose their own format by extension
//! ([`crate::io::mesh::write::encode_by_extension`]); JSON outputs are JSON.

use std::path::Path;

use crate::io::{self, ArrayData, IoError, RenderOptions};

/// The extensions an array output accepts, for messages.
const KNOWN: &str = ".npy, .tiff, .png or .png16";

/// The file format of an array output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ArrayFormat {
    /// NumPy `.npy`.
    Npy,
    /// 32-bit float TIFF.
    Tiff,
    /// Colour-mapped 8-bit PNG, as `?format=png`.
    Png,
    /// 16-bit grey PNG (extension `.png16`).
    Png16,
}

/// Why an array output could not be written; names the flag.
#[derive(Debug, thiserror::Error)]
pub(crate) enum OutputError {
    /// The extension names no array format.
    #[error("{flag}: unknown extension '{extension}'; use {KNOWN}")]
    UnknownExtension {
        /// The output flag (`--out`).
        flag: String,
        /// The extension given, with its dot (or empty).
        extension: String,
    },
    /// The array does not fit the format (e.g. a 3D array as `.png16`).
    #[error("{flag}: cannot write '{path}' as {format}: {reason}")]
    Encode {
        /// The output flag.
        flag: String,
        /// The file.
        path: String,
        /// The format's extension.
        format: &'static str,
        /// Why.
        reason: String,
    },
    /// The file could not be written.
    #[error("{flag}: cannot write '{path}': {reason}")]
    Write {
        /// The output flag.
        flag: String,
        /// The file.
        path: String,
        /// The system's reason.
        reason: String,
    },
}

impl OutputError {
    /// The flag at fault.
    pub(crate) fn flag(&self) -> &str {
        match self {
            OutputError::UnknownExtension { flag, .. }
            | OutputError::Encode { flag, .. }
            | OutputError::Write { flag, .. } => flag,
        }
    }

    /// The message without the flag.
    pub(crate) fn reason(&self) -> String {
        match self {
            OutputError::UnknownExtension { extension, .. } => {
                format!("unknown extension '{extension}'; use {KNOWN}")
            }
            OutputError::Encode {
                path,
                format,
                reason,
                ..
            } => format!("cannot write '{path}' as {format}: {reason}"),
            OutputError::Write { path, reason, .. } => {
                format!("cannot write '{path}': {reason}")
            }
        }
    }
}

impl ArrayFormat {
    /// The format of `path` by its extension (case ignored).
    ///
    /// # Errors
    ///
    /// [`OutputError::UnknownExtension`] naming `flag` for any other
    /// extension, or none.
    pub(crate) fn of(flag: &str, path: &Path) -> Result<Self, OutputError> {
        let extension = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        Ok(match extension.as_str() {
            "npy" => ArrayFormat::Npy,
            "tif" | "tiff" => ArrayFormat::Tiff,
            "png" => ArrayFormat::Png,
            "png16" => ArrayFormat::Png16,
            _ => {
                return Err(OutputError::UnknownExtension {
                    flag: flag.into(),
                    extension: path
                        .extension()
                        .map(|e| format!(".{}", e.to_string_lossy()))
                        .unwrap_or_default(),
                })
            }
        })
    }

    /// The extension, for messages.
    fn name(self) -> &'static str {
        match self {
            ArrayFormat::Npy => ".npy",
            ArrayFormat::Tiff => ".tiff",
            ArrayFormat::Png => ".png",
            ArrayFormat::Png16 => ".png16",
        }
    }

    /// `array` encoded in this format.
    ///
    /// # Errors
    ///
    /// The codec's, e.g. a 16-bit PNG of a 3D array.
    pub(crate) fn encode(self, array: &ArrayData) -> Result<Vec<u8>, IoError> {
        match self {
            ArrayFormat::Npy => io::encode_npy(array),
            ArrayFormat::Tiff => io::encode_tiff_f32(array),
            ArrayFormat::Png => io::render_png(array, &picture_options(array)),
            ArrayFormat::Png16 => io::encode_png16(array, None),
        }
    }
}

/// The options of the service's `?format=png` without query parameters: a
/// colour bar, and ten iso-value lines on float maps; the automatic style
/// (labels get the label palette, a `u8` `(rows, cols, 3)` array is a picture).
pub(crate) fn picture_options(array: &ArrayData) -> RenderOptions {
    RenderOptions {
        colorbar: true,
        iso_lines: io::default_iso_lines(array),
        ..RenderOptions::default()
    }
}

/// Checks the extension of an output before the work starts, so that a typo
/// costs nothing.
///
/// # Errors
///
/// As [`ArrayFormat::of`].
pub(crate) fn check(flag: &str, path: Option<&Path>) -> Result<(), OutputError> {
    path.map_or(Ok(()), |p| ArrayFormat::of(flag, p).map(|_| ()))
}

/// Writes `array` to `path` in the format of its extension; errors name `flag`.
///
/// # Errors
///
/// [`OutputError`]: an unknown extension, an array the format cannot hold,
/// or a file that cannot be written.
pub(crate) fn write_array(flag: &str, path: &Path, array: &ArrayData) -> Result<(), OutputError> {
    let format = ArrayFormat::of(flag, path)?;
    let bytes = format.encode(array).map_err(|e| OutputError::Encode {
        flag: flag.into(),
        path: path.display().to_string(),
        format: format.name(),
        reason: e.to_string(),
    })?;
    std::fs::write(path, bytes).map_err(|e| OutputError::Write {
        flag: flag.into(),
        path: path.display().to_string(),
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::ArrayD;

    #[test]
    fn extensions_choose_the_format_and_unknown_ones_name_the_flag() {
        let of = |p: &str| ArrayFormat::of("--out", Path::new(p));
        assert_eq!(of("u.npy").unwrap(), ArrayFormat::Npy);
        assert_eq!(of("U.TIF").unwrap(), ArrayFormat::Tiff);
        assert_eq!(of("dir.x/u.tiff").unwrap(), ArrayFormat::Tiff);
        assert_eq!(of("u.png").unwrap(), ArrayFormat::Png);
        assert_eq!(of("u.png16").unwrap(), ArrayFormat::Png16);
        let e = of("u.xyz").unwrap_err();
        assert_eq!(
            e.to_string(),
            "--out: unknown extension '.xyz'; use .npy, .tiff, .png or .png16"
        );
        assert_eq!(e.flag(), "--out");
        assert!(
            e.reason().starts_with("unknown extension"),
            "{}",
            e.reason()
        );
        assert!(of("u")
            .unwrap_err()
            .to_string()
            .contains("unknown extension ''"));
    }

    #[test]
    fn every_format_encodes_a_float_map_and_png16_refuses_a_volume() {
        let u = ArrayData::F64(ArrayD::from_shape_fn(vec![6, 7], |i| (i[0] + i[1]) as f64));
        for (format, magic) in [
            (ArrayFormat::Npy, &b"\x93NUMPY"[..]),
            (ArrayFormat::Tiff, &b"II*\0"[..]),
            (ArrayFormat::Png, &b"\x89PNG"[..]),
            (ArrayFormat::Png16, &b"\x89PNG"[..]),
        ] {
            let bytes = format.encode(&u).unwrap();
            assert!(bytes.starts_with(magic), "{format:?}");
        }
        let v = ArrayData::F64(ArrayD::zeros(vec![2, 3, 4]));
        assert!(ArrayFormat::Png16.encode(&v).is_err());
    }
}
