//! The run path of the reference BLAS and LAPACK that hushfuse links (its build.rs says which,
//! as `DEP_HUSHFUSE_BLAS_RPATH`): a run path reaches only the binaries of the crate that sets
//! it, and without one this extension would load whatever Debian's `libblas.so.3` alternative
//! points to (OpenBLAS, whose CPU-chosen kernels move the rate–distortion floor's last digits
//! away from the command line's).
fn main() {
    println!("cargo:rerun-if-env-changed=DEP_HUSHFUSE_BLAS_RPATH");
    if let Ok(path) = std::env::var("DEP_HUSHFUSE_BLAS_RPATH") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{path}");
    }
}
