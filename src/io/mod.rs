//! Codecs between bytes and arrays: the layer between the numerical core and
//! the service. Decoders check declared sizes against [`Limits`] *before*
//! allocating, and never panic on malformed input.
//!
//! * [`array`]: [`ArrayData`], an n-dimensional array of one of the supported dtypes.

pub mod array;

pub use array::{ArrayData, DType};

/// A file format the codecs know.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// NumPy `.npy` (f32, f64, u8, u16, bool, i32, i64; 2D or 3D).
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

/// Size limits checked against a file's declared dimensions before any allocation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest number of array elements.
    pub max_cells: usize,
    /// Largest decoded size in bytes.
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

/// Decodes a file. `hint` forces a format; otherwise it is detected from the
/// first bytes (magic numbers).
pub fn decode(bytes: &[u8], hint: Option<Format>, limits: &Limits) -> Result<Decoded, IoError> {
    let _ = (bytes, hint, limits);
    Err(IoError::UnknownFormat("codecs are not written yet".into()))
}

/// Encodes an array as NPY (any dtype, C order, little endian).
pub fn encode_npy(array: &ArrayData) -> Result<Vec<u8>, IoError> {
    let _ = array;
    Err(IoError::Encode("codecs are not written yet".into()))
}
