//! What every bench shares: running one generic bench function on each compiled-in backend, and
//! forcing lazy backends to finish.

use phi_core::{Backend, Tensor};

/// `$bench::<B>(c)` for every backend compiled in.
macro_rules! on_every_backend {
    ($c:expr, $bench:ident) => {{
        #[cfg(feature = "ndarray")]
        $bench::<phi_core::backend::ndarray::NdArray>($c);
        #[cfg(feature = "burn")]
        $bench::<phi_core::backend::burn::Burn>($c);
        #[cfg(feature = "tch")]
        $bench::<phi_core::backend::tch::Tch>($c);
    }};
}
pub(crate) use on_every_backend;

/// Makes sure lazy or asynchronous backends finish the work: reads the first row back.
pub fn force<B: Backend>(t: &Tensor<B>) {
    std::hint::black_box(t.narrow(0, 0..1).expect("a tensor with rows").to_vec());
}
