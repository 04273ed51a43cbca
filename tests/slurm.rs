//! scripts/slurm on a real (single-node) Slurm cluster: a 4-task job array of shards of a
//! built-in scenario and the dependent merge job give, byte for byte, the outputs of the
//! unsharded run. `.ci/run` starts the cluster (scripts/slurm/ci-setup.sh); where Slurm is not
//! installed or not up, the test says so and skips.
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

fn cluster_up() -> Result<(), String> {
    let sinfo = Command::new("sinfo")
        .args(["-h", "-o", "%t"])
        .output()
        .map_err(|_| "Slurm is not installed (no sinfo on PATH)".to_string())?;
    let states = String::from_utf8_lossy(&sinfo.stdout).into_owned();
    if !sinfo.status.success()
        || !states
            .lines()
            .any(|l| ["idle", "mix", "alloc"].contains(&l.trim()))
    {
        return Err(format!(
            "no Slurm node is up (sinfo: {:?} {}); scripts/slurm/ci-setup.sh starts one",
            states.trim(),
            String::from_utf8_lossy(&sinfo.stderr).trim()
        ));
    }
    Ok(())
}

fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    // The folder's lock file is not an output (it names whichever process held it).
    std::fs::read_dir(dir)
        .unwrap()
        .filter(|e| {
            !e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with(".hushfuse-lock")
        })
        .map(|e| {
            let p = e.unwrap().path();
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect()
}

fn logs(out: &Path) -> String {
    let mut s = String::new();
    if let Ok(entries) = std::fs::read_dir(out.join("logs")) {
        for e in entries.flatten() {
            s.push_str(&format!(
                "--- {}\n{}\n",
                e.path().display(),
                std::fs::read_to_string(e.path()).unwrap_or_default()
            ));
        }
    }
    s
}

#[test]
fn a_4_task_slurm_array_and_its_merge_job_give_the_bytes_of_the_unsharded_run() {
    if let Err(why) = cluster_up() {
        eprintln!("SKIPPED tests/slurm.rs: {why}");
        return;
    }
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cluster");
    let bin = env!("CARGO_BIN_EXE_hushfuse");
    let submit = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm/submit.sh");
    let sub = Command::new(&submit)
        .args(["default", "4"])
        .arg(&out)
        .env("HUSHFUSE", bin)
        .current_dir(dir.path())
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&sub.stdout).into_owned();
    assert!(
        sub.status.success(),
        "submit.sh failed: {said}{}",
        String::from_utf8_lossy(&sub.stderr)
    );
    let job = |prefix: &str| -> String {
        said.lines()
            .find_map(|l| l.strip_prefix(prefix))
            .and_then(|l| l.split(':').next())
            .unwrap_or_else(|| panic!("no {prefix:?} in {said}"))
            .trim()
            .to_string()
    };
    let (array, merge) = (job("array job "), job("merge job "));
    // Wait for the merge job to leave the queue (10 minutes at most).
    let deadline = Instant::now() + Duration::from_secs(600);
    loop {
        let q = Command::new("squeue")
            .args(["-h", "-j", &format!("{array},{merge}"), "-o", "%i %T"])
            .output()
            .unwrap();
        let queued = String::from_utf8_lossy(&q.stdout).into_owned();
        if queued.trim().is_empty() {
            break;
        }
        if Instant::now() > deadline {
            let _ = Command::new("scancel").args([&array, &merge]).status();
            panic!(
                "the jobs did not finish in 10 minutes:\n{queued}\n{}",
                logs(&out)
            );
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let on_cluster = started.elapsed().as_secs_f64();
    let merged = out.join("merged");
    assert!(
        merged.join("hushfuse-manifest.json").exists(),
        "the merge job wrote no output:\n{}",
        logs(&out)
    );
    for i in 1..=4 {
        assert!(out
            .join(format!("shards/shard-{i:04}-of-0004.hfshard"))
            .exists());
    }
    let whole = dir.path().join("whole");
    let run = Command::new(bin)
        .args(["run", "default", "--out"])
        .arg(&whole)
        .output()
        .unwrap();
    assert!(run.status.success());
    let (a, b) = (files(&whole), files(&merged));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        assert!(
            bytes == &b[name],
            "{name} differs between the cluster's merge and the unsharded run"
        );
    }
    eprintln!(
        "slurm: 4-task array + merge job of `default` took {on_cluster:.1} s on the cluster, {:.1} s in all",
        started.elapsed().as_secs_f64()
    );
}
