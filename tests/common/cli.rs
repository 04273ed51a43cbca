//! What the command-line tests share: running the binary, and a small valid scenario.
#![allow(dead_code)] // each test file uses what it needs

use std::path::Path;
use std::process::{Command, Output};

/// A small valid scenario: 1-D constant velocity, two linear sensors, the all-data KF and
/// Algorithm 1 swept over two rates (8 trials x 20 steps, seed 1).
pub const TINY: &str = r#"
name = "tiny"
trials = 8
steps = 20
seed = 1

[model]
kind = "constant-velocity-1d"
dt = 1.0
sigma2 = 0.1

[prior]
mean = [0.0, 1.0]
cov_diag = [1.0, 1.0]

[groups]
position = [0]

[[sensors]]
observe = [0]
R_diag = [1.0]

[[sensors]]
H = [[1.0, 0.0]]
R = [[2.0]]

[[schemes]]
kind = "centralized-kf"

[[schemes]]
kind = "dkf-alg1-random"
sweep.rate = [0.5, 1.0]
"#;

/// The hushfuse binary with `args`, run in `cwd`.
pub fn hushfuse(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("binary runs")
}
