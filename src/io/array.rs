//! Typed n-dimensional arrays as they travel between codecs, storage and the core.

use std::borrow::Cow;

use ndarray::ArrayD;

use crate::numerics::metric::CostValues;

/// Element type of an [`ArrayData`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum DType {
    /// Boolean (NPY `|b1`).
    Bool,
    /// Unsigned 8-bit.
    U8,
    /// Unsigned 16-bit.
    U16,
    /// Signed 32-bit (labels).
    I32,
    /// Signed 64-bit (frozen order).
    I64,
    /// 32-bit float.
    F32,
    /// 64-bit float.
    F64,
}

impl DType {
    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            DType::Bool | DType::U8 => 1,
            DType::U16 => 2,
            DType::I32 | DType::F32 => 4,
            DType::I64 | DType::F64 => 8,
        }
    }
}

/// An array in standard (C) layout, of one of the supported element types.
#[derive(Debug, Clone, PartialEq)]
pub enum ArrayData {
    /// Booleans (masks).
    Bool(ArrayD<bool>),
    /// 8-bit images.
    U8(ArrayD<u8>),
    /// 16-bit images.
    U16(ArrayD<u16>),
    /// Labels.
    I32(ArrayD<i32>),
    /// Ranks.
    I64(ArrayD<i64>),
    /// Single precision fields.
    F32(ArrayD<f32>),
    /// Double precision fields (distance maps).
    F64(ArrayD<f64>),
}

macro_rules! each {
    ($self:expr, $a:ident => $e:expr) => {
        match $self {
            ArrayData::Bool($a) => $e,
            ArrayData::U8($a) => $e,
            ArrayData::U16($a) => $e,
            ArrayData::I32($a) => $e,
            ArrayData::I64($a) => $e,
            ArrayData::F32($a) => $e,
            ArrayData::F64($a) => $e,
        }
    };
}

impl ArrayData {
    /// The shape, axis 0 first.
    pub fn shape(&self) -> &[usize] {
        each!(self, a => a.shape())
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        each!(self, a => a.len())
    }

    /// True if the array has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The element type.
    pub fn dtype(&self) -> DType {
        match self {
            ArrayData::Bool(_) => DType::Bool,
            ArrayData::U8(_) => DType::U8,
            ArrayData::U16(_) => DType::U16,
            ArrayData::I32(_) => DType::I32,
            ArrayData::I64(_) => DType::I64,
            ArrayData::F32(_) => DType::F32,
            ArrayData::F64(_) => DType::F64,
        }
    }

    /// Size of the elements in bytes.
    pub fn nbytes(&self) -> usize {
        self.len() * self.dtype().size()
    }

    /// Element `i` (C order) as f64 (true = 1).
    pub fn get_f64(&self, i: usize) -> Option<f64> {
        Some(match self {
            ArrayData::Bool(a) => f64::from(u8::from(*a.as_slice()?.get(i)?)),
            ArrayData::U8(a) => f64::from(*a.as_slice()?.get(i)?),
            ArrayData::U16(a) => f64::from(*a.as_slice()?.get(i)?),
            ArrayData::I32(a) => f64::from(*a.as_slice()?.get(i)?),
            ArrayData::I64(a) => *a.as_slice()?.get(i)? as f64,
            ArrayData::F32(a) => f64::from(*a.as_slice()?.get(i)?),
            ArrayData::F64(a) => *a.as_slice()?.get(i)?,
        })
    }

    /// The values as a cost field for the core: f32 and f64 are borrowed,
    /// integer types are converted to f64. Booleans are refused (`None`).
    pub fn as_cost_values(&self) -> Option<CostValues<'_>> {
        Some(match self {
            ArrayData::F32(a) => CostValues::F32(Cow::Borrowed(a.as_slice()?)),
            ArrayData::F64(a) => CostValues::F64(Cow::Borrowed(a.as_slice()?)),
            ArrayData::U8(a) => {
                CostValues::F64(Cow::Owned(a.iter().map(|&v| f64::from(v)).collect()))
            }
            ArrayData::U16(a) => {
                CostValues::F64(Cow::Owned(a.iter().map(|&v| f64::from(v)).collect()))
            }
            ArrayData::I32(a) => {
                CostValues::F64(Cow::Owned(a.iter().map(|&v| f64::from(v)).collect()))
            }
            ArrayData::I64(a) => CostValues::F64(Cow::Owned(a.iter().map(|&v| v as f64).collect())),
            ArrayData::Bool(_) => return None,
        })
    }

    /// The array as a mask: true where the value is non-zero.
    pub fn to_mask(&self) -> Vec<bool> {
        match self {
            ArrayData::Bool(a) => a.iter().copied().collect(),
            _ => (0..self.len())
                .map(|i| self.get_f64(i).is_some_and(|v| v != 0.0))
                .collect(),
        }
    }
}
