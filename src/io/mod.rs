//! Codecs between bytes and arrays: the layer between the numerical core and
//! the service. Decoders check declared sizes against [`Limits`] *before*
//! allocating, and never panic on malformed input.
//!
//! * [`array`]: [`ArrayData`], an n-dimensional array of one of the supported dtypes.

pub mod array;

pub use array::{ArrayData, DType};
