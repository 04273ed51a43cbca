//! Live runs (`hushfuse live`, `center`, `node`, `channel-proxy`): real 802.15.4 frames over
//! UDP on loopback give the estimates of the simulation, bit for bit; through the proxy at
//! loss 0.2, those of the simulation of the same link; a killed center resumes to the same
//! estimates; a killed node ends as the documented run with its datagrams of the steps it
//! missed lost; junk datagrams are counted and dropped, never a wrong estimate.
#[path = "common/cli.rs"]
mod common;
use common::hushfuse;
use hushfuse::live::{self, wire, Center, Node};
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "exit {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Trial 0 of arena-1d as CSV (`data/`), with a few readings taken out (holes: the sensor is
/// "missing" at those steps).
fn arena_data(d: &Path, steps: usize) {
    ok(&hushfuse(
        &[
            "run",
            "arena-1d",
            "--trials",
            "1",
            "--out",
            "sim",
            "--write-trial",
            "0",
            "data",
        ],
        d,
    ));
    let text = read(&d.join("data/measurements.csv"));
    let mut kept = String::new();
    for (n, line) in text.lines().enumerate() {
        let step: usize = line.split(',').next().unwrap().parse().unwrap_or(0);
        // Every 7th reading out (the header is line 0), and only `steps` steps.
        if (n == 0 || n % 7 != 3) && step <= steps {
            kept.push_str(line);
            kept.push('\n');
        }
    }
    std::fs::write(d.join("data/holes.csv"), kept).unwrap();
}

/// `hushfuse live arena-1d` on the readings with holes, into `live/`, with `extra` arguments.
fn live_run(d: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "live",
        "arena-1d",
        "--measurements",
        "data/holes.csv",
        "--out",
        "live",
    ];
    args.extend_from_slice(extra);
    ok(&hushfuse(&args, d));
    read(&d.join("live/estimates.csv"))
}

fn replay(d: &Path, out: &str, extra: &[&str]) -> String {
    let mut args = vec![
        "replay",
        "arena-1d",
        "--measurements",
        "data/holes.csv",
        "--out",
        out,
    ];
    args.extend_from_slice(extra);
    ok(&hushfuse(&args, d));
    read(&d.join(out).join("estimates.csv"))
}

/// On loopback with an ideal link, every scheme of arena-1d: `hushfuse live` writes the
/// `estimates.csv` of `hushfuse replay` of the same readings, byte for byte (the estimates,
/// what each sensor did, the bits it sent).
#[test]
fn live_equals_replay_for_every_arena_scheme() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    arena_data(d, 100);
    let expected = replay(d, "rep", &[]);
    let got = live_run(d, &[]);
    assert!(expected.contains(",missing,0"), "the data has holes");
    assert_eq!(got.lines().count(), 1 + 17 * 100, "17 schemes x 100 steps");
    assert_eq!(got, expected);
    // With the truth, the table live prints scores every scheme as replay's does.
    let args = ["--truth", "data/truth.csv"];
    let rep = hushfuse(
        &[
            "replay",
            "arena-1d",
            "--measurements",
            "data/holes.csv",
            "--out",
            "rep2",
            args[0],
            args[1],
        ],
        d,
    );
    let live = hushfuse(
        &[
            "live",
            "arena-1d",
            "--measurements",
            "data/holes.csv",
            "--out",
            "live2",
            args[0],
            args[1],
        ],
        d,
    );
    ok(&live);
    let (rep, live) = (
        String::from_utf8_lossy(&rep.stdout),
        String::from_utf8_lossy(&live.stdout),
    );
    let row = |text: &str, scheme: &str| -> Vec<String> {
        let line = text
            .lines()
            .find(|l| l.starts_with(scheme))
            .unwrap_or_else(|| panic!("{scheme} in {text}"));
        line[scheme.len()..]
            .split_whitespace()
            .map(str::to_string)
            .collect()
    };
    for scheme in ["Centralized KF (all data)", "Censored PF", "Send-on-delta"] {
        let (r, l) = (row(&rep, scheme), row(&live, scheme));
        // replay: [params...] RMSE position, RMSE velocity, ...; live: bits, RMSE position, velocity.
        let at = r.iter().position(|x| x.contains('.')).unwrap();
        let at = if r[at].contains('=') { at + 1 } else { at };
        assert_eq!(
            &l[1..3],
            &r[at..at + 2],
            "{scheme}: live {l:?}, replay {r:?}"
        );
    }
}

/// The fields of a line of `estimates.csv` (labels and parameters are quoted and may hold
/// commas).
fn fields(line: &str) -> Vec<String> {
    let (mut out, mut cur, mut quoted) = (Vec::new(), String::new(), false);
    for c in line.chars() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => out.push(std::mem::take(&mut cur)),
            c => cur.push(c),
        }
    }
    out.push(cur);
    out
}

/// The CSV's rows with the link and bits columns of each sensor cut off: the estimates.
fn estimates_only(csv: &str) -> Vec<Vec<String>> {
    csv.lines().map(|l| fields(l)[..8].to_vec()).collect()
}

/// Through the channel proxy at loss 0.2: the estimates of `hushfuse replay --loss 0.2` (the
/// simulated link with the same fates), and a sensor the simulation says was lost is a
/// silence to the live center.
#[test]
fn proxy_at_loss_equals_the_simulated_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    arena_data(d, 60);
    let expected = replay(d, "rep", &["--loss", "0.2"]);
    let got = live_run(d, &["--loss", "0.2"]);
    assert!(expected.contains(",lost,"), "the link loses packets");
    assert_eq!(estimates_only(&got), estimates_only(&expected));
    let mut lost = 0;
    for (g, e) in got.lines().zip(expected.lines()).skip(1) {
        let (g, e) = (fields(g), fields(e));
        for c in (8..g.len()).step_by(2) {
            if e[c] == "lost" {
                lost += 1;
                assert_eq!((g[c].as_str(), g[c + 1].as_str()), ("silent", "0"));
            } else {
                assert_eq!((&g[c], &g[c + 1]), (&e[c], &e[c + 1]));
            }
        }
    }
    assert!(lost > 100, "{lost} packets lost");
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn spawn(args: &[&str], d: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .args(args)
        .current_dir(d)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn node(i: usize, port: u16, d: &Path) -> Child {
    let addr = format!("127.0.0.1:{port}");
    spawn(
        &[
            "node",
            "arena-1d",
            "--sensor",
            &i.to_string(),
            "--connect",
            &addr,
            "--measurements",
            "data/holes.csv",
        ],
        d,
    )
}

/// `hushfuse center arena-1d` on `port`, `steps` steps, with `extra` arguments.
fn center(port: u16, steps: &str, extra: &[&str], d: &Path) -> Child {
    let listen = format!("127.0.0.1:{port}");
    let mut args = vec!["center", "arena-1d", "--listen", &listen, "--steps", steps];
    args.extend_from_slice(extra);
    spawn(&args, d)
}

fn wait_ok(mut c: Child, what: &str) {
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        if let Some(s) = c.try_wait().unwrap() {
            let mut err = String::new();
            let _ = std::io::Read::read_to_string(c.stderr.as_mut().unwrap(), &mut err);
            assert!(s.success(), "{what} failed: {s}\n{err}");
            return;
        }
        assert!(Instant::now() < deadline, "{what} did not end");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn lines(p: &Path) -> usize {
    std::fs::read_to_string(p).map_or(0, |t| t.lines().count())
}

/// A center killed (SIGKILL) in the middle of the run and started again with `--resume` on
/// its folder: the nodes find it again, and the run ends with exactly the estimates of an
/// uninterrupted one; no row is lost.
#[test]
fn killed_center_resumes_to_the_same_estimates() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    arena_data(d, 100);
    let expected = replay(d, "rep", &[]);
    let port = free_port();
    let mut center = center(port, "100", &["--out", "live"], d);
    let nodes: Vec<Child> = (0..4).map(|i| node(i, port, d)).collect();
    // Kill it once it has fused some steps, well before the end (17 x 100).
    let csv = d.join("live/estimates.csv");
    let start = Instant::now();
    while lines(&csv) < 250 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the center did not start"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    center.kill().unwrap();
    center.wait().unwrap();
    let at_kill = lines(&csv);
    assert!(at_kill < 1701, "killed before the end ({at_kill} lines)");
    let center = self::center(port, "100", &["--out", "live", "--resume"], d);
    wait_ok(center, "the resumed center");
    for (i, n) in nodes.into_iter().enumerate() {
        wait_ok(n, &format!("node {i}"));
    }
    assert_eq!(read(&csv), expected);
    assert!(read(&d.join("live/live.log")).contains("resumed after"));
}

/// A node killed in the middle of the run and started again: the center closes the step it
/// missed after its timeout and the next ones without waiting for it (they are "no_report",
/// silences, and logged), the restarted node catches up and reports again; every step has its
/// row, and the estimates are those of the same run in one process with that node's datagrams
/// of exactly those steps lost.
#[test]
fn killed_node_ends_as_a_run_with_its_missed_steps_lost() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    arena_data(d, 100);
    let port = free_port();
    let extra = [
        "--timeout",
        "0.2",
        "--scheme",
        "Send-on-delta",
        "--scheme",
        "Censored PF",
    ];
    let center = center(port, "100", &[&extra[..], &["--out", "live"]].concat(), d);
    let mut nodes: Vec<Option<Child>> = (0..4).map(|i| Some(node(i, port, d))).collect();
    let csv = d.join("live/estimates.csv");
    let start = Instant::now();
    while lines(&csv) < 30 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the center did not start"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut n2 = nodes[2].take().unwrap();
    n2.kill().unwrap();
    n2.wait().unwrap();
    // The center waits once (--timeout) and then runs on without it until it is back.
    while lines(&csv) < 40 {
        std::thread::sleep(Duration::from_millis(1));
    }
    nodes[2] = Some(node(2, port, d));
    wait_ok(center, "the center");
    for (i, n) in nodes.into_iter().enumerate() {
        wait_ok(n.unwrap(), &format!("node {i}"));
    }
    let got = read(&csv);
    assert_eq!(got.lines().count(), 1 + 2 * 100, "every step has its row");
    // The steps sensor 2 missed, from the center's own rows.
    let missed: Vec<(u16, u32)> = got
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f = fields(l);
            (f[12] == "no_report").then(|| (f[2].parse().unwrap(), f[3].parse().unwrap()))
        })
        .collect();
    assert!(!missed.is_empty(), "the node was down for some steps");
    assert!(
        missed.len() < 150,
        "and came back ({} steps missed)",
        missed.len()
    );
    assert!(read(&d.join("live/live.log")).contains("sensor 2 rejoined"));
    // The same run in one process, sensor 2's datagrams of those steps lost.
    let (text, source) = hushfuse::scenario::builtin::resolve("arena-1d", false).unwrap();
    let (exp, _) =
        hushfuse::engine::replay::load_experiment(&text, &source, 100, None, &Default::default())
            .unwrap();
    let meas = hushfuse::engine::replay::parse_measurements(&read(&d.join("data/holes.csv")), "m")
        .unwrap();
    let rec = hushfuse::engine::replay::recorded(&exp, &meas, None).unwrap();
    let variants: Vec<usize> = (0..exp.variants.len())
        .filter(|&v| {
            let l = &exp.curves[exp.variants[v].curve].label;
            l == "Send-on-delta" || l == "Censored PF"
        })
        .collect();
    let fp = live::fingerprint(&exp, &text, 0);
    let mut center = Center::new(&exp, 0, fp, variants, None).unwrap();
    let mut nodes: Vec<Node> = (0..4)
        .map(|i| {
            let mine = (0..100)
                .map(|k| rec.available[k][i].then(|| rec.measurements[k][i].clone()))
                .collect();
            Node::new(&exp, i, 0, Box::new(live::Recorded(mine)), None).unwrap()
        })
        .collect();
    let records = live::run_local(&mut center, &mut nodes, |dg| {
        dg.sensor == 2
            && matches!(dg.kind, wire::Kind::Frame | wire::Kind::Done)
            && missed.contains(&(dg.variant, dg.step))
    })
    .unwrap();
    let mut reference = hushfuse::engine::replay::estimates_header(&exp);
    for r in &records {
        reference.push_str(&hushfuse::engine::replay::estimates_row(
            &exp,
            r.variant,
            r.k,
            &r.estimate,
            r.sensors.iter().map(|s| (s.link, s.bits)),
        ));
    }
    assert_eq!(got, reference);
}

/// Junk sent to a running center — random octets, truncated datagrams, frames with a wrong
/// FCS, frames of a step long past — is counted and dropped: the estimates are those of the
/// clean run.
#[test]
fn junk_datagrams_are_counted_and_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    arena_data(d, 100);
    let expected = replay(d, "rep", &[]);
    let port = free_port();
    let center = center(port, "100", &["--out", "live"], d);
    let nodes: Vec<Child> = (0..4).map(|i| node(i, port, d)).collect();
    let junk = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to = format!("127.0.0.1:{port}");
    // A well-formed frame of sensor 0, step 1, variant 0: stale once the run is past it.
    let good = live::frame_datagram(
        &hushfuse::link::Message::Measurement(hushfuse::linalg::Vector::from_vec(vec![1.0])),
        0,
        0,
        1,
    )
    .unwrap();
    let mut bad_fcs = wire::Datagram::decode(&good).unwrap();
    let last = bad_fcs.body.len() - 1;
    bad_fcs.body[last] ^= 0xff;
    let bad_fcs = bad_fcs.encode();
    let csv = d.join("live/estimates.csv");
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    let start = Instant::now();
    while lines(&csv) < 1701 && start.elapsed() < Duration::from_secs(60) {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let random: Vec<u8> = (0..(x % 40) as usize)
            .map(|j| (x >> (j % 8 * 8)) as u8)
            .collect();
        let _ = junk.send_to(&random, &to);
        let _ = junk.send_to(&good[..(x as usize % good.len())], &to);
        let _ = junk.send_to(&bad_fcs, &to);
        if lines(&csv) > 20 {
            let _ = junk.send_to(&good, &to);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    wait_ok(center, "the center");
    for (i, n) in nodes.into_iter().enumerate() {
        wait_ok(n, &format!("node {i}"));
    }
    assert_eq!(read(&csv), expected);
    let log = read(&d.join("live/live.log"));
    let counts: Vec<u64> = log
        .lines()
        .find(|l| l.starts_with("datagrams dropped:"))
        .unwrap()
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|t| t.parse().ok())
        .collect();
    // corrupt, bad frames, stale, duplicates, unknown sensors
    assert!(counts[0] > 100, "{log}");
    assert!(counts[1] > 100, "{log}");
    assert!(counts[2] > 10, "{log}");
}

/// Bad requests get a clear error and exit code 2; a node of another run is refused by the
/// center and says so.
#[test]
fn bad_requests_are_refused_with_their_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let err = |out: &Output, code: i32, text: &str| {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{stderr}");
        assert!(stderr.contains(text), "{text:?} not in: {stderr}");
    };
    err(
        &hushfuse(
            &[
                "node",
                "arena-1d",
                "--sensor",
                "9",
                "--connect",
                "127.0.0.1:9",
            ],
            d,
        ),
        2,
        "the scenario has 4 sensors (0 to 3), not 9",
    );
    err(
        &hushfuse(&["center", "arena-1d", "--listen", "127.0.0.1:0", "--scheme", "Nope"], d),
        2,
        "--scheme \"Nope\": the scenario has no such scheme; its schemes are: Centralized KF (all data)",
    );
    err(
        &hushfuse(
            &["node", "arena-1d", "--sensor", "0", "--connect", "nowhere"],
            d,
        ),
        2,
        "--connect: \"nowhere\" is not an address",
    );
    err(
        &hushfuse(&["live", "arena-1d", "--truth", "t.csv"], d),
        2,
        "--truth goes with --measurements",
    );
    // A node of another run (other steps): refused.
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let extra = [
        "--wait",
        "3",
        "--timeout",
        "0.05",
        "--scheme",
        "Send-on-delta",
        "--out",
        "c",
    ];
    let center = center(port, "5", &extra, d);
    std::thread::sleep(Duration::from_millis(300));
    let other = hushfuse(
        &[
            "node",
            "arena-1d",
            "--sensor",
            "0",
            "--connect",
            &listen,
            "--steps",
            "6",
        ],
        d,
    );
    err(
        &other,
        1,
        "the center refused this node: it runs another scenario, seed, number of steps or trial",
    );
    wait_ok(center, "the center without nodes");
    let log = read(&d.join("c/live.log"));
    assert!(
        log.contains("starting without sensor(s) 0, 1, 2, 3"),
        "{log}"
    );
    assert!(read(&d.join("c/estimates.csv")).contains(",no_report,0"));
}
