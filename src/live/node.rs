//! The sensor side of a live run, without sockets: [`Node`] turns the center's datagrams into
//! the sensor's replies, running the scheme's own [`crate::scheme::SensorNode`] on its readings
//! with its own coins ([`crate::stats::seeding::sensor_coins`]). A program that embeds a
//! sensor feeds it what arrives and sends what it returns; [`run_node`] does that over UDP.
use super::secure::{self, SecureEnd};
use super::wire::{self, Datagram, Kind, MessageKind, DONE_READING, HELLO_FRESH, STEP_CATCH_UP};
use crate::engine::fusion_side;
use crate::linalg::Vector;
use crate::link::{Message, Transmission};
use crate::scenario::experiment::Experiment;
use crate::scheme::{Feedback, SensorNode};
use crate::stats::seeding;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

/// Where a node's readings come from.
pub trait Readings {
    /// The sensor's reading at step `k` (1-based) of every variant (each variant reads the
    /// same data from step 1); `None`: no reading at that step.
    fn reading(&mut self, k: usize) -> Result<Option<Vector>, String>;

    /// Whether [`Readings::reading`] of step `k` would answer at once; a node waits for it
    /// while still hearing the center ([`run_node`]). Readings held in memory always are.
    fn ready(&mut self, _k: usize) -> bool {
        true
    }
}

/// Readings held in memory: a simulated trial's, or a recording's.
pub struct Recorded(pub Vec<Option<Vector>>);

impl Readings for Recorded {
    fn reading(&mut self, k: usize) -> Result<Option<Vector>, String> {
        self.0.get(k.wrapping_sub(1)).cloned().ok_or_else(|| {
            format!(
                "no reading for step {k}: the data has {} steps",
                self.0.len()
            )
        })
    }
}

/// Readings from lines of text (standard input): line k is the reading of step k, its
/// components separated by commas or spaces; an empty line is no reading. Lines read are kept,
/// so the next variant reads them again.
pub struct Lines<R> {
    input: R,
    parsed: ParsedLines,
}

impl<R: std::io::BufRead> Lines<R> {
    pub fn new(input: R, dim: usize) -> Self {
        Self {
            input,
            parsed: ParsedLines::new(dim),
        }
    }
}

impl<R: std::io::BufRead> Readings for Lines<R> {
    fn reading(&mut self, k: usize) -> Result<Option<Vector>, String> {
        while self.parsed.read.len() < k {
            let mut line = String::new();
            let n = self.input.read_line(&mut line);
            self.parsed.push(n.map(|n| (n > 0).then_some(line)))?;
        }
        Ok(self.parsed.read[k - 1].clone())
    }
}

/// [`Lines`] read by a thread of their own, so that a node waiting for a reading that has not
/// come yet still hears the center (it ends the run, or moves on without this sensor): an input
/// that stays open but silent never keeps the node alive after the run ([`Readings::ready`]).
pub struct BackgroundLines {
    lines: std::sync::mpsc::Receiver<std::io::Result<Option<String>>>,
    parsed: ParsedLines,
    /// The input ended or failed: what is read is all there will be.
    over: bool,
}

impl BackgroundLines {
    /// Reads `input` (e.g. standard input) line by line on a thread of its own.
    pub fn spawn<R: std::io::BufRead + Send + 'static>(mut input: R, dim: usize) -> Self {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || loop {
            let mut line = String::new();
            let r = input.read_line(&mut line).map(|n| (n > 0).then_some(line));
            let end = !matches!(r, Ok(Some(_)));
            if tx.send(r).is_err() || end {
                return;
            }
        });
        Self {
            lines: rx,
            parsed: ParsedLines::new(dim),
            over: false,
        }
    }

    /// Takes one line from the reader thread (waiting for it when `block`); false when none
    /// was there (or the input is over).
    fn take(&mut self, block: bool) -> Result<bool, String> {
        if self.over {
            return Ok(false);
        }
        let r = if block {
            self.lines.recv().ok()
        } else {
            self.lines.try_recv().ok()
        };
        let Some(r) = r else {
            return Ok(false);
        };
        if !matches!(r, Ok(Some(_))) {
            self.over = true;
        }
        self.parsed.push(r)?;
        Ok(true)
    }
}

impl Readings for BackgroundLines {
    fn reading(&mut self, k: usize) -> Result<Option<Vector>, String> {
        while self.parsed.read.len() < k {
            if !self.take(true)? && self.over {
                return Err(self.parsed.ended());
            }
        }
        Ok(self.parsed.read[k - 1].clone())
    }

    fn ready(&mut self, k: usize) -> bool {
        while self.parsed.read.len() < k {
            match self.take(false) {
                Ok(true) => {}
                // An error or the end of the input: `reading` reports it now.
                Err(_) => return true,
                Ok(false) => return self.over,
            }
        }
        true
    }
}

/// The lines of a reading source parsed so far.
struct ParsedLines {
    dim: usize,
    read: Vec<Option<Vector>>,
    /// A line that could not be read or parsed: every later reading reports it.
    failed: Option<String>,
}

/// Characters of a bad line shown in its error (a 5 MB line is not echoed whole).
const ECHO_CHARS: usize = 60;

impl ParsedLines {
    fn new(dim: usize) -> Self {
        Self {
            dim,
            read: Vec::new(),
            failed: None,
        }
    }

    fn ended(&self) -> String {
        self.failed.clone().unwrap_or_else(|| {
            format!(
                "the input ended at line {}: one line per step is needed (an empty line for no reading)",
                self.read.len() + 1
            )
        })
    }

    /// Parses the next line (`Ok(None)`: the input ended).
    fn push(&mut self, line: std::io::Result<Option<String>>) -> Result<(), String> {
        if let Some(f) = &self.failed {
            return Err(f.clone());
        }
        let line_no = self.read.len() + 1;
        let parsed = match line {
            Err(e) => Err(format!("cannot read line {line_no}: {e}")),
            Ok(None) => Err(self.ended()),
            Ok(Some(line)) => parse_line(&line, line_no, self.dim),
        };
        match parsed {
            Ok(z) => {
                self.read.push(z);
                Ok(())
            }
            Err(e) => {
                self.failed = Some(e.clone());
                Err(e)
            }
        }
    }
}

/// Line `line_no` as a reading of `dim` components (`None`: an empty line, no reading). Every
/// value must be finite and fit the 32-bit single that carries it on the wire.
fn parse_line(line: &str, line_no: usize, dim: usize) -> Result<Option<Vector>, String> {
    let echo = || {
        let t = line.trim();
        match t.char_indices().nth(ECHO_CHARS) {
            Some((cut, _)) => format!("{:?}… ({} characters)", &t[..cut], t.chars().count()),
            None => format!("{t:?}"),
        }
    };
    let fields: Vec<&str> = line
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .collect();
    if fields.is_empty() {
        return Ok(None);
    }
    let mut values = Vec::with_capacity(fields.len());
    for f in &fields {
        let x = f
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("line {line_no}: {} is not finite numbers", echo()))?;
        if x.abs() > f64::from(f32::MAX) {
            return Err(format!(
                "line {line_no}: {f} does not fit the 32-bit single that carries a reading on the wire (at most {:e} in magnitude); rescale the readings",
                f32::MAX
            ));
        }
        values.push(x);
    }
    if values.len() != dim {
        return Err(format!(
            "line {line_no}: {} numbers, the sensor measures {dim}",
            values.len()
        ));
    }
    Ok(Some(Vector::from_vec(values)))
}

/// What the node does after a datagram.
#[derive(Debug, Default)]
pub struct Reply {
    /// Datagrams to send to the center, in order.
    pub datagrams: Vec<Vec<u8>>,
    /// The center said the run is over.
    pub finished: bool,
}

/// One variant's sensor, as far as it got.
struct Current {
    variant: usize,
    sensor: Box<dyn SensorNode>,
    coins: Xoshiro256PlusPlus,
    /// Steps done (0: none).
    done: usize,
    /// The feedback the sensor last heard.
    held: Option<Feedback>,
    /// The replies of the last step done, sent again when the center asks for it again.
    last: Vec<Vec<u8>>,
}

/// Sensor `sensor` of a live run of trial `trial` of `exp`.
pub struct Node<'a> {
    exp: &'a Experiment,
    sensor: usize,
    trial: usize,
    readings: Box<dyn Readings + 'a>,
    current: Option<Current>,
    fresh: bool,
    /// The node's end of the secured link, when the scenario secures its frames.
    secure: Option<SecureEnd>,
}

/// The first eight octets of a SHA-256 of what a node and its center must agree on: the
/// scenario as run, its seed and steps, and the trial.
pub fn fingerprint(exp: &Experiment, scenario_text: &str, trial: usize) -> [u8; 8] {
    let hex = crate::output::sha256_hex(
        format!("{scenario_text}\0{}\0{}\0{trial}", exp.seed, exp.steps).as_bytes(),
    );
    let mut out = [0u8; 8];
    for (o, pair) in out.iter_mut().zip(hex.as_bytes().chunks(2)) {
        *o = u8::from_str_radix(std::str::from_utf8(pair).unwrap_or("00"), 16).unwrap_or(0);
    }
    out
}

impl<'a> Node<'a> {
    pub fn new(
        exp: &'a Experiment,
        sensor: usize,
        trial: usize,
        readings: Box<dyn Readings + 'a>,
        secure: Option<SecureEnd>,
    ) -> Result<Self, String> {
        if sensor >= exp.system.n_sensors() {
            return Err(format!(
                "the scenario has {} sensors (0 to {}), not {sensor}",
                exp.system.n_sensors(),
                exp.system.n_sensors().saturating_sub(1)
            ));
        }
        super::check_live(exp)?;
        super::center::check_keys(exp, secure.as_ref())?;
        Ok(Self {
            exp,
            sensor,
            trial,
            readings,
            current: None,
            fresh: true,
            secure,
        })
    }

    /// The greeting that (re)announces this node to the center (sealed in a secured run; the
    /// error is a frame counter file that cannot be written).
    pub fn hello(&mut self, fingerprint: [u8; 8]) -> Result<Vec<u8>, String> {
        let mut d = Datagram::new(Kind::Hello, self.sensor, 0, 0);
        d.flags = if self.fresh { HELLO_FRESH } else { 0 };
        d.body = fingerprint.to_vec();
        self.seal_up(d.encode())
    }

    /// A datagram to the center as it goes up: sealed in a secured run.
    fn seal_up(&mut self, datagram: Vec<u8>) -> Result<Vec<u8>, String> {
        match self.secure.as_mut() {
            Some(end) => end.seal_datagram(&datagram, self.sensor),
            None => Ok(datagram),
        }
    }

    /// What the node's end of the secured link dropped (`None`: the run is not secured).
    pub fn security_dropped(&self) -> Option<secure::Dropped> {
        self.secure.as_ref().map(SecureEnd::dropped)
    }

    /// Whether [`Node::handle`] would answer `octets` at once: false for the announcement of a
    /// step whose reading has not come yet ([`Readings::ready`]).
    pub fn ready(&mut self, octets: &[u8]) -> bool {
        let octets = match &self.secure {
            Some(end) if end.secures_downlink() => secure::unsealed_part(octets, end.spec()),
            _ => octets,
        };
        match Datagram::decode(octets) {
            Ok(d) if d.kind == Kind::Step && usize::from(d.sensor) == self.sensor => {
                self.readings.ready(d.step as usize)
            }
            _ => true,
        }
    }

    /// Handles one datagram from the center. Datagrams that are not for this node, corrupt,
    /// or of a step already done are ignored (an empty reply).
    pub fn handle(&mut self, octets: &[u8]) -> Result<Reply, String> {
        let octets = match self.secure.as_mut() {
            Some(end) if end.secures_downlink() => {
                match end.open_datagram(octets, wire::CENTER_ADDRESS, self.sensor) {
                    Ok(inner) => inner,
                    // Forged, replayed, truncated: counted, and not heard.
                    Err(_) => return Ok(Reply::default()),
                }
            }
            _ => octets,
        };
        let Ok(d) = Datagram::decode(octets) else {
            return Ok(Reply::default());
        };
        let mut reply = self.handle_datagram(&d)?;
        reply.datagrams = std::mem::take(&mut reply.datagrams)
            .into_iter()
            .map(|d| self.seal_up(d))
            .collect::<Result<_, _>>()?;
        if let Some(end) = self.secure.as_mut() {
            end.save_seen(reply.finished)?;
        }
        Ok(reply)
    }

    fn handle_datagram(&mut self, d: &Datagram) -> Result<Reply, String> {
        match d.kind {
            Kind::End => Ok(Reply {
                datagrams: Vec::new(),
                finished: true,
            }),
            Kind::Reject => Err(format!(
                "the center refused this node: {}",
                String::from_utf8_lossy(&d.body)
            )),
            Kind::Step if usize::from(d.sensor) == self.sensor => self.step(d),
            _ => Ok(Reply::default()),
        }
    }

    fn step(&mut self, d: &Datagram) -> Result<Reply, String> {
        let (v, k) = (usize::from(d.variant), d.step as usize);
        if v >= self.exp.variants.len() || k == 0 || k > self.exp.steps {
            return Ok(Reply::default());
        }
        if self.current.as_ref().is_none_or(|c| c.variant < v) {
            self.current = Some(self.start(v)?);
        }
        let cur = self.current.as_mut().expect("just set");
        if cur.variant > v || k < cur.done {
            return Ok(Reply::default());
        }
        let catch_up = d.flags & STEP_CATCH_UP != 0;
        if k == cur.done {
            // Asked again (a restarted center, a lost reply): the same answer.
            let datagrams = if catch_up {
                Vec::new()
            } else {
                cur.last.clone()
            };
            return Ok(Reply {
                datagrams,
                finished: false,
            });
        }
        if k > cur.done + 1 {
            // Steps missed (this node was down, or their announcements were lost): ask for them.
            let ask = Datagram::new(Kind::CatchUp, self.sensor, v, cur.done).encode();
            return Ok(Reply {
                datagrams: vec![ask],
                finished: false,
            });
        }
        self.fresh = false;
        let replies = self.sense(d, k)?;
        let cur = self.current.as_mut().expect("current variant");
        cur.done = k;
        cur.last = replies.clone();
        Ok(Reply {
            datagrams: if catch_up { Vec::new() } else { replies },
            finished: false,
        })
    }

    fn start(&self, v: usize) -> Result<Current, String> {
        let stream = seeding::coin_stream(v);
        let center_seed = seeding::center_seed(self.exp.seed, self.trial as u64, stream);
        let mut inst = self.exp.variants[v]
            .scheme
            .build_for_trial(self.trial, center_seed)
            .map_err(|e| format!("cannot build the scheme: {e}"))?;
        let sensor = inst.sensors.swap_remove(self.sensor);
        Ok(Current {
            variant: v,
            sensor,
            coins: seeding::sensor_coins(self.exp.seed, self.trial as u64, stream, self.sensor),
            done: 0,
            held: None,
            last: Vec::new(),
        })
    }

    /// Step `k`: the feedback heard, the reading, the sensor's decision, its frame.
    fn sense(&mut self, d: &Datagram, k: usize) -> Result<Vec<Vec<u8>>, String> {
        let (i, n) = (self.sensor, self.exp.system.n_sensors());
        let reading = self.readings.reading(k)?;
        let cur = self.current.as_mut().expect("current variant");
        let v = cur.variant;
        let label = &self.exp.curves[self.exp.variants[v].curve].label;
        // Secured feedback is opened first; feedback that does not verify is not heard (`None`:
        // the sensor keeps what it last heard).
        let body = match self.secure.as_mut() {
            Some(end) if end.secures_downlink() && !d.body.is_empty() => {
                end.open_frame(&d.body, wire::CENTER_ADDRESS, i).ok()
            }
            _ => Some(d.body.clone()),
        };
        if let Some(body) = body {
            if let Ok(Some(fb)) =
                wire::read_feedback(d.flags, &body, i, n, self.exp.system.state_dim())
            {
                cur.held = Some(fb);
            } else if d.flags & wire::STEP_REFERENCE != 0 && body.is_empty() {
                // An innovation reference with nothing for this sensor (it is not activated).
                cur.held = Some(Feedback::InnovationReference(vec![None; n]));
            }
        }
        let schedule = self.exp.variants[v].scheme.schedule();
        let mut out = Vec::new();
        let steps = fusion_side::scheduled(schedule, k, i, n, reading.is_some());
        if let (true, Some(z)) = (steps, &reading) {
            let t = cur
                .sensor
                .step(k, z, cur.held.as_ref(), &mut cur.coins)
                .map_err(|e| format!("scheme {label}, step {k}: {e}"))?;
            if let Transmission::Send(m) = t {
                let mut frame = frame_datagram(&m, i, v, k).map_err(|e| {
                    format!("scheme {label}, step {k}: its message cannot be sent: {e}")
                })?;
                if let Some(end) = self.secure.as_mut() {
                    // The 802.15.4 frame secured as the radio sends it.
                    let mut d = Datagram::decode(&frame).expect("our own datagram");
                    d.body = end.seal_frame(&d.body, i).map_err(|e| {
                        format!("scheme {label}, step {k}: its frame cannot be secured: {e}")
                    })?;
                    frame = d.encode();
                }
                out.push(frame);
            }
        }
        let mut done = Datagram::new(Kind::Done, i, v, k);
        done.flags = if reading.is_some() { DONE_READING } else { 0 };
        out.push(done.encode());
        Ok(out)
    }
}

/// The [`Kind::Frame`] datagram of sensor `i`'s message at step `k` of variant `v`.
pub fn frame_datagram(m: &Message, i: usize, v: usize, k: usize) -> Result<Vec<u8>, String> {
    let (kind, body) = match m {
        Message::Measurement(v) | Message::Estimate(v) => (
            if matches!(m, Message::Measurement(_)) {
                MessageKind::Measurement
            } else {
                MessageKind::Estimate
            },
            wire::mpdu(
                k as u8,
                wire::CENTER_ADDRESS,
                wire::sensor_address(i),
                &wire::f32_payload(v.iter().copied()),
            )
            .map_err(|e| e.to_string())?,
        ),
        Message::Frame { octets, .. } => {
            if octets.len() > wire::MAX_MPDU_OCTETS {
                return Err(format!("a frame of {} octets", octets.len()));
            }
            (MessageKind::Codec, octets.clone())
        }
    };
    let mut d = Datagram::new(Kind::Frame, i, v, k);
    d.flags = kind.code();
    d.aux = u16::try_from(m.bits()).map_err(|_| format!("{} payload bits", m.bits()))?;
    d.body = body;
    Ok(d.encode())
}

/// How [`run_node`] talks to the center.
#[derive(Debug, Clone)]
pub struct NodeOptions {
    pub center: SocketAddr,
    /// Greet the center again after this long without a word from it.
    pub hello_every: Duration,
    /// Give up after this long without a word from the center.
    pub give_up_after: Duration,
}

impl NodeOptions {
    /// The center at `center`; a greeting every second of silence, giving up after a minute.
    pub fn to(center: SocketAddr) -> Self {
        Self {
            center,
            hello_every: Duration::from_secs(1),
            give_up_after: Duration::from_secs(60),
        }
    }
}

/// Runs `node` against the center at `opts.center` until the center ends the run.
pub fn run_node(node: &mut Node, fingerprint: [u8; 8], opts: &NodeOptions) -> Result<(), String> {
    let ended = serve_node(node, fingerprint, opts);
    if let Some(d) = node.security_dropped() {
        // The node's own count of what it refused (forged or replayed announcements), for
        // whoever runs it; the center's is in its live.log.
        let kinds: Vec<String> = d.kinds().iter().map(|(k, n)| format!("{n} {k}")).collect();
        eprintln!(
            "sensor {}: dropped by the security check: {}",
            node.sensor,
            kinds.join(", ")
        );
    }
    ended
}

fn serve_node(node: &mut Node, fingerprint: [u8; 8], opts: &NodeOptions) -> Result<(), String> {
    let bind: SocketAddr = if opts.center.is_ipv4() {
        "0.0.0.0:0".parse().expect("address")
    } else {
        "[::]:0".parse().expect("address")
    };
    let socket = UdpSocket::bind(bind).map_err(|e| format!("cannot open a UDP socket: {e}"))?;
    let send = |octets: &[u8]| {
        // A datagram that cannot be sent now is as good as lost: the center asks again.
        let _ = socket.send_to(octets, opts.center);
    };
    send(&node.hello(fingerprint)?);
    let mut heard = Instant::now();
    let mut buf = [0u8; 2048];
    // A step announced before its reading came (readings from a live input): handled once the
    // reading is there, while the center is still heard (it may end the run meanwhile).
    let mut waiting: Option<Vec<u8>> = None;
    loop {
        if let Some(w) = waiting.take_if(|w| node.ready(w)) {
            let reply = node.handle(&w)?;
            for d in &reply.datagrams {
                send(d);
            }
            if reply.finished {
                return Ok(());
            }
        }
        let wait = if waiting.is_some() {
            Duration::from_millis(20)
        } else {
            opts.hello_every
        };
        socket
            .set_read_timeout(Some(wait))
            .map_err(|e| e.to_string())?;
        match socket.recv_from(&mut buf) {
            Ok((len, from)) => {
                if from != opts.center {
                    continue;
                }
                heard = Instant::now();
                if !node.ready(&buf[..len]) {
                    // The newest announcement replaces an older one still waiting.
                    waiting = Some(buf[..len].to_vec());
                    continue;
                }
                let reply = node.handle(&buf[..len])?;
                for d in &reply.datagrams {
                    send(d);
                }
                if reply.finished {
                    return Ok(());
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::ConnectionRefused
                ) =>
            {
                if waiting.is_some() {
                    // Waiting for a reading, and the center is quiet: keep waiting (it announces
                    // again, or ends the run), but greet it now and then.
                    if heard.elapsed() >= opts.hello_every {
                        heard = Instant::now();
                        send(&node.hello(fingerprint)?);
                    }
                    continue;
                }
                if heard.elapsed() >= opts.give_up_after {
                    return Err(format!(
                        "no word from the center at {} for {:.0} s",
                        opts.center,
                        opts.give_up_after.as_secs_f64()
                    ));
                }
                send(&node.hello(fingerprint)?);
            }
            Err(e) => return Err(format!("cannot receive: {e}")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_read_one_reading_per_step_and_keep_them() {
        let text = "1.5, 2\n\n3 4\n";
        let mut r = Lines::new(std::io::Cursor::new(text), 2);
        assert_eq!(
            r.reading(3).unwrap(),
            Some(Vector::from_vec(vec![3.0, 4.0]))
        );
        assert_eq!(
            r.reading(1).unwrap(),
            Some(Vector::from_vec(vec![1.5, 2.0]))
        );
        assert_eq!(r.reading(2).unwrap(), None, "an empty line: no reading");
        let e = r.reading(4).unwrap_err();
        assert!(e.contains("ended at line 4"), "{e}");
        let mut bad = Lines::new(std::io::Cursor::new("1 nan\n"), 2);
        assert!(bad.reading(1).unwrap_err().contains("not finite numbers"));
        let mut short = Lines::new(std::io::Cursor::new("1\n"), 2);
        assert!(short.reading(1).unwrap_err().contains("measures 2"));
    }

    /// A value the wire's single cannot carry is refused at the node, naming the line; a long
    /// bad line is not echoed whole.
    #[test]
    fn lines_refuse_what_a_single_cannot_carry_and_cut_long_echoes() {
        for big in ["1e39", "-1e300"] {
            let mut r = Lines::new(std::io::Cursor::new(format!("1\n{big}\n")), 1);
            assert!(r.reading(1).is_ok());
            let e = r.reading(2).unwrap_err();
            assert!(
                e.starts_with("line 2:") && e.contains(big) && e.contains("32-bit single"),
                "{e}"
            );
        }
        let long = "x".repeat(5_000_000);
        let mut r = Lines::new(std::io::Cursor::new(format!("{long}\n")), 1);
        let e = r.reading(1).unwrap_err();
        assert!(
            e.len() < 200 && e.contains("5000000 characters"),
            "{}",
            &e[..e.len().min(300)]
        );
    }

    /// Lines read on a thread: not ready before the line comes, ready after; the end of the
    /// input makes the reading report it at once.
    #[test]
    fn background_lines_say_when_a_reading_is_there() {
        let (r, mut w) = std::io::pipe().unwrap();
        let mut lines = BackgroundLines::spawn(std::io::BufReader::new(r), 1);
        assert!(!lines.ready(1));
        use std::io::Write;
        writeln!(w, "2.5").unwrap();
        let start = Instant::now();
        while !lines.ready(1) && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(lines.reading(1).unwrap(), Some(Vector::from_vec(vec![2.5])));
        assert!(!lines.ready(2));
        drop(w);
        while !lines.ready(2) && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(lines.reading(2).unwrap_err().contains("ended at line 2"));
    }

    #[test]
    fn recorded_readings_name_a_step_beyond_the_data() {
        let mut r = Recorded(vec![None]);
        assert_eq!(r.reading(1).unwrap(), None);
        assert!(r.reading(2).unwrap_err().contains("1 steps"));
        assert!(r.reading(0).is_err());
    }
}
