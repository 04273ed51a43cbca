//! `report.html` references nothing outside itself, and (when Chromium is installed) a headless
//! browser renders it.
use hushfuse::output::html::external_references;
use std::process::Command;

fn hushfuse(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(args)
        .output()
        .expect("binary runs")
}

/// Runs hushfuse and requires success, showing its stderr otherwise.
fn run_ok(args: &[&str]) {
    let out = hushfuse(args);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Independent of `external_references`: attribute values of src/href and CSS imports.
fn naive_check(html: &str) {
    let l = html.to_ascii_lowercase();
    for bad in [
        "src=\"http",
        "src='http",
        "href=\"http",
        "href='http",
        "src=\"file",
        "href=\"file",
        "<script src",
        "@import",
        "<link",
        "url(http",
        "<img",
    ] {
        assert!(!l.contains(bad), "report.html contains {bad}");
    }
    for attr in ["src=", "href="] {
        for (i, _) in l.match_indices(attr) {
            let rest = l[i + attr.len()..].trim_start_matches(['"', '\'']);
            assert!(
                rest.starts_with('#'),
                "external {attr}: {}",
                &l[i..(i + 60).min(l.len())]
            );
        }
    }
}

#[test]
fn the_checker_finds_external_references() {
    assert!(
        external_references("<p>ok</p><svg xmlns=\"http://www.w3.org/2000/svg\"></svg>").is_empty()
    );
    for bad in [
        "<script src=\"x.js\"></script>",
        "<img src=\"http://a/b.png\">",
        "<a href=\"http://example.com\">x</a>",
        "<style>@import url(x.css);</style>",
        "<link rel=stylesheet href=a.css>",
        "<div style=\"background:url(a.png)\">",
    ] {
        assert!(!external_references(bad).is_empty(), "missed {bad}");
    }
}

#[test]
fn report_html_is_self_contained() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    run_ok(&[
        "run",
        "arena-rss",
        "--trials",
        "4",
        "--report",
        "--out",
        run.to_str().unwrap(),
    ]);
    let arena = dir.path().join("arena");
    run_ok(&[
        "run",
        "arena-tobit",
        "--trials",
        "4",
        "--budgets",
        "20,40",
        "--budget-axis",
        "payload",
        "--report",
        "--out",
        arena.to_str().unwrap(),
    ]);
    // `hushfuse report <out-dir>` rewrites the first one from its files.
    let first = std::fs::read_to_string(run.join("report.html")).unwrap();
    std::fs::remove_file(run.join("report.html")).unwrap();
    run_ok(&["report", run.to_str().unwrap()]);
    let again = std::fs::read_to_string(run.join("report.html")).unwrap();
    assert_eq!(first, again, "report <out-dir> differs from run --report");
    for page in [run.join("report.html"), arena.join("report.html")] {
        let html = std::fs::read_to_string(&page).unwrap();
        assert!(html.starts_with("<!DOCTYPE html>"));
        assert!(
            html.matches("<svg").count() >= 3,
            "{}: figures missing",
            page.display()
        );
        assert!(html.contains("Who sent when"));
        assert!(html.contains("The scenario as run"));
        assert!(html.contains(env!("CARGO_PKG_VERSION")));
        assert_eq!(
            external_references(&html),
            Vec::<String>::new(),
            "{}",
            page.display()
        );
        naive_check(&html);
    }
    let arena_html = std::fs::read_to_string(arena.join("report.html")).unwrap();
    assert!(arena_html.contains("Best scheme per budget") && arena_html.contains("Pareto front"));
}

/// Renders the arena report in headless Chromium when it is installed (skipped otherwise:
/// CI installs no browser unless told to).
#[test]
fn headless_chromium_renders_the_report() {
    let browser = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| {
            Command::new(b)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        });
    let Some(browser) = browser else {
        eprintln!("skipped: no chromium on PATH");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    run_ok(&[
        "run",
        "arena-1d",
        "--trials",
        "4",
        "--report",
        "--out",
        run.to_str().unwrap(),
    ]);
    let png = dir.path().join("r.png");
    let profile = dir.path().join("profile");
    let status = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", png.display()))
        .arg("--window-size=1200,2000")
        .arg(format!("file://{}", run.join("report.html").display()))
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let bytes = std::fs::read(&png).unwrap();
    assert!(
        bytes.starts_with(b"\x89PNG") && bytes.len() > 20_000,
        "{} bytes",
        bytes.len()
    );
}
