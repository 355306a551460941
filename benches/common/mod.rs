//! What every bench shares: forcing lazy backends to finish. Benches run a generic bench function
//! on each compiled-in backend with [`phi_core::for_each_backend!`].

use phi_core::{Backend, Tensor};

/// Makes sure lazy or asynchronous backends finish the work: reads the first row back.
pub fn force<B: Backend>(t: &Tensor<B>) {
    std::hint::black_box(t.narrow(0, 0..1).expect("a tensor with rows").to_vec());
}
