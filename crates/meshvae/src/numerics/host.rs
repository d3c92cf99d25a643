//! Float data in host memory, in the model's precision: what the CPU engine reads and returns
//! in place of any tensor library's types (each executor converts its own tensors).

/// The float type of a model's variables and data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Precision {
    F32,
    F64,
}

/// Borrowed values of either precision.
#[derive(Debug, Clone, Copy)]
pub(crate) enum HostSlice<'a> {
    F32(&'a [f32]),
    F64(&'a [f64]),
}

/// Owned values of either precision.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum HostVec {
    F32(Vec<f32>),
    F64(Vec<f64>),
}

/// A borrowed row-major array: values and dimensions.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HostArray<'a> {
    pub data: HostSlice<'a>,
    pub dims: &'a [usize],
}

/// An owned row-major array.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct HostTensor {
    pub data: HostVec,
    pub dims: Vec<usize>,
}
