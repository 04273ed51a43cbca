//! Secured live runs (`[security]`, issue 41) on loopback: the estimates are those of the
//! unsecured run byte for byte; an attacker who knows the scenario but not the key — forged
//! readings and feedback, replays of an earlier run's datagrams under the same key, bit flips
//! — changes no estimate, and every datagram it sends is counted by kind; a node killed and
//! restarted never uses a frame counter twice; bad key files are refused naming the file.
#[path = "common/cli.rs"]
mod common;
use common::hushfuse;
use hushfuse::link::security::ccm_star::addressed_header_octets;
use hushfuse::link::security::counter::CounterStore;
use hushfuse::link::security::keys::{Key, KeyRing};
use hushfuse::link::security::{KeyIdMode, SecurityLevel, SecuritySpec};
use hushfuse::live::secure::{unsealed_part, SecureEnd};
use hushfuse::live::wire::{self, Datagram, Kind};
use std::collections::HashMap;
use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const SPEC: SecuritySpec = SecuritySpec {
    level: SecurityLevel::EncMic64,
    key_id_mode: KeyIdMode::Index,
    secure_feedback: true,
};
const STEPS: &str = "30";

/// arena-1d with its frames encrypted and signed (`enc-mic-64`), in `d/sec.toml`.
fn secured_scenario(d: &Path) {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/arena-1d.toml"),
    )
    .unwrap();
    let text = format!("{text}\n[security]\nlevel = \"enc-mic-64\"\n");
    std::fs::write(d.join("sec.toml"), text).unwrap();
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "exit {:?}\n{}\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
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

/// Waits for `c` to succeed; its standard error.
fn wait_ok(mut c: Child, what: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        if let Some(s) = c.try_wait().unwrap() {
            let mut err = String::new();
            let _ = std::io::Read::read_to_string(c.stderr.as_mut().unwrap(), &mut err);
            assert!(s.success(), "{what} failed: {s}\n{err}");
            return err;
        }
        assert!(Instant::now() < deadline, "{what} did not end");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The counts of a "dropped by the security check: …" line: (forged, replayed, others).
fn security_counts(text: &str, prefix: &str) -> (u64, u64, u64) {
    let line = text
        .lines()
        .find(|l| l.starts_with(prefix) && l.contains("dropped by the security check:"))
        .unwrap_or_else(|| panic!("no security line for {prefix:?} in\n{text}"));
    let mut counts = HashMap::new();
    for part in line.split(": ").last().unwrap().split(", ") {
        let (n, kind) = part.split_once(' ').unwrap();
        counts.insert(kind.to_string(), n.parse::<u64>().unwrap());
    }
    let others = counts["truncated"] + counts["bad_fcs"] + counts["unsecured"];
    (counts["forged"], counts["replayed"], others)
}

/// Which way a datagram went, and for which sensor.
type Stream = (bool, usize);

/// What the attacker sent towards each end: (forged or bit-flipped, replays).
#[derive(Default, Clone, Copy, Debug)]
struct Sent {
    forged: u64,
    replayed: u64,
}

/// The attacker inside the relay: it knows the scenario, not the key.
struct Attack {
    /// The earlier run's datagrams, per stream, in order.
    earlier: HashMap<Stream, Vec<Vec<u8>>>,
    /// A sender with its own key (an attacker's guess).
    fake: SecureEnd,
    /// Per stream: datagrams sent so far (genuine), and what was injected.
    seen: HashMap<Stream, usize>,
    sent: HashMap<Stream, Sent>,
    /// The center has spoken (it is listening: what was sent before may have gone to a port
    /// nobody had opened yet), and it has ended the run (what is sent now may never be read).
    started: bool,
    ended: bool,
}

impl Attack {
    /// What to send before genuine `g` of `stream`: a forgery, the earlier run's datagram at
    /// the same place, `g` with one bit flipped.
    fn before(&mut self, stream: Stream, g: &[u8]) -> Vec<Vec<u8>> {
        let j = *self.seen.entry(stream).and_modify(|j| *j += 1).or_insert(0);
        let i = stream.1;
        let mut out = Vec::new();
        let inner = Datagram::decode(unsealed_part(g, &SPEC));
        self.started |= !stream.0;
        self.ended |= inner.as_ref().is_ok_and(|d| d.kind == Kind::End);
        if !self.started || self.ended {
            return out;
        }
        let sent = self.sent.entry(stream).or_default();
        if let Ok(mut d) = inner {
            // A forged reading in place of a frame, "no reading" in place of a report, other
            // feedback or a catch-up flag in place of an announcement.
            match d.kind {
                Kind::Frame => {
                    let z = wire::mpdu(
                        d.step as u8,
                        wire::CENTER_ADDRESS,
                        wire::sensor_address(i),
                        &wire::f32_payload([1.0e3]),
                    )
                    .unwrap();
                    d.body = self.fake.seal_frame(&z, i).unwrap();
                }
                _ => d.flags ^= 1,
            }
            out.push(self.fake.seal_datagram(&d.encode(), i).unwrap());
            sent.forged += 1;
        }
        if let Some(old) = self.earlier.get(&stream).and_then(|e| e.get(j)) {
            out.push(old.clone());
            sent.replayed += 1;
        }
        // One bit flipped past the sensor index (octets 4 and 5 pick the key).
        let mut flipped = g.to_vec();
        let at = 6 + (j * 7) % (g.len() - 6);
        flipped[at] ^= 1 << (j % 8);
        out.push(flipped);
        sent.forged += 1;
        out
    }
}

/// What a relay saw: every genuine datagram per stream, in order.
type Capture = Arc<Mutex<HashMap<Stream, Vec<Vec<u8>>>>>;

fn sensor_of(octets: &[u8]) -> Option<usize> {
    let inner = unsealed_part(octets, &SPEC);
    Datagram::decode(inner).ok().map(|d| usize::from(d.sensor))
}

/// A relay on `listen` between the nodes and the center at `center` (a socket per node, so
/// the center sees one address per node), recording every datagram, and with `attack`,
/// injecting before each.
fn relay(
    listen: UdpSocket,
    center: SocketAddr,
    attack: Option<Arc<Mutex<Attack>>>,
    stop: Arc<AtomicBool>,
) -> (Capture, std::thread::JoinHandle<()>) {
    let capture: Capture = Arc::default();
    let cap = capture.clone();
    let handle = std::thread::spawn(move || {
        let listen = Arc::new(listen);
        listen
            .set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let mut upstream: HashMap<SocketAddr, Arc<UdpSocket>> = HashMap::new();
        let mut buf = [0u8; 2048];
        let mut threads = Vec::new();
        while !stop.load(Ordering::Relaxed) {
            let Ok((len, node)) = listen.recv_from(&mut buf) else {
                continue;
            };
            let g = buf[..len].to_vec();
            let Some(i) = sensor_of(&g) else { continue };
            let sock = upstream
                .entry(node)
                .or_insert_with(|| {
                    let s = Arc::new(UdpSocket::bind("127.0.0.1:0").unwrap());
                    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
                    let (s2, back, cap, attack, stop) = (
                        s.clone(),
                        listen.clone(),
                        cap.clone(),
                        attack.clone(),
                        stop.clone(),
                    );
                    threads.push(std::thread::spawn(move || {
                        let mut buf = [0u8; 2048];
                        while !stop.load(Ordering::Relaxed) {
                            let Ok((len, _)) = s2.recv_from(&mut buf) else {
                                continue;
                            };
                            let g = buf[..len].to_vec();
                            if let Some(a) = &attack {
                                for x in a.lock().unwrap().before((false, i), &g) {
                                    let _ = back.send_to(&x, node);
                                }
                            }
                            cap.lock()
                                .unwrap()
                                .entry((false, i))
                                .or_default()
                                .push(g.clone());
                            let _ = back.send_to(&g, node);
                        }
                    }));
                    s
                })
                .clone();
            if let Some(a) = &attack {
                for x in a.lock().unwrap().before((true, i), &g) {
                    let _ = sock.send_to(&x, center);
                }
            }
            cap.lock()
                .unwrap()
                .entry((true, i))
                .or_default()
                .push(g.clone());
            let _ = sock.send_to(&g, center);
        }
        for t in threads {
            let _ = t.join();
        }
    });
    (capture, handle)
}

/// A secured run of `sec.toml` through a relay: the center writing `out`, four nodes, `extra`
/// arguments for the center; returns what the relay captured, the center's log, and the
/// nodes' standard errors.
fn secured_run(
    d: &Path,
    out: &str,
    extra: &[&str],
    attack: Option<Arc<Mutex<Attack>>>,
) -> (HashMap<Stream, Vec<Vec<u8>>>, String, Vec<String>) {
    let center_socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let center_addr = center_socket.local_addr().unwrap();
    drop(center_socket);
    let listen = UdpSocket::bind("127.0.0.1:0").unwrap();
    let relay_addr = listen.local_addr().unwrap().to_string();
    let stop = Arc::new(AtomicBool::new(false));
    let (capture, relay) = relay(listen, center_addr, attack, stop.clone());
    let c = center_addr.to_string();
    let mut args = vec![
        "center", "sec.toml", "--listen", &c, "--key", "key", "--steps", STEPS, "--out", out,
    ];
    args.extend_from_slice(extra);
    let center = spawn(&args, d);
    let nodes: Vec<Child> = (0..4)
        .map(|i| {
            let i = i.to_string();
            spawn(
                &[
                    "node",
                    "sec.toml",
                    "--sensor",
                    &i,
                    "--connect",
                    &relay_addr,
                    "--key",
                    "key",
                    "--steps",
                    STEPS,
                ],
                d,
            )
        })
        .collect();
    wait_ok(center, "the center");
    let errs: Vec<String> = nodes
        .into_iter()
        .enumerate()
        .map(|(i, n)| wait_ok(n, &format!("node {i}")))
        .collect();
    stop.store(true, Ordering::Relaxed);
    relay.join().unwrap();
    let captured = capture.lock().unwrap().clone();
    (captured, read(&d.join(out).join("live.log")), errs)
}

/// The unsecured live run's estimates of the same scenario and readings.
fn plain_estimates(d: &Path) -> String {
    ok(&hushfuse(
        &["live", "arena-1d", "--steps", STEPS, "--out", "plain"],
        d,
    ));
    read(&d.join("plain/estimates.csv"))
}

/// The attack of the issue: a relay that knows the scenario but not the key sends, before
/// every genuine datagram in both directions, a forgery (a reading of 1000 in place of the
/// frame, "no reading" in place of a report, other flags on an announcement), the datagram
/// at the same place in an earlier run under the same key, and the genuine one with a bit
/// flipped. The estimates are the unsecured run's byte for byte; the center and every node
/// count each forged or flipped datagram as forged and each replay as replayed.
#[test]
fn an_attacker_without_the_key_changes_no_estimate_and_is_counted() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    secured_scenario(d);
    ok(&hushfuse(&["keygen", "key", "--sensors", "4"], d));
    let expected = plain_estimates(d);
    let (earlier, _, _) = secured_run(d, "run1", &[], None);
    assert_eq!(read(&d.join("run1/estimates.csv")), expected);

    let counters = CounterStore::create(&d.join("attacker.counter")).unwrap();
    let fake = SecureEnd::new(SPEC, KeyRing::network(Key::new([0x5a; 16])), 0, counters);
    let attack = Arc::new(Mutex::new(Attack {
        earlier,
        fake,
        seen: HashMap::new(),
        sent: HashMap::new(),
        started: false,
        ended: false,
    }));
    let (_, log, errs) = secured_run(d, "run2", &[], Some(attack.clone()));
    assert_eq!(read(&d.join("run2/estimates.csv")), expected);

    let sent = attack.lock().unwrap().sent.clone();
    let total = |up: bool| {
        sent.iter()
            .filter(|((u, _), _)| *u == up)
            .fold(Sent::default(), |a, (_, s)| Sent {
                forged: a.forged + s.forged,
                replayed: a.replayed + s.replayed,
            })
    };
    let up = total(true);
    assert!(up.forged > 2000 && up.replayed > 1000, "{up:?}");
    let (forged, replayed, others) = security_counts(&log, "dropped by the security check");
    // Every forgery and flip fails its MIC; no genuine datagram does.
    assert_eq!(forged, up.forged, "{log}");
    // Every replay is refused; a genuine resend of a frame already taken counts too.
    assert!(replayed >= up.replayed, "{replayed} < {}", up.replayed);
    assert_eq!(others, 0);
    for (i, err) in errs.iter().enumerate() {
        let s = sent.get(&(false, i)).copied().unwrap_or_default();
        assert!(s.forged > 100 && s.replayed > 50, "sensor {i}: {s:?}");
        let (forged, replayed, others) = security_counts(err, &format!("sensor {i}:"));
        assert_eq!(forged, s.forged, "sensor {i}");
        assert!(
            replayed >= s.replayed,
            "sensor {i}: {replayed} < {}",
            s.replayed
        );
        assert_eq!(others, 0);
    }
}

/// The frame counter of a secured MPDU (after the addressed header and the security control
/// octet).
fn frame_counter(mpdu: &[u8]) -> u32 {
    let fc = u16::from_le_bytes([mpdu[0], mpdu[1]]);
    let at = addressed_header_octets(fc).unwrap() + 1;
    u32::from_le_bytes(mpdu[at..at + 4].try_into().unwrap())
}

/// A node killed (SIGKILL) in the middle of a secured run and started again: across both of
/// its processes, every (sender, counter) pair on the wire secures one content only — an
/// envelope counter is never seen twice, and a frame counter twice only on the same frame
/// sent again — so no CCM* nonce is reused; the restarted node's frames are not refused as
/// replays.
#[test]
fn a_restarted_node_never_reuses_a_frame_counter() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    secured_scenario(d);
    ok(&hushfuse(&["keygen", "key", "--sensors", "4"], d));
    let center_socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let center_addr = center_socket.local_addr().unwrap();
    drop(center_socket);
    let listen = UdpSocket::bind("127.0.0.1:0").unwrap();
    let relay_addr = listen.local_addr().unwrap().to_string();
    let stop = Arc::new(AtomicBool::new(false));
    let (capture, relay) = relay(listen, center_addr, None, stop.clone());
    let c = center_addr.to_string();
    let center = spawn(
        &[
            "center",
            "sec.toml",
            "--listen",
            &c,
            "--key",
            "key",
            "--steps",
            "100",
            "--out",
            "live",
            "--timeout",
            "0.2",
            "--scheme",
            "Send-on-delta",
            "--scheme",
            "Censored PF",
        ],
        d,
    );
    let node = |i: usize| {
        let i = i.to_string();
        spawn(
            &[
                "node",
                "sec.toml",
                "--sensor",
                &i,
                "--connect",
                &relay_addr,
                "--key",
                "key",
                "--steps",
                "100",
            ],
            d,
        )
    };
    let mut nodes: Vec<Option<Child>> = (0..4).map(|i| Some(node(i))).collect();
    let csv = d.join("live/estimates.csv");
    let lines = |p: &Path| std::fs::read_to_string(p).map_or(0, |t| t.lines().count());
    let start = Instant::now();
    while lines(&csv) < 30 {
        assert!(start.elapsed() < Duration::from_secs(60), "no start");
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut n2 = nodes[2].take().unwrap();
    n2.kill().unwrap();
    n2.wait().unwrap();
    while lines(&csv) < 40 {
        std::thread::sleep(Duration::from_millis(1));
    }
    nodes[2] = Some(node(2));
    wait_ok(center, "the center");
    for (i, n) in nodes.into_iter().enumerate() {
        wait_ok(n.unwrap(), &format!("node {i}"));
    }
    stop.store(true, Ordering::Relaxed);
    relay.join().unwrap();
    let log = read(&d.join("live/live.log"));
    assert!(log.contains("sensor 2 rejoined"), "{log}");
    let captured = capture.lock().unwrap().clone();
    let up = &captured[&(true, 2)];
    let mut envelopes: HashMap<u32, &[u8]> = HashMap::new();
    let mut frames: HashMap<u32, Vec<u8>> = HashMap::new();
    for g in up {
        let n = g.len() - SPEC.level.mic_octets() - 4;
        let c = u32::from_le_bytes(g[n..n + 4].try_into().unwrap());
        assert!(
            envelopes.insert(c, g).is_none(),
            "envelope counter {c} of sensor 2 used twice"
        );
        let d = Datagram::decode(&g[..n]).unwrap();
        if d.kind == Kind::Frame {
            let f = frame_counter(&d.body);
            let before = frames.insert(f, d.body.clone());
            assert!(
                before.is_none_or(|b| b == d.body),
                "frame counter {f} of sensor 2 secures two frames"
            );
        }
    }
    assert!(frames.len() > 20, "{} frames", frames.len());
    let (forged, _, others) = security_counts(&log, "dropped by the security check");
    assert_eq!((forged, others), (0, 0), "{log}");
}

/// Key files the run cannot trust are refused with exit 2, naming the file, before any
/// socket work: readable by others, too short, not hexadecimal; and a secured scenario
/// without a key, or a key for an unsecured one.
#[test]
fn bad_key_files_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    secured_scenario(d);
    ok(&hushfuse(&["keygen", "good.key", "--sensors", "4"], d));
    let write = |name: &str, text: &str, mode: u32| {
        use std::os::unix::fs::PermissionsExt;
        std::fs::write(d.join(name), text).unwrap();
        std::fs::set_permissions(d.join(name), std::fs::Permissions::from_mode(mode)).unwrap();
    };
    let good = read(&d.join("good.key"));
    write("open.key", &good, 0o644);
    write("short.key", "network 0011223344\n", 0o600);
    write(
        "nothex.key",
        "network 000102030405060708090a0b0c0d0eXY\n",
        0o600,
    );
    for (file, why) in [
        ("open.key", "other"),
        ("short.key", "32"),
        ("nothex.key", "hex"),
    ] {
        for cmd in [
            vec!["center", "sec.toml", "--listen", "127.0.0.1:0"],
            vec![
                "node",
                "sec.toml",
                "--sensor",
                "0",
                "--connect",
                "127.0.0.1:9",
            ],
        ] {
            let mut args = cmd.clone();
            args.extend_from_slice(&["--key", file]);
            let out = hushfuse(&args, d);
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
            assert!(err.contains(file), "{args:?} names the file: {err}");
            assert!(err.to_lowercase().contains(why), "{args:?} says why: {err}");
            assert!(!err.contains(&good[good.len() - 33..good.len() - 1]));
        }
    }
    let out = hushfuse(&["center", "sec.toml", "--listen", "127.0.0.1:0"], d);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--key"));
    let out = hushfuse(
        &[
            "center",
            "arena-1d",
            "--listen",
            "127.0.0.1:0",
            "--key",
            "good.key",
        ],
        d,
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no [security]"));
}

/// `hushfuse live` on a secured scenario makes its own owner-only key in its folder, never
/// prints it, and gives the unsecured run's estimates byte for byte.
#[test]
fn live_makes_a_private_key_and_keeps_the_estimates() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    secured_scenario(d);
    let expected = plain_estimates(d);
    for _ in 0..2 {
        // Twice in one folder: the second run replaces the first one's key.
        let out = hushfuse(&["live", "sec.toml", "--steps", STEPS, "--out", "sec"], d);
        ok(&out);
        assert_eq!(read(&d.join("sec/estimates.csv")), expected);
        let key = read(&d.join("sec/live.key"));
        let hex = key
            .lines()
            .last()
            .unwrap()
            .split_whitespace()
            .last()
            .unwrap();
        assert_eq!(hex.len(), 32);
        let mode = std::fs::metadata(d.join("sec/live.key"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "owner-only: {mode:o}");
        for text in [
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
            read(&d.join("sec/live.log")),
        ] {
            assert!(!text.contains(hex), "the key is never printed");
        }
        let log = read(&d.join("sec/live.log"));
        let (forged, _, others) = security_counts(&log, "dropped by the security check");
        assert_eq!((forged, others), (0, 0), "{log}");
    }
}
