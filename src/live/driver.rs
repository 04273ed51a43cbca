//! The center over UDP ([`run_center`]): greets the nodes, paces the steps (lock step or the
//! wall clock), shows a status line once a second, hands every fused step to a [`CenterSink`]
//! before it announces the next; and the [`Journal`] a restarted center resumes from.
use super::center::{Center, SensorRecord, StepRecord};
use crate::linalg::Vector;
use crate::link::Received;
use crate::scenario::experiment::Experiment;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

/// When the center closes a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// When every node has reported, or after `timeout` (the nodes that did not report are
    /// silences).
    Lockstep { timeout: Duration },
    /// Every `period`, on the wall clock, with what has arrived.
    Period(Duration),
}

/// How [`run_center`] runs.
#[derive(Debug, Clone)]
pub struct CenterOptions {
    pub pace: Pace,
    /// How long to wait for every node's greeting before the first step (and after a restart).
    pub wait_for_nodes: Duration,
    /// Print the status line (to standard error) once a second.
    pub status: bool,
}

/// Takes every fused step (written and flushed before the next step is announced) and the
/// events worth a line in the log. Not an engine [`crate::engine::trial::Observer`]: it
/// journals what only a live run has (per sensor `missing` or `no_report`, the raw inbox a
/// restarted center replays) and the run's events.
pub trait CenterSink {
    fn record(&mut self, center: &Center, record: &StepRecord) -> Result<(), String>;
    fn event(&mut self, text: &str);
}

/// Runs `center` on `socket` until every variant has run.
pub fn run_center(
    socket: &UdpSocket,
    center: &mut Center,
    opts: &CenterOptions,
    sink: &mut dyn CenterSink,
) -> Result<(), String> {
    let n = center.sensors();
    let mut nodes: HashMap<usize, SocketAddr> = HashMap::new();
    let mut buf = [0u8; 2048];
    let mut status = Status::new(opts.status);
    let send = |octets: &[u8], to: SocketAddr| {
        // A datagram that cannot be sent now is as good as lost.
        let _ = socket.send_to(octets, to);
    };
    // Greetings: every node, or the wait is over.
    let start = Instant::now();
    while nodes.len() < n && start.elapsed() < opts.wait_for_nodes {
        socket
            .set_read_timeout(Some(Duration::from_millis(100)))
            .map_err(|e| e.to_string())?;
        if let Ok((len, from)) = socket.recv_from(&mut buf) {
            take(center, &buf[..len], from, &mut nodes, sink, &send);
        }
    }
    if nodes.len() < n {
        let missing: Vec<String> = (0..n)
            .filter(|i| !nodes.contains_key(i))
            .map(|i| i.to_string())
            .collect();
        sink.event(&format!(
            "starting without sensor(s) {} (no greeting within {:.0} s): they are silences until they come",
            missing.join(", "),
            opts.wait_for_nodes.as_secs_f64()
        ));
    }
    let t0 = Instant::now();
    let mut steps_done = 0u64;
    while !center.finished() {
        let announced = center.announce()?;
        for (i, to) in &nodes {
            send(&announced[*i], *to);
        }
        let step_start = Instant::now();
        let deadline = match opts.pace {
            Pace::Lockstep { timeout } => step_start + timeout,
            Pace::Period(p) => t0 + p.mul_f64((steps_done + 1) as f64),
        };
        let mut resent = step_start;
        loop {
            let now = Instant::now();
            let lockstep_done = matches!(opts.pace, Pace::Lockstep { .. }) && center.complete();
            if lockstep_done || now >= deadline {
                break;
            }
            // Announce again to nodes that have not reported (a lost announcement).
            if now.duration_since(resent) >= Duration::from_millis(500) {
                resent = now;
                for i in center.missing() {
                    if let Some(to) = nodes.get(&i) {
                        send(&center.announcement(i)?, *to);
                    }
                }
            }
            let wait = (deadline - now).min(Duration::from_millis(100));
            socket
                .set_read_timeout(Some(wait.max(Duration::from_micros(100))))
                .map_err(|e| e.to_string())?;
            if let Ok((len, from)) = socket.recv_from(&mut buf) {
                take(center, &buf[..len], from, &mut nodes, sink, &send);
            }
            status.show(center, n);
        }
        let (v, k) = center.position();
        let missing = center.missing();
        let record = center.close()?;
        if !missing.is_empty() {
            sink.event(&format!(
                "{} step {k}: no report from sensor(s) {}: silences",
                center.label(v),
                missing
                    .iter()
                    .map(|i| i.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        status.bits += record.bits;
        sink.record(center, &record)?;
        center.save_seen(false)?;
        steps_done += 1;
        status.show(center, n);
    }
    status.finish();
    center.save_seen(true)?;
    // Sealed once and sent three times: the copies share one counter, so a copy the node never
    // took cannot end a later run under the same key.
    let mut ends = Vec::with_capacity(nodes.len());
    for (&i, &to) in &nodes {
        ends.push((center.end_datagram(i)?, to));
    }
    for _ in 0..3 {
        for (end, to) in &ends {
            send(end, *to);
        }
    }
    let d = center.dropped;
    sink.event(&format!(
        "datagrams dropped: {} corrupt, {} bad frames, {} stale, {} duplicates, {} of unknown sensors, {} rejected (content not usable)",
        d.corrupt, d.bad_frame, d.stale, d.duplicate, d.unknown_sensor, d.rejected
    ));
    if let Some(s) = center.security_dropped() {
        let kinds: Vec<String> = s.kinds().iter().map(|(k, n)| format!("{n} {k}")).collect();
        sink.event(&format!(
            "dropped by the security check: {}",
            kinds.join(", ")
        ));
    }
    Ok(())
}

/// One datagram into the center: a greeting records the node's address, replies go back.
fn take(
    center: &mut Center,
    octets: &[u8],
    from: SocketAddr,
    nodes: &mut HashMap<usize, SocketAddr>,
    sink: &mut dyn CenterSink,
    send: &dyn Fn(&[u8], SocketAddr),
) {
    let a = center.accept(octets);
    if let Some((i, fresh)) = a.hello {
        let before = nodes.insert(i, from);
        if before.is_none() || fresh {
            let (v, k) = center.position();
            sink.event(&format!(
                "sensor {i} {} from {from} ({} step {k})",
                if before.is_some() || (fresh && k > 1) {
                    "rejoined"
                } else {
                    "joined"
                },
                center.label(v)
            ));
        }
    }
    for r in &a.replies {
        send(r, from);
    }
}

/// The status line: step, sensors heard, bits per second, the estimate and its 2-sigma.
struct Status {
    on: bool,
    tty: bool,
    last: Instant,
    since: Instant,
    bits: u64,
}

impl Status {
    fn new(on: bool) -> Self {
        use std::io::IsTerminal;
        Self {
            on,
            tty: std::io::stderr().is_terminal(),
            last: Instant::now(),
            since: Instant::now(),
            bits: 0,
        }
    }

    fn show(&mut self, center: &Center, n: usize) {
        if !self.on || self.last.elapsed() < Duration::from_secs(1) || center.finished() {
            return;
        }
        self.last = Instant::now();
        let (v, k) = center.position();
        let rate = self.bits as f64 / self.since.elapsed().as_secs_f64().max(1e-9);
        let mut line = format!(
            "{} step {k}: heard {}/{n}, {rate:.0} bit/s",
            center.label(v),
            center.heard()
        );
        if let Some(est) = center.estimate() {
            let _ = write!(line, ", x =");
            for j in 0..est.mean.len().min(4) {
                let _ = write!(
                    line,
                    " {:.3}±{:.3}",
                    est.mean[j],
                    2.0 * est.cov[(j, j)].max(0.0).sqrt()
                );
            }
        }
        if self.tty {
            eprint!("\r{line:<100}");
        } else {
            eprintln!("{line}");
        }
    }

    fn finish(&self) {
        if self.on && self.tty {
            eprintln!();
        }
    }
}

/// The center's journal: one line per fused step (what each sensor's slot held), flushed
/// before the next step is announced, so that a restarted center re-fuses exactly what it had.
pub struct Journal {
    file: std::fs::File,
}

impl Journal {
    /// Appends to the journal at `path` (created if absent).
    pub fn append(path: &std::path::Path) -> Result<Self, String> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|e| format!("cannot open {}: {e}", path.display()))?;
        Ok(Self { file })
    }

    /// The journal's line of one step (with its newline).
    pub fn line(r: &StepRecord) -> String {
        let mut line = format!("{} {}", r.variant, r.k);
        for (got, s) in r.inbox.iter().zip(&r.sensors) {
            let _ = write!(line, " {}:{}:{}", s.link, s.bits, token(got));
        }
        line.push('\n');
        line
    }

    pub fn write(&mut self, r: &StepRecord) -> Result<(), String> {
        let line = Self::line(r);
        self.file
            .write_all(line.as_bytes())
            .and_then(|_| self.file.sync_data())
            .map_err(|e| format!("cannot write the journal: {e}"))
    }

    /// The steps of a journal's text (after its head line), in order; a last line cut short by
    /// a crash is left out. Every line is checked against `exp`: a sensor entry per sensor, each
    /// entry's link agreeing with what it holds, a reading or estimate of the right dimension,
    /// finite, priced as it is, a frame that fits 802.15.4. Errors: (line index, what).
    pub fn read(text: &str, exp: &Experiment) -> Result<Vec<JournalLine>, (usize, String)> {
        let mut out = Vec::new();
        let lines: Vec<&str> = text.split_inclusive('\n').collect();
        for (no, line) in lines.iter().enumerate() {
            if !line.ends_with('\n') {
                break; // cut short
            }
            // The head line is line 0 of the file; these are lines 1, 2, ...
            out.push(parse_line(line.trim_end(), exp).map_err(|e| (no + 1, e))?);
        }
        Ok(out)
    }
}

fn hex(bytes: impl IntoIterator<Item = u8>) -> String {
    bytes.into_iter().map(|b| format!("{b:02x}")).collect()
}

fn token(r: &Received) -> String {
    let floats = |v: &Vector| {
        v.iter()
            .map(|x| format!("{:016x}", x.to_bits()))
            .collect::<Vec<_>>()
            .join(",")
    };
    match r {
        Received::Silent => "s".into(),
        Received::NotScheduled => "n".into(),
        Received::Measurement(z) => format!("m{}", floats(z)),
        Received::Estimate(x) => format!("e{}", floats(x)),
        Received::Frame(o) => format!("f{}", hex(o.iter().copied())),
    }
}

fn parse_token(t: &str) -> Option<Received> {
    let floats = |s: &str| -> Option<Vector> {
        let v = s
            .split(',')
            .map(|h| u64::from_str_radix(h, 16).ok().map(f64::from_bits))
            .collect::<Option<Vec<f64>>>()?;
        Some(Vector::from_vec(v))
    };
    let (head, rest) = t.split_at_checked(1)?;
    Some(match head {
        "s" if rest.is_empty() => Received::Silent,
        "n" if rest.is_empty() => Received::NotScheduled,
        "m" => Received::Measurement(floats(rest)?),
        "e" => Received::Estimate(floats(rest)?),
        "f" => Received::Frame(
            (0..rest.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(rest.get(i..i + 2)?, 16).ok())
                .collect::<Option<Vec<u8>>>()?,
        ),
        _ => return None,
    })
}

/// One journaled step: variant, step, the inbox, what each sensor did.
pub type JournalLine = (usize, usize, Vec<Received>, Vec<SensorRecord>);

fn parse_line(line: &str, exp: &Experiment) -> Result<JournalLine, String> {
    let mut parts = line.split(' ');
    let number = |p: Option<&str>, what: &str| -> Result<usize, String> {
        p.and_then(|t| t.parse().ok())
            .ok_or_else(|| format!("the {what} is not a number"))
    };
    let v = number(parts.next(), "variant")?;
    let k = number(parts.next(), "step")?;
    if v >= exp.variants.len() || k == 0 || k > exp.steps {
        return Err(format!(
            "variant {v}, step {k}: the scenario has {} variants of {} steps",
            exp.variants.len(),
            exp.steps
        ));
    }
    let sys = &exp.system;
    let mut inbox = Vec::new();
    let mut sensors = Vec::new();
    for (i, p) in parts.enumerate() {
        if i >= sys.n_sensors() {
            return Err(format!(
                "more sensor entries than the scenario's {} sensors",
                sys.n_sensors()
            ));
        }
        let bad = |what: String| format!("sensor {i}'s entry: {what}");
        let mut f = p.splitn(3, ':');
        let link = match f.next().unwrap_or_default() {
            "sent" => "sent",
            "silent" => "silent",
            "not_scheduled" => "not_scheduled",
            "missing" => "missing",
            "no_report" => "no_report",
            "rejected" => "rejected",
            other => return Err(bad(format!("{other:?} is not a link"))),
        };
        let bits: u64 = f
            .next()
            .and_then(|b| b.parse().ok())
            .ok_or_else(|| bad("its bits are not a number".into()))?;
        let got = f
            .next()
            .and_then(parse_token)
            .ok_or_else(|| bad("its message cannot be read".into()))?;
        let reals = |v: &Vector, dim: usize| -> Result<u64, String> {
            if v.len() != dim || !v.iter().all(|x| x.is_finite()) {
                return Err(bad(format!(
                    "{} values, {dim} finite ones expected",
                    v.len()
                )));
            }
            Ok(32 * dim as u64)
        };
        let priced = match (link, &got) {
            ("sent", Received::Measurement(z)) => reals(z, sys.sensors[i].meas_dim())?,
            ("sent", Received::Estimate(x)) => reals(x, sys.state_dim())?,
            ("sent", Received::Frame(o)) if o.len() <= super::wire::MAX_MPDU_OCTETS => {
                if bits == 0
                    || crate::link::codec802154::mpdu_bits_for_payload(bits) != 8 * o.len() as u64
                {
                    return Err(bad(format!(
                        "{bits} payload bits in a frame of {} octets",
                        o.len()
                    )));
                }
                bits
            }
            ("silent" | "no_report" | "rejected", Received::Silent)
            | ("not_scheduled" | "missing", Received::NotScheduled) => 0,
            _ => {
                return Err(bad(format!(
                    "a {link} entry cannot hold {}",
                    token_kind(&got)
                )))
            }
        };
        if bits != priced {
            return Err(bad(format!("{bits} bits, {priced} expected")));
        }
        inbox.push(got);
        sensors.push(SensorRecord { link, bits });
    }
    if inbox.len() != sys.n_sensors() {
        return Err(format!(
            "{} sensor entries, the scenario has {} sensors",
            inbox.len(),
            sys.n_sensors()
        ));
    }
    Ok((v, k, inbox, sensors))
}

/// What a journal token holds, in words.
fn token_kind(r: &Received) -> &'static str {
    match r {
        Received::Silent => "a silence",
        Received::NotScheduled => "no reading",
        Received::Measurement(_) => "a reading",
        Received::Estimate(_) => "an estimate",
        Received::Frame(_) => "a frame",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn journal_tokens_round_trip_exactly() {
        for r in [
            Received::Silent,
            Received::NotScheduled,
            Received::Measurement(Vector::from_vec(vec![0.1, -1e300])),
            Received::Estimate(Vector::from_vec(vec![f64::from(1.1f32)])),
            Received::Frame(vec![0x41, 0x88, 0, 255]),
        ] {
            assert_eq!(parse_token(&token(&r)), Some(r));
        }
        assert_eq!(parse_token("x"), None);
        assert_eq!(parse_token("fz0"), None);
        let text = crate::scenario::builtin::get("arena-1d").unwrap();
        let exp =
            crate::engine::replay::load_experiment(text, "arena-1d", 5, None, &Default::default())
                .unwrap()
                .0;
        let one = "sent:32:m3ff0000000000000";
        let good = format!("0 1 {one} silent:0:s no_report:0:s not_scheduled:0:n\n0 2 sent:3");
        let read = Journal::read(&good, &exp).unwrap();
        assert_eq!(read.len(), 1, "the cut last line is left out");
        assert_eq!(
            read[0].2[0],
            Received::Measurement(Vector::from_vec(vec![1.0]))
        );
        // A hand-edited line is refused, naming the line and what is wrong.
        let rest = "silent:0:s silent:0:s silent:0:s";
        for (line, says) in [
            ("garbage".to_string(), "variant is not a number"),
            (
                format!("0 1 {one} {rest} silent:0:s"),
                "more sensor entries",
            ),
            (
                format!("0 1 {one} silent:0:s silent:0:s"),
                "3 sensor entries",
            ),
            (
                format!("0 1 silent:0:m3ff0000000000000 {rest}"),
                "a silent entry cannot hold a reading",
            ),
            (
                format!("0 1 sent:100000000000:m3ff0000000000000 {rest}"),
                "100000000000 bits, 32 expected",
            ),
            (format!("0 1 sent:32:m7ff8000000000000 {rest}"), "finite"),
            (
                format!("0 1 sent:64:m3ff0000000000000,0 {rest}"),
                "2 values",
            ),
            (format!("0 99999 {one} {rest}"), "steps"),
        ] {
            let text = format!("0 1 {one} {rest}\n{line}\n");
            let (no, e) = Journal::read(&text, &exp).unwrap_err();
            assert_eq!(no, 2, "{line}");
            assert!(e.contains(says), "{line}: {e}");
        }
    }
}
