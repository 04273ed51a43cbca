//! Issue 9's "tried as a new user would" cases: each bad file exits with code 2, names the file
//! and the right field, and never panics, aborts or hangs.
#[path = "common/cli.rs"]
mod common;
use common::hushfuse;

const BASE: &str = r#"
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

[[sensors]]
observe = [0]
R_diag = [1.0]

[[sensors]]
H = [[1.0, 0.0]]
R = [[2.0]]

[[schemes]]
kind = "centralized-kf"
"#;

const SCHEME: &str = "kind = \"centralized-kf\"";

/// Runs `text` and returns (exit code, stderr, the temporary folder).
fn run(text: &str) -> (Option<i32>, String, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scenario.toml");
    std::fs::write(&path, text).unwrap();
    let out = hushfuse(&["run", path.to_str().unwrap()], dir.path());
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
        dir,
    )
}

/// `BASE` with `from` replaced by `to` must exit 2 and name `field` (and what was expected).
fn refused(from: &str, to: &str, field: &str, expected: &str) {
    assert!(BASE.contains(from), "pattern {from:?} not in BASE");
    let (code, stderr, _dir) = run(&BASE.replacen(from, to, 1));
    assert_eq!(code, Some(2), "{to:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{to:?} panicked: {stderr}");
    assert!(
        stderr.contains("scenario.toml"),
        "{to:?}: no file in {stderr}"
    );
    assert!(
        stderr.contains(&format!("field `{field}")),
        "{to:?}: field {field} not named in {stderr}"
    );
    assert!(
        stderr.contains(expected),
        "{to:?}: {expected:?} not in {stderr}"
    );
}

fn with_scheme(extra: &str) -> String {
    format!("{SCHEME}\n{extra}")
}

#[test]
fn unknown_scheme_keys_are_refused() {
    refused(
        SCHEME,
        &with_scheme("rate = 0.5"),
        "schemes[0].rate",
        "unknown field",
    );
    refused(
        SCHEME,
        &with_scheme("Label = \"x\""),
        "schemes[0].Label",
        "unknown field",
    );
}

#[test]
fn fixed_length_lists_are_not_cut() {
    let range =
        "kind = \"range\"\nposition = [1.0, 0.0, 3.0]\nposition_indices = [0, 1]\nR_diag = [1.0]";
    refused(
        "observe = [0]\nR_diag = [1.0]",
        range,
        "sensors[0].position",
        "exactly 2",
    );
    let idx = "kind = \"range\"\nposition = [1.0, 0.0]\nposition_indices = [0]\nR_diag = [1.0]";
    refused(
        "observe = [0]\nR_diag = [1.0]",
        idx,
        "sensors[0].position_indices",
        "exactly 2",
    );
    let field = |area: &str, grid: &str| {
        format!("{SCHEME}\n\n[[sensor_fields]]\nkind = \"range\"\nlayout = \"grid\"\narea = {area}\n{grid}\nposition_indices = [0, 1]\nr = 1.0\n")
    };
    refused(
        SCHEME,
        &field("[0.0, 1.0, 0.0]", "grid = [2, 2]"),
        "sensor_fields[0].area",
        "exactly 4",
    );
    refused(
        SCHEME,
        &field("[0.0, 1.0, 0.0, 1.0]", "grid = [2, 2, 2]"),
        "sensor_fields[0].grid",
        "exactly 2",
    );
}

#[test]
fn count_on_a_grid_and_zero_prop3_samples_are_refused() {
    let grid = format!("{SCHEME}\n\n[[sensor_fields]]\nkind = \"range\"\nlayout = \"grid\"\narea = [0.0, 1.0, 0.0, 1.0]\ngrid = [2, 2]\ncount = 5\nposition_indices = [0, 1]\nr = 1.0\n");
    refused(SCHEME, &grid, "sensor_fields[0].count", "only for layout");
    let pf = "kind = \"censored-pf\"\nl = 1.0\nfeedback = \"none\"\nprop3_samples = 0";
    refused(SCHEME, pf, "schemes[0].prop3_samples", "at least 1");
}

#[test]
fn an_asymmetric_covariance_is_refused() {
    refused(
        "kind = \"constant-velocity-1d\"\ndt = 1.0\nsigma2 = 0.1",
        "kind = \"matrix\"\nF = [[1.0, 1.0], [0.0, 1.0]]\nQ = [[1.0, 0.5], [0.0, 1.0]]",
        "model.Q",
        "not symmetric",
    );
    refused(
        "cov_diag = [1.0, 1.0]",
        "cov = [[1.0, 0.5], [0.0, 1.0]]",
        "prior.cov",
        "not symmetric",
    );
}

#[test]
fn sweeps_cannot_mix_kinds_override_or_repeat() {
    let base = "kind = \"centralized-kf-random\"\nrate = 0.5";
    refused(
        SCHEME,
        &format!("{base}\nsweep.kind = [\"centralized-kf\", \"dkf\"]"),
        "schemes[0].sweep.kind",
        "cannot be swept",
    );
    refused(
        SCHEME,
        &format!("{base}\nsweep.rate = [0.5, 1.0]"),
        "schemes[0].sweep.rate",
        "base value and a sweep",
    );
    refused(
        SCHEME,
        "kind = \"centralized-kf-random\"\nsweep.rate = [0.5, 0.5]",
        "schemes[0].sweep.rate",
        "listed twice",
    );
}

#[test]
fn paper_typos_are_errors() {
    let paper = |body: &str| format!("{SCHEME}\n\n[paper]\ncitation = \"c\"\n{body}");
    let published = |scheme: &str, metric: &str| {
        paper(&format!("[[paper.published]]\nscheme = \"{scheme}\"\nmetric = \"{metric}\"\nvalue = 1.0\nsource = \"T\"\n"))
    };
    refused(
        SCHEME,
        &published("Nope", "mse"),
        "paper.published[0].scheme",
        "no scheme is labelled",
    );
    refused(
        SCHEME,
        &published("Centralized KF (all data)", "msee"),
        "paper.published[0].metric",
        "unknown metric",
    );
    refused(
        SCHEME,
        &published("Centralized KF (all data)", "rmse:nope"),
        "paper.published[0].metric",
        "unknown group",
    );
    let kf = "a = \"Centralized KF (all data)\"\nb = \"Centralized KF (all data)\"";
    refused(
        SCHEME,
        &paper(&format!("[[paper.claims]]\nkind = \"close\"\ntext = \"t\"\n{kf}\nmetric = \"mse\"\nwithin = -0.1\n")),
        "paper.claims[0].within",
        ">= 0",
    );
    refused(
        SCHEME,
        &paper(&format!("[[paper.claims]]\nkind = \"below\"\ntext = \"t\"\n{kf}\nmetric = \"mse\"\nrate_range = [0.9, 0.1]\n")),
        "paper.claims[0].rate_range",
        "lo < hi",
    );
    refused(
        SCHEME,
        &paper("[[paper.claims]]\nkind = \"consistent\"\ntext = \"t\"\nschemes = [\"Nope\"]\n"),
        "paper.claims[0].schemes[0]",
        "no scheme is labelled",
    );
}

/// A description that contains a line starting `report =` is still a scenario: the file kind
/// is told by structure.
#[test]
fn a_report_line_in_a_description_does_not_change_the_parser() {
    let text = BASE.replacen(
        "name = \"tiny\"",
        "name = \"tiny\"\ndescription = \"\"\"\nreport = zhang-tables\n\"\"\"",
        1,
    );
    let (code, stderr, dir) = run(&text);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(dir.path().join("hushfuse-out/tiny/summary.json").exists());
}

#[test]
fn output_names_cannot_leave_the_output_folder() {
    for name in ["../../x", "/tmp/x", "", "a/b", ".."] {
        refused(
            "name = \"tiny\"",
            &format!("name = \"{name}\""),
            "name",
            "--out",
        );
    }
}

#[test]
fn errors_name_the_right_place() {
    refused("dt = 1.0", "dtt = 1.0", "model.dtt", "unknown field");
    refused("mean = [0.0, 1.0]\n", "", "prior.mean", "missing field");
    refused(
        "cov_diag = [1.0, 1.0]",
        "cov = [[1.0, 2.0], [2.0, 1.0]]",
        "prior.cov",
        "positive definite",
    );
    refused("dt = 1.0", "dt = 0.0", "model.dt", "positive");
}

/// Requests that cannot fit are refused before the run, quickly, with a clear message.
#[test]
fn requests_too_large_for_the_machine_are_refused_before_the_run() {
    let start = std::time::Instant::now();
    refused(
        "steps = 20",
        "steps = 9223372036854775807",
        "steps",
        "at most",
    );
    refused(
        SCHEME,
        "kind = \"censored-pf\"\nl = 1.0\nparticles = 1000000000",
        "schemes[0].particles",
        "at most",
    );
    let grid = format!("{SCHEME}\n\n[[sensor_fields]]\nkind = \"range\"\nlayout = \"grid\"\narea = [0.0, 1.0, 0.0, 1.0]\ngrid = [100000, 100000]\nposition_indices = [0, 1]\nr = 1.0\n");
    refused(SCHEME, &grid, "sensor_fields", "at most 100000 sensors");
    let (code, stderr, _d) = run(&BASE.replacen("trials = 8", "trials = 1000000000000", 1));
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("--allow-large") && stderr.contains("memory"),
        "{stderr}"
    );
    let (code, stderr, _d) = run(
        &BASE.replacen("steps = 20", "steps = 10000000", 1).replacen(
            "trials = 8",
            "trials = 100000",
            1,
        ),
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        (stderr.contains("memory") || stderr.contains("hours")) && stderr.contains("--allow-large"),
        "{stderr}"
    );
    // Small in memory, but days of particle filtering.
    let pf = BASE
        .replacen("trials = 8", "trials = 100000", 1)
        .replacen("steps = 20", "steps = 100", 1)
        .replacen(
            SCHEME,
            "kind = \"censored-pf\"\nl = 1.0\nparticles = 1000000",
            1,
        );
    let (code, stderr, _d) = run(&pf);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("hours") && stderr.contains("--allow-large"),
        "{stderr}"
    );
    assert!(
        start.elapsed().as_secs() < 30,
        "refusals took {:?}",
        start.elapsed()
    );
}

#[test]
fn numbers_too_large_for_double_precision_are_refused() {
    refused(
        "sigma2 = 0.1",
        "sigma2 = 1e300",
        "model.sigma2",
        "too large",
    );
}

/// `hushfuse list-schemes` prints every kind with its parameters.
#[test]
fn list_schemes_prints_the_registry() {
    let dir = tempfile::tempdir().unwrap();
    let out = hushfuse(&["list-schemes"], dir.path());
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    for kind in [
        "centralized-kf",
        "dkf-alg2-event",
        "quantized-innovation",
        "censored-pf",
    ] {
        assert!(text.contains(kind), "{kind} missing from {text}");
    }
    assert!(
        text.contains("prop3_samples") && text.contains("default 200"),
        "{text}"
    );
}
