//! Bakes the libtorch lib folder into the rpath of this package's binaries, tests and benches when the `tch`
//! feature is on, so they run without `LD_LIBRARY_PATH`.
//!
//! With the `cuda` feature it also links `libtorch_cuda.so` unconditionally. rustc links with
//! `--as-needed`, and nothing in phi or tch references a symbol of `libtorch_cuda.so` directly (its
//! kernels register themselves with libtorch's dispatcher when the library is loaded), so without
//! this the library is dropped from the binary's NEEDED entries and libtorch sees no CUDA device.
//! `libtorch_cuda.so` in turn needs cuBLAS, cuDNN, NCCL, ..., which only GPU machines have:
//! `--allow-shlib-undefined` lets the link succeed on machines without them, and the binary then
//! runs only where they are present. The default build does not load `libtorch_cuda.so` and so
//! runs on any machine with the CPU-side libraries.
fn main() {
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    if let Ok(lib) = std::env::var("DEP_TCH_LIBTORCH_LIB") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{lib}");
        if std::env::var_os("CARGO_FEATURE_CUDA").is_some() {
            println!("cargo:rustc-link-arg=-L{lib}");
            println!("cargo:rustc-link-arg=-Wl,--no-as-needed");
            println!("cargo:rustc-link-arg=-ltorch_cuda");
            println!("cargo:rustc-link-arg=-Wl,--as-needed");
            println!("cargo:rustc-link-arg=-Wl,--allow-shlib-undefined");
        }
    }
}
