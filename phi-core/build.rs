//! Bakes the libtorch lib folder into the rpath of this package's binaries, tests and benches when the `tch`
//! feature is on, so they run without `LD_LIBRARY_PATH`; and, with `tch`, compiles the C++ shim
//! that gives the sparse linear solve implicit gradients in libtorch's autograd
//! (`src/solve/tch_shim.cpp`, see `backend/tch.rs`).
fn main() {
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    println!("cargo:rerun-if-changed=src/solve/tch_shim.cpp");
    if let Ok(lib) = std::env::var("DEP_TCH_LIBTORCH_LIB") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{lib}");
        if std::env::var_os("CARGO_FEATURE_TCH").is_some() {
            let root = std::path::Path::new(&lib)
                .parent()
                .expect("the libtorch lib folder has a parent");
            let include = root.join("include");
            cc::Build::new()
                .cpp(true)
                .pic(true)
                .warnings(false)
                .include(&include)
                .include(include.join("torch/csrc/api/include"))
                .flag("-std=c++17")
                .flag("-D_GLIBCXX_USE_CXX11_ABI=1")
                .flag("-DGLOG_USE_GLOG_EXPORT")
                .file("src/solve/tch_shim.cpp")
                .compile("phi_tch_shim");
        }
    }
}
