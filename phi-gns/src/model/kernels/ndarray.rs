//! The GNS kernels of [`NdArray`].

use phi_core::backend::ndarray::NdArray;

use super::GnsKernels;

impl GnsKernels for NdArray {}
