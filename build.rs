//! Finds a BLAS/LAPACK library for the conic solver of the vector rate–distortion floor
//! (`src/stats/rate_distortion`): Clarabel's PSD cone calls BLAS/LAPACK (Fortran symbols such as
//! `dsyevr_`), which no crate of crates.io builds offline. When the system OpenBLAS is there
//! (Debian: `libopenblas-dev`; `.ci/run` installs it) the crate links it and sets the cfg
//! `hushfuse_openblas`; without it everything else builds and runs, and the vector floor says
//! what to install (the scalar closed forms need nothing). `HUSHFUSE_NO_OPENBLAS=1` builds as
//! if it were absent.
use std::path::Path;
use std::process::Command;

fn main() {
    println!("cargo:rustc-check-cfg=cfg(hushfuse_openblas)");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=HUSHFUSE_NO_OPENBLAS");
    if std::env::var_os("HUSHFUSE_NO_OPENBLAS").is_some() {
        return;
    }
    if let Some(dir) = openblas_dir() {
        println!("cargo:rustc-link-search=native={dir}");
        println!("cargo:rustc-link-lib=openblas");
        println!("cargo:rustc-cfg=hushfuse_openblas");
    }
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
