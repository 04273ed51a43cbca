//! Tests of the output folder: staging, manifests, stale files, locks and atomic writes.
use super::*;

#[test]
fn a_rerun_removes_the_stale_files_its_manifest_lists_and_refuses_unknown_ones() {
    let dir = tempfile::tempdir().unwrap();
    let m = Manifest::new("run", "s", "h");
    let mut out = OutputDir::open(dir.path()).unwrap();
    out.stage("a.txt", b"1").unwrap();
    out.stage("sub/b.txt", b"2").unwrap();
    out.commit(m.clone(), false).unwrap();
    assert_eq!(std::fs::read(dir.path().join("sub/b.txt")).unwrap(), b"2");
    let mut out = OutputDir::open(dir.path()).unwrap();
    out.stage("a.txt", b"3").unwrap();
    let files = out.commit(m.clone(), false).unwrap();
    assert_eq!(files, vec!["a.txt".to_string()]);
    assert!(
        !dir.path().join("sub").exists(),
        "stale file and its folder removed"
    );
    assert_eq!(read_manifest(dir.path()).unwrap().unwrap().files, files);
    std::fs::write(dir.path().join("notes.txt"), "mine").unwrap();
    let e = OutputDir::open(dir.path()).err().unwrap();
    assert!(
        e.contains("notes.txt") && e.contains("does not list"),
        "{e}"
    );
    std::fs::remove_file(dir.path().join(MANIFEST)).unwrap();
    let e = OutputDir::open(dir.path()).err().unwrap();
    assert!(
        e.contains("a.txt") && e.contains("no hushfuse-manifest.json"),
        "{e}"
    );
}

#[test]
fn temporaries_of_dead_writers_are_removed_and_live_ones_kept() {
    let dir = tempfile::tempdir().unwrap();
    let dead = dir.path().join(".summary.json.tmp-999999999");
    let live = dir
        .path()
        .join(format!(".summary.json.tmp-{}", std::process::id()));
    std::fs::write(&dead, "half").unwrap();
    std::fs::write(&live, "writing").unwrap();
    remove_stale_temporaries(dir.path());
    assert!(!dead.exists() || !Path::new("/proc/self").exists());
    assert!(live.exists());
}

/// A producer writing `0..n` as text in many small pieces, as serde_json does.
fn numbers(n: usize) -> impl FnMut(&mut dyn Write) -> std::io::Result<()> {
    move |w| (0..n).try_for_each(|i| write!(w, "{i},"))
}

#[test]
fn a_streamed_file_is_written_whole_and_a_failed_one_leaves_the_old_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sub/a.csv");
    write_file_with(&path, numbers(100_000)).unwrap();
    let mut expected = Vec::new();
    numbers(100_000)(&mut expected).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), expected);
    let failing = |w: &mut dyn Write| {
        w.write_all(&[b'x'; 200_000])?;
        Err(std::io::Error::other("the producer failed"))
    };
    let e = write_file_with(&path, failing).unwrap_err();
    assert!(e.contains("the producer failed"), "{e}");
    assert_eq!(std::fs::read(&path).unwrap(), expected, "old file kept");
    let left: Vec<_> = std::fs::read_dir(dir.path().join("sub")).unwrap().collect();
    assert_eq!(left.len(), 1, "no temporary left");
}

#[test]
fn the_test_hook_lets_half_a_streamed_file_reach_the_disk_then_fails_as_a_full_disk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("half.csv");
    let mut whole = Vec::new();
    numbers(50_000)(&mut whole).unwrap();
    let e = write_half_then_fail(File::create(&path).unwrap(), &mut numbers(50_000)).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::StorageFull);
    assert!(e.to_string().contains("no space left on device"), "{e}");
    assert_eq!(std::fs::read(&path).unwrap(), whole[..whole.len() / 2]);
    // An empty file fails too: the hook always fails.
    let e = write_half_then_fail(
        File::create(&path).unwrap(),
        &mut |_: &mut dyn Write| Ok(()),
    )
    .unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::StorageFull);
}

#[test]
fn an_uncommitted_output_leaves_the_folder_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let mut out = OutputDir::open(dir.path()).unwrap();
    out.stage("a.txt", b"1").unwrap();
    drop(out);
    // Only the (released) lock file stays.
    assert_eq!(list_files(dir.path()).unwrap(), vec![LOCK.to_string()]);
}

#[test]
fn a_manifest_naming_files_outside_its_folder_is_refused_and_nothing_is_removed() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("o");
    std::fs::write(root.path().join("victim.txt"), "keep").unwrap();
    let victim = root.path().join("victim.txt").display().to_string();
    for bad in [
        "../victim.txt",
        victim.as_str(),
        "a/../../victim.txt",
        "./a",
        "",
        "a//b",
        ".hushfuse-staging/x",
        "hushfuse-manifest.json",
    ] {
        std::fs::create_dir_all(&dir).unwrap();
        let mut m = Manifest::new("run", "s", "h");
        m.files = vec![bad.to_string()];
        std::fs::write(dir.join(MANIFEST), serde_json::to_string(&m).unwrap()).unwrap();
        let e = OutputDir::open(&dir).err().expect(bad);
        assert!(
            e.contains("hushfuse-manifest.json") && e.contains("lists"),
            "{bad}: {e}"
        );
        assert_eq!(
            std::fs::read_to_string(root.path().join("victim.txt")).unwrap(),
            "keep"
        );
    }
}

#[test]
fn a_folder_reached_through_a_symbolic_link_is_neither_written_nor_cleaned() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("o");
    let outside = root.path().join("outside");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::write(outside.join("x.txt"), "keep").unwrap();
    std::os::unix::fs::symlink(&outside, dir.join("sub")).unwrap();
    let mut m = Manifest::new("run", "s", "h");
    m.files = vec!["sub/x.txt".into(), "sub".into()];
    std::fs::write(dir.join(MANIFEST), serde_json::to_string(&m).unwrap()).unwrap();
    let out = OutputDir::open(&dir).unwrap();
    let e = out
        .commit(Manifest::new("run", "s", "h"), false)
        .unwrap_err();
    assert!(e.contains("symbolic link"), "{e}");
    assert_eq!(
        std::fs::read_to_string(outside.join("x.txt")).unwrap(),
        "keep"
    );
}

#[test]
fn a_staging_folder_hushfuse_did_not_make_is_refused_and_kept() {
    let dir = tempfile::tempdir().unwrap();
    let staging = dir.path().join(STAGING);
    std::fs::create_dir_all(&staging).unwrap();
    std::fs::write(staging.join("user.txt"), "mine").unwrap();
    let e = OutputDir::open(dir.path()).err().unwrap();
    assert!(e.contains("user.txt") && e.contains("did not stage"), "{e}");
    assert_eq!(
        std::fs::read_to_string(staging.join("user.txt")).unwrap(),
        "mine"
    );
    // An empty one is removed, as is hushfuse's own from a run that died while staging.
    std::fs::remove_file(staging.join("user.txt")).unwrap();
    drop(OutputDir::open(dir.path()).unwrap());
    assert!(!staging.exists());
    let mut out = OutputDir::open(dir.path()).unwrap();
    out.stage("half.txt", b"1").unwrap();
    out.abandon(); // killed: no clean-up, no commit
    drop(OutputDir::open(dir.path()).unwrap());
    assert!(!staging.exists());
}

#[test]
fn a_commit_killed_between_the_moves_and_the_manifest_is_finished_by_the_next_open() {
    let dir = tempfile::tempdir().unwrap();
    // An earlier run wrote old.txt and a.txt.
    let mut out = OutputDir::open(dir.path()).unwrap();
    out.stage("old.txt", b"old").unwrap();
    out.stage("a.txt", b"old a").unwrap();
    out.commit(Manifest::new("run", "s", "h1"), false).unwrap();
    // The next one staged a.txt and b/c.txt and its manifest, moved a.txt, then died.
    let mut out = OutputDir::open(dir.path()).unwrap();
    out.stage("a.txt", b"new a").unwrap();
    out.stage("b/c.txt", b"new c").unwrap();
    let mut m = Manifest::new("run", "s", "h2");
    m.files = vec!["a.txt".into(), "b/c.txt".into()];
    let staging = dir.path().join(STAGING);
    write_file(
        &staging.join(MANIFEST),
        serde_json::to_string(&m).unwrap().as_bytes(),
    )
    .unwrap();
    std::fs::rename(staging.join("a.txt"), dir.path().join("a.txt")).unwrap();
    out.abandon();
    let out = OutputDir::open(dir.path()).unwrap();
    assert_eq!(std::fs::read(dir.path().join("a.txt")).unwrap(), b"new a");
    assert_eq!(std::fs::read(dir.path().join("b/c.txt")).unwrap(), b"new c");
    assert!(
        !dir.path().join("old.txt").exists(),
        "the earlier run's stale file"
    );
    assert_eq!(read_manifest(dir.path()).unwrap().unwrap(), m);
    assert!(!staging.exists());
    drop(out);
}

#[test]
fn one_output_per_folder_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let first = OutputDir::open(dir.path()).unwrap();
    let e = OutputDir::open(dir.path()).err().unwrap();
    assert!(
        e.contains("being written by another hushfuse run")
            && e.contains(&std::process::id().to_string()),
        "{e}"
    );
    assert!(OutputDir::open_existing(dir.path()).is_err());
    drop(first);
    drop(OutputDir::open(dir.path()).unwrap());
    // A released lock names no process: finished folders of one experiment are identical.
    assert_eq!(std::fs::read(dir.path().join(LOCK)).unwrap(), b"");
}

#[test]
fn a_folder_without_room_for_the_output_is_refused_naming_both_sizes() {
    let dir = tempfile::tempdir().unwrap();
    assert!(check_free_space(dir.path(), 1.0).is_ok());
    let e = check_free_space(dir.path(), 1e30).unwrap_err();
    assert!(
        e.contains(&dir.path().display().to_string()) && e.contains("MiB free"),
        "{e}"
    );
    assert!(check_free_space(dir.path(), f64::NAN).is_err());
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 128,
        // A fixed seed: the same cases on every run and machine (CI included).
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed0002),
        ..proptest::prelude::ProptestConfig::default()
    })]
    /// Whatever a manifest lists, a run into its folder touches nothing outside it: entries
    /// that are not normalized names inside the folder are refused before anything moves.
    #[test]
    fn no_manifest_makes_a_run_touch_files_outside_its_folder(
        entries in proptest::collection::vec(
            proptest::collection::vec(
                proptest::sample::select(vec![
                    "..", ".", "", "a", "b", "victim.txt", "o", ".hushfuse-staging",
                    "hushfuse-manifest.json", ".hushfuse-lock", "c:", "d\\e",
                    "../victim.txt", "../o/../victim.txt", "b/a",
                ]),
                1..4,
            ),
            0..4,
        ),
        absolute in proptest::bool::ANY,
    ) {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("o");
        std::fs::create_dir_all(dir.join("b")).unwrap();
        std::fs::write(root.path().join("victim.txt"), "keep").unwrap();
        std::fs::write(dir.join("b/a"), "old").unwrap();
        // The folder's one file is listed, so a folder is refused only for its entries.
        let mut files: Vec<String> = entries.iter().map(|parts| parts.join("/")).collect();
        files.push("b/a".to_string());
        if absolute {
            files.push(root.path().join("victim.txt").display().to_string());
        }
        let mut m = Manifest::new("run", "s", "h");
        m.files = files.clone();
        std::fs::write(dir.join(MANIFEST), serde_json::to_string(&m).unwrap()).unwrap();
        let valid = files.iter().all(|f| check_entry(f).is_ok());
        match OutputDir::open(&dir) {
            Ok(mut out) => {
                proptest::prop_assert!(valid, "{files:?} was accepted");
                out.stage("a", b"new").unwrap();
                // A listed name that is a folder, or an unlisted file, may refuse the
                // commit; neither may touch anything outside.
                let _ = out.commit(Manifest::new("run", "s", "h2"), false);
            }
            // A bad entry is refused by name; a valid manifest may still be refused for
            // another reason (a listed name that is a folder), never for its entries.
            Err(e) => proptest::prop_assert_eq!(!valid, e.contains(" lists "), "{}", e),
        }
        proptest::prop_assert_eq!(
            std::fs::read_to_string(root.path().join("victim.txt")).unwrap(),
            "keep"
        );
        let outside: Vec<_> = std::fs::read_dir(root.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        proptest::prop_assert_eq!(outside.len(), 2, "{:?}", outside);
    }
}
