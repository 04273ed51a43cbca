//! Live runs tried as a careless user, a broken network and a hostile peer would: options out of
//! range refused before anything is created, an interrupted journal never lost and resumed only
//! by its own run, `hushfuse live` taking its node processes with it, a node on a silent input
//! ending with the run, and a channel proxy that junk from thousands of ports cannot bring down.
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn hushfuse(args: &[&str], d: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(args)
        .current_dir(d)
        .output()
        .unwrap()
}

fn spawn(args: &[&str], d: &Path, stdin: Stdio) -> Child {
    Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(args)
        .current_dir(d)
        .stdin(stdin)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn refused(out: &Output, text: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains(text), "{text:?} not in: {stderr}");
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn lines(p: &Path) -> usize {
    std::fs::read_to_string(p).map_or(0, |t| t.lines().count())
}

fn wait_for(what: &str, mut ready: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ready() {
        assert!(start.elapsed() < Duration::from_secs(60), "{what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn alive(pid: u32) -> bool {
    // A zombie still has its /proc entry: read its state.
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .is_ok_and(|s| !s.split(") ").nth(1).unwrap_or("").starts_with('Z'))
}

/// Waits and options out of range are refused (exit 2) before the output folder exists; a wait
/// of 1e19 s used to panic on the clock.
#[test]
fn bad_options_are_refused_before_the_folder_is_made() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let listen = format!("127.0.0.1:{}", free_port());
    let center = |extra: &[&str]| {
        let mut args = vec!["center", "arena-1d", "--listen", &listen, "--out", "out"];
        args.extend_from_slice(extra);
        hushfuse(&args, d)
    };
    refused(
        &center(&["--timeout", "1e19"]),
        "--timeout: expected a positive number of seconds up to 86400",
    );
    refused(&center(&["--period", "1e19"]), "--period");
    refused(&center(&["--wait", "0"]), "--wait");
    refused(&center(&["--scheme", "No such scheme"]), "no such scheme");
    let live = hushfuse(&["live", "arena-1d", "--period", "1e19", "--out", "out"], d);
    refused(&live, "--period");
    assert!(
        !d.join("out").exists(),
        "the folder was made before the options were checked"
    );
    // A delay on the downlink is refused (it was accepted and ignored), in live runs too.
    std::fs::write(
        d.join("dl.toml"),
        hushfuse_arena_with(
            "[channel]\nkind = \"bernoulli\"\nloss = 0.1\ndownlink = { delay = 3 }\n",
        ),
    )
    .unwrap();
    refused(
        &hushfuse(&["run", "dl.toml", "--trials", "2"], d),
        "downlink.delay is not supported",
    );
    refused(
        &hushfuse(&["live", "dl.toml", "--out", "out"], d),
        "downlink.delay is not supported",
    );
}

fn as_str(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// arena-1d's text with `extra` appended.
fn hushfuse_arena_with(extra: &str) -> String {
    let text = hushfuse::scenario::builtin::get("arena-1d").unwrap();
    format!("{text}\n{extra}")
}

/// A center killed mid-run leaves a journal that names its run. Started again without
/// `--resume` it refuses (naming `--resume`) and leaves the journal as it was; with `--resume`
/// and another seed, trial, loss or scheme list it refuses naming what differs; a hand-edited
/// line is refused naming the file and line; and a second center resuming into the folder of a
/// running one is refused by the lock before it rewrites anything.
#[test]
fn an_interrupted_journal_is_kept_and_resumed_only_by_its_own_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let sod = ["--scheme", "Send-on-delta"];
    let center_args = |extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [
            "center", "arena-1d", "--listen", &listen, "--steps", "100000", "--out", "live",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        a.extend(sod.iter().map(|s| s.to_string()));
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let mut center = spawn(&as_str(&center_args(&[])), d, Stdio::null());
    let nodes: Vec<Child> = (0..4)
        .map(|i| {
            let addr = format!("127.0.0.1:{port}");
            spawn(
                &[
                    "node",
                    "arena-1d",
                    "--sensor",
                    &i.to_string(),
                    "--connect",
                    &addr,
                    "--steps",
                    "100000",
                ],
                d,
                Stdio::null(),
            )
        })
        .collect();
    let journal = d.join("live/center-journal.txt");
    wait_for("the center fuses steps", || lines(&journal) > 30);
    center.kill().unwrap();
    center.wait().unwrap();
    for mut n in nodes {
        let _ = n.kill();
        let _ = n.wait();
    }
    let kept = std::fs::read(&journal).unwrap();
    let head = String::from_utf8_lossy(&kept)
        .lines()
        .next()
        .unwrap()
        .to_string();
    assert!(
        head.starts_with("# hushfuse live journal {") && head.contains("\"seed\""),
        "{head}"
    );

    let run = |extra: &[&str]| hushfuse(&as_str(&center_args(extra)), d);
    refused(&run(&[]), "interrupted live run");
    refused(&run(&["--resume", "--seed", "99"]), "seed (--seed) differs");
    refused(
        &run(&["--resume", "--trial", "3"]),
        "trial (--trial) differs (the journal's: 0; this center's: 3)",
    );
    refused(
        &run(&["--resume", "--loss", "0.2"]),
        "link differs (the journal's: the scenario's; this center's: --loss 0.2)",
    );
    refused(
        &hushfuse(
            &[
                "center",
                "arena-1d",
                "--listen",
                &listen,
                "--steps",
                "100000",
                "--out",
                "live",
                "--resume",
                "--scheme",
                "Innovation trigger (Wu 2013)",
            ],
            d,
        ),
        "schemes (--scheme) differs (the journal's: Send-on-delta;",
    );
    assert_eq!(
        std::fs::read(&journal).unwrap(),
        kept,
        "a refused center touched the journal"
    );

    // A hand-edited journal: a sensor entry claiming 10^11 bits.
    let mut edited = String::from_utf8(kept.clone()).unwrap();
    let at = edited.find("sent:32:").expect("a reading in the journal");
    edited.replace_range(at..at + 8, "sent:100000000000:");
    let bad_line = edited[..at].lines().count();
    std::fs::write(&journal, &edited).unwrap();
    refused(
        &run(&["--resume"]),
        &format!("center-journal.txt line {bad_line}: sensor"),
    );
    std::fs::write(&journal, &kept).unwrap();

    // One center resumes (and waits for its nodes); a second one is refused by the lock and
    // leaves the files as the first wrote them.
    let mut first = spawn(
        &as_str(&center_args(&["--resume", "--wait", "60"])),
        d,
        Stdio::null(),
    );
    let log = d.join("live/live.log");
    wait_for("the first center resumes", || {
        std::fs::read_to_string(&log).is_ok_and(|t| t.contains("resumed after"))
    });
    let (j, e) = (
        std::fs::read(&journal).unwrap(),
        std::fs::read(d.join("live/estimates.csv")).unwrap(),
    );
    let other = format!("127.0.0.1:{}", free_port());
    let second = hushfuse(
        &[
            "center",
            "arena-1d",
            "--listen",
            &other,
            "--steps",
            "100000",
            "--out",
            "live",
            "--resume",
            "--scheme",
            "Send-on-delta",
        ],
        d,
    );
    refused(&second, "live");
    assert_eq!(std::fs::read(&journal).unwrap(), j);
    assert_eq!(std::fs::read(d.join("live/estimates.csv")).unwrap(), e);
    first.kill().unwrap();
    first.wait().unwrap();
}

/// SIGTERM (as Ctrl-C) to `hushfuse live` ends its node processes with it.
#[test]
fn a_stopped_live_run_takes_its_nodes_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut live = spawn(
        &[
            "live",
            "arena-1d",
            "--steps",
            "100000",
            "--period",
            "0.02",
            "--scheme",
            "Send-on-delta",
            "--out",
            "live",
        ],
        d,
        Stdio::null(),
    );
    let est = d.join("live/estimates.csv");
    wait_for("the live run fuses steps", || lines(&est) > 5);
    let children: Vec<u32> =
        std::fs::read_to_string(format!("/proc/{}/task/{}/children", live.id(), live.id()))
            .unwrap()
            .split_whitespace()
            .map(|p| p.parse().unwrap())
            .collect();
    assert_eq!(children.len(), 4, "four node processes");
    assert!(children.iter().all(|&p| alive(p)));
    // SAFETY: a signal to our own child.
    unsafe {
        libc::kill(live.id() as i32, libc::SIGTERM);
    }
    let status = live.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    wait_for("the nodes end", || children.iter().all(|&p| !alive(p)));
}

/// A node reading standard input that stays open but silent ends when the run ends (the center
/// closes its steps without it and says the run is over).
#[test]
fn a_node_on_a_silent_input_ends_with_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let listen = addr.clone();
    let mut center = spawn(
        &[
            "center",
            "arena-1d",
            "--listen",
            &listen,
            "--steps",
            "5",
            "--timeout",
            "0.2",
            "--scheme",
            "Send-on-delta",
            "--out",
            "live",
        ],
        d,
        Stdio::null(),
    );
    let mut nodes: Vec<Child> = (0..3)
        .map(|i| {
            spawn(
                &[
                    "node",
                    "arena-1d",
                    "--sensor",
                    &i.to_string(),
                    "--connect",
                    &addr,
                    "--steps",
                    "5",
                ],
                d,
                Stdio::null(),
            )
        })
        .collect();
    // Standard input a pipe nobody writes to, kept open by this test.
    let mut silent = spawn(
        &[
            "node",
            "arena-1d",
            "--sensor",
            "3",
            "--connect",
            &addr,
            "--steps",
            "5",
            "--stdin",
        ],
        d,
        Stdio::piped(),
    );
    let _keep_open = silent.stdin.take();
    assert!(center.wait().unwrap().success());
    for n in &mut nodes {
        assert!(n.wait().unwrap().success());
    }
    let start = Instant::now();
    let status = loop {
        if let Some(s) = silent.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > Duration::from_secs(20) {
            let _ = silent.kill();
            panic!("the node on a silent input did not end with the run");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "{status}");
}

/// Well-formed greetings from 3000 source ports: the proxy relays for a bounded number of peers
/// and keeps running (it aborted at about 2600 before).
#[test]
fn the_channel_proxy_survives_thousands_of_peers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let center = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to_center = center.local_addr().unwrap().to_string();
    let mut proxy = spawn(
        &[
            "channel-proxy",
            "arena-1d",
            "--loss",
            "0.2",
            "--listen",
            "127.0.0.1:0",
            "--center",
            &to_center,
        ],
        d,
        Stdio::null(),
    );
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(proxy.stdout.as_mut().unwrap()),
        &mut line,
    )
    .unwrap();
    let at = line.trim().to_string();
    let hello =
        hushfuse::live::wire::Datagram::new(hushfuse::live::wire::Kind::Hello, 0, 0, 0).encode();
    for _ in 0..3000 {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        let _ = s.send_to(&hello, &at);
        let _ = s.send_to(b"junk", &at);
    }
    std::thread::sleep(Duration::from_millis(500));
    assert!(proxy.try_wait().unwrap().is_none(), "the proxy ended");
    // It still relays: a greeting from a known peer reaches the center.
    center
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut buf = [0u8; 256];
    // The proxy opens one socket towards the center per peer it relays for.
    let mut peers = std::collections::HashSet::new();
    while let Ok((_, from)) = center.recv_from(&mut buf) {
        peers.insert(from);
    }
    assert!(
        !peers.is_empty() && peers.len() <= 4 * 4 + 16,
        "{} peers relayed",
        peers.len()
    );
    proxy.kill().unwrap();
    proxy.wait().unwrap();
}
