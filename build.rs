//! Finds a BLAS/LAPACK library for the conic solver of the vector rate–distortion floor
//! (`src/stats/rate_distortion`): Clarabel's PSD cone calls BLAS/LAPACK (Fortran symbols such as
//! `dsyevr_`), which no crate of crates.io builds offline.
//!
//! **The reference BLAS and LAPACK first** (Debian: `libblas-dev liblapack-dev`; `.ci/run`
//! installs them), linked from their own folders with a run path to them, so the loader never
//! swaps in another implementation behind Debian's `libblas.so.3` alternative. They are plain
//! compiled Fortran with no choice of kernel at run time, so the floor comes out the same to the
//! last bit on every x86-64 machine. OpenBLAS, the fallback, picks its kernels by the CPU it
//! finds (Haswell, SkylakeX, Zen, …), and the floor's last digits (about 1e-8 relative, the
//! solver's tolerance) then depend on the machine: a summary recorded on an AVX2 machine did not
//! match one computed on an AVX-512 one.
//!
//! Either sets the cfg `hushfuse_blas` (and `hushfuse_openblas` for OpenBLAS, whose thread
//! count is set to one); without either, everything else builds and runs, and the vector floor
//! says what to install (the scalar closed forms need nothing). `HUSHFUSE_NO_BLAS=1` builds as
//! if both were absent, `HUSHFUSE_OPENBLAS=1` takes OpenBLAS even where the reference is there.
use std::path::Path;
use std::process::Command;

fn main() {
    println!("cargo:rustc-check-cfg=cfg(hushfuse_blas)");
    println!("cargo:rustc-check-cfg=cfg(hushfuse_openblas)");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=HUSHFUSE_NO_BLAS");
    println!("cargo:rerun-if-env-changed=HUSHFUSE_OPENBLAS");
    if std::env::var_os("HUSHFUSE_NO_BLAS").is_some() {
        return;
    }
    let prefer_openblas = std::env::var_os("HUSHFUSE_OPENBLAS").is_some();
    if let Some(dir) = reference_dir().filter(|_| !prefer_openblas) {
        let (blas, lapack) = (format!("{dir}/blas"), format!("{dir}/lapack"));
        println!("cargo:rustc-link-search=native={lapack}");
        println!("cargo:rustc-link-search=native={blas}");
        println!("cargo:rustc-link-lib=dylib=lapack");
        println!("cargo:rustc-link-lib=dylib=blas");
        println!("cargo:rustc-link-arg=-Wl,-rpath,{lapack}:{blas}");
        // For dependents' build scripts (python/build.rs), as DEP_HUSHFUSE_BLAS_RPATH.
        println!("cargo:rpath={lapack}:{blas}");
        println!("cargo:rustc-cfg=hushfuse_blas");
    } else if let Some(dir) = openblas_dir() {
        println!("cargo:rustc-link-search=native={dir}");
        println!("cargo:rustc-link-lib=openblas");
        println!("cargo:rustc-cfg=hushfuse_blas");
        println!("cargo:rustc-cfg=hushfuse_openblas");
    }
}

/// The library directory holding Debian's reference `blas/libblas.so` and
/// `lapack/liblapack.so`.
fn reference_dir() -> Option<String> {
    [
        "/usr/lib/x86_64-linux-gnu",
        "/usr/lib/aarch64-linux-gnu",
        "/usr/lib64",
        "/usr/lib",
    ]
    .into_iter()
    .find(|d| {
        Path::new(d).join("blas/libblas.so").exists()
            && Path::new(d).join("lapack/liblapack.so").exists()
    })
    .map(str::to_string)
}

/// The directory of `libopenblas.so`: pkg-config's answer, else the usual library directories.
fn openblas_dir() -> Option<String> {
    let pkg = Command::new("pkg-config")
        .args(["--variable=libdir", "openblas"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .filter(|d| Path::new(d).join("libopenblas.so").exists());
    pkg.or_else(|| {
        [
            "/usr/lib/x86_64-linux-gnu",
            "/usr/lib/aarch64-linux-gnu",
            "/usr/lib64",
            "/usr/lib",
            "/usr/local/lib",
            "/opt/homebrew/opt/openblas/lib",
        ]
        .into_iter()
        .find(|d| Path::new(d).join("libopenblas.so").exists())
        .map(str::to_string)
    })
}
