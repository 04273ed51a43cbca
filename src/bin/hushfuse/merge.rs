//! `hushfuse merge`: the outputs of a whole run from the shard files of `run --shard I/N`.
use super::*;

/// `hushfuse merge`: the outputs of a whole run from the shard files of `run --shard I/N`.
pub(crate) fn merge(inputs: &[PathBuf], out: &Path, report: bool) -> Result<(), Failure> {
    let hooks = engine_run::Hooks {
        note: &|m| eprintln!("{m}"),
        show: &|t| print_out(t),
        ..Default::default()
    };
    let done = engine_run::merge(inputs, out, report, &hooks).map_err(failure)?;
    wrote(&done, Vec::new());
    check_failed(&done.failed)?;
    check_finite(done.non_finite)
}
