//! The source layout rules, checked on every test run: no file of `src/` (nor of the Python
//! crate's `python/src/`) imports another in a
//! circle (`scripts/check-import-cycles.py`), and no file is over 900 lines nor any function
//! over 150 (`scripts/check-sizes.py`). Each checker first proves on planted cases that it can
//! fail (`--self-test`).
use std::process::Command;

fn python(args: &[&str]) -> std::process::Output {
    Command::new("python3")
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("python3 runs the layout checkers")
}

fn passes(args: &[&str]) {
    let o = python(args);
    assert!(
        o.status.success(),
        "{args:?} failed:\n{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn no_import_circle_in_src() {
    passes(&["scripts/check-import-cycles.py", "--self-test"]);
    passes(&["scripts/check-import-cycles.py", "src"]);
    // The Python crate's sources too (a circle external.rs <-> runs.rs went unseen).
    passes(&["scripts/check-import-cycles.py", "python/src"]);
}

#[test]
fn no_file_over_900_lines_and_no_function_over_150_in_src() {
    passes(&["scripts/check-sizes.py", "--self-test"]);
    passes(&["scripts/check-sizes.py", "src"]);
    passes(&["scripts/check-sizes.py", "python/src"]);
}
