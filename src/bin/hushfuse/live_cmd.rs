//! `hushfuse center`, `node`, `live` and `channel-proxy`: a live run over UDP
//! ([`hushfuse::live`]).
use super::*;
use hushfuse::linalg::Vector;
use hushfuse::live::{self, Center, CenterOptions, LiveFolder, Node, NodeOptions, Pace};
use hushfuse::scenario::experiment::Experiment;
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::time::Duration;

/// What every process of one live run must agree on.
#[derive(clap::Args, Clone, Default)]
pub(crate) struct LiveRun {
    /// Coins of this trial (and, for simulated readings, its measurements).
    #[arg(long, default_value_t = 0)]
    pub(crate) trial: usize,
    /// Override the scenario's seed.
    #[arg(long)]
    pub(crate) seed: Option<u64>,
    /// Steps (default: the scenario's, or those of the recorded measurements).
    #[arg(long)]
    pub(crate) steps: Option<usize>,
    /// The scenario with a Bernoulli link that loses each packet with probability P (as
    /// `hushfuse run --loss`); the channel proxy applies it.
    #[arg(long, value_name = "P")]
    pub(crate) loss: Option<f64>,
    /// The run's key file, for a scenario with a [security] level (docs/live.md: format,
    /// owner-only permissions; `hushfuse keygen` makes one). The frame counters are kept
    /// beside it. `hushfuse live` makes a fresh one in its folder when none is given.
    #[arg(long, value_name = "FILE")]
    pub(crate) key: Option<PathBuf>,
}

/// How the center paces and waits.
#[derive(clap::Args, Clone)]
pub(crate) struct Pacing {
    /// Close each step after SECS on the wall clock (default: lock step, when every node has
    /// reported).
    #[arg(long, value_name = "SECS")]
    pub(crate) period: Option<f64>,
    /// In lock step, close a step after SECS without every node's report (the silent nodes
    /// are silences).
    #[arg(long, value_name = "SECS", default_value_t = 10.0)]
    pub(crate) timeout: f64,
    /// Seconds to wait for every node to greet before the first step.
    #[arg(long, value_name = "SECS", default_value_t = 30.0)]
    pub(crate) wait: f64,
    /// Run only these schemes (labels as in the tables; repeat the option); default: all.
    #[arg(long = "scheme", value_name = "LABEL")]
    pub(crate) schemes: Vec<String>,
}

/// Longest wait a live option takes: a day (beyond it a deadline on the clock can overflow).
const MAX_WAIT_SECONDS: f64 = 86_400.0;

fn seconds(name: &str, s: f64) -> Result<Duration, Failure> {
    Duration::try_from_secs_f64(s)
        .ok()
        .filter(|d| !d.is_zero() && s <= MAX_WAIT_SECONDS)
        .ok_or_else(|| {
            Failure::Input(format!(
                "{name}: expected a positive number of seconds up to {MAX_WAIT_SECONDS} (a day), got {s}"
            ))
        })
}

fn address(text: &str, what: &str) -> Result<SocketAddr, Failure> {
    text.to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| Failure::Input(format!("{what}: {text:?} is not an address (HOST:PORT)")))
}

/// The scenario's text as every process of the run loads it, and the experiment of `steps`
/// steps (the scenario's when `None`).
pub(crate) fn load(
    scenario: &str,
    run: &LiveRun,
    data_steps: Option<usize>,
) -> Result<(Experiment, String), Failure> {
    let (text, source) = scenario_text(scenario)?;
    let text = with_loss(text, &source, run.loss)?;
    let steps = match run.steps.or(data_steps) {
        Some(s) => s,
        None => {
            build::parse(&text, &source)
                .map_err(|e| Failure::Input(e.to_string()))?
                .steps
        }
    };
    let (exp, _) = replay::load_experiment(&text, &source, steps, run.seed, &Default::default())
        .map_err(|e| Failure::Input(e.to_string()))?;
    live::check_live(&exp).map_err(Failure::Input)?;
    Ok((exp, text))
}

/// The variants `pacing.schemes` names (all when empty).
fn variants(exp: &Experiment, pacing: &Pacing) -> Result<Vec<usize>, Failure> {
    let label = |v: usize| exp.curves[exp.variants[v].curve].label.as_str();
    for s in &pacing.schemes {
        if !(0..exp.variants.len()).any(|v| label(v) == s) {
            let all: Vec<&str> = (0..exp.variants.len()).map(label).collect();
            return Err(Failure::Input(format!(
                "--scheme {s:?}: the scenario has no such scheme; its schemes are: {}",
                all.join(", ")
            )));
        }
    }
    Ok((0..exp.variants.len())
        .filter(|&v| pacing.schemes.is_empty() || pacing.schemes.iter().any(|s| s == label(v)))
        .collect())
}

fn center_options(pacing: &Pacing, status: bool) -> Result<CenterOptions, Failure> {
    Ok(CenterOptions {
        pace: match pacing.period {
            Some(p) => Pace::Period(seconds("--period", p)?),
            None => Pace::Lockstep {
                timeout: seconds("--timeout", pacing.timeout)?,
            },
        },
        wait_for_nodes: seconds("--wait", pacing.wait)?,
        status,
    })
}

/// The end at short `address` of a secured run's link, from `--key` (`None`: the scenario is
/// not secured). A key file that is missing, malformed or readable by others is refused.
fn secure_end(
    exp: &Experiment,
    run: &LiveRun,
    address: u16,
) -> Result<Option<live::secure::SecureEnd>, Failure> {
    match (&run.key, exp.security.is_secured()) {
        (None, false) => Ok(None),
        (Some(k), false) => Err(Failure::Input(format!(
            "--key {}: the scenario has no [security] level, its frames go unsecured",
            k.display()
        ))),
        (None, true) => Err(Failure::Input(format!(
            "the scenario secures its frames ([security] level = \"{}\"): give the run's key file with --key FILE (`hushfuse keygen FILE --sensors {}` makes one)",
            exp.security.level.name(),
            exp.system.n_sensors()
        ))),
        (Some(k), true) => {
            let keys = live::secure::LiveKeys::load(k, exp.security, exp.system.n_sensors())
                .map_err(Failure::Input)?;
            keys.end(address).map(Some).map_err(Failure::Input)
        }
    }
}

/// `hushfuse keygen`: a fresh network key at `path` and the frame counter files of the center
/// and `sensors` sensors beside it.
pub(crate) fn keygen(path: &Path, sensors: usize) -> Result<(), Failure> {
    live::secure::LiveKeys::create(path, sensors).map_err(Failure::Input)?;
    eprintln!(
        "wrote the key {} (owner-only) and the frame counters of the center and {sensors} sensors beside it ({}.counter-A, A the short address: 0 the center, i + 1 sensor i); copy each node its key and its counter file",
        path.display(),
        path.display()
    );
    Ok(())
}

/// The center on `socket`, writing into `dir` (resumed from its journal with `resume`).
#[allow(clippy::too_many_arguments)]
fn serve(
    exp: &Experiment,
    text: &str,
    run: &LiveRun,
    pacing: &Pacing,
    socket: &UdpSocket,
    dir: &Path,
    resume: bool,
    truth: Option<&[Vector]>,
) -> Result<String, Failure> {
    let fp = live::fingerprint(exp, text, run.trial);
    // Every option checked before the folder is touched.
    let opts = center_options(pacing, true)?;
    let chosen = variants(exp, pacing)?;
    let id = live::RunId::new(exp, text, run.trial, run.loss, &chosen);
    let end = secure_end(exp, run, live::wire::CENTER_ADDRESS)?;
    let mut center = Center::new(exp, run.trial, fp, chosen, end).map_err(Failure::Input)?;
    let folder = if resume {
        LiveFolder::resume(exp, dir, &mut center, &id)
            .map_err(Failure::Input)?
            .0
    } else {
        let hash = output::sha256_hex(format!("{text}\0{:?}\0{}", run.seed, run.trial).as_bytes());
        LiveFolder::create(exp, dir, &hash, &id).map_err(Failure::Input)?
    };
    let mut tally = Tally {
        exp,
        inner: folder,
        truth,
        rows: Vec::new(),
    };
    live::run_center(socket, &mut center, &opts, &mut tally).map_err(Failure::Run)?;
    Ok(tally.table())
}

/// The center's folder, and per scheme what arrived and (with the truth) the errors: the table
/// printed at the end.
struct Tally<'a> {
    exp: &'a Experiment,
    inner: LiveFolder<'a>,
    truth: Option<&'a [Vector]>,
    /// (variant, steps, payload bits arrived, per group the summed error norms: their mean is
    /// the "RMSE" of a one-trial replay, the mean over steps of the per-step RMSE).
    rows: Vec<(usize, usize, u64, Vec<f64>)>,
}

impl live::CenterSink for Tally<'_> {
    fn record(&mut self, center: &Center, r: &live::StepRecord) -> Result<(), String> {
        self.inner.record(center, r)?;
        if self.rows.last().is_none_or(|row| row.0 != r.variant) {
            self.rows
                .push((r.variant, 0, 0, vec![0.0; self.exp.groups.len()]));
        }
        let row = self.rows.last_mut().expect("just pushed");
        row.1 += 1;
        row.2 += r.bits;
        if let Some(x) = self.truth.and_then(|t| t.get(r.k - 1)) {
            for ((_, idx), sq) in self.exp.groups.iter().zip(row.3.iter_mut()) {
                let e2 = idx.iter().map(|&j| (r.estimate.mean[j] - x[j]).powi(2));
                *sq += e2.sum::<f64>().sqrt();
            }
        }
        Ok(())
    }

    fn event(&mut self, text: &str) {
        self.inner.event(text);
    }
}

impl Tally<'_> {
    fn table(&self) -> String {
        let mut header = vec!["scheme".to_string(), "arrived bits/step".to_string()];
        if self.truth.is_some() {
            header.extend(self.exp.groups.iter().map(|(g, _)| format!("RMSE {g}")));
        }
        let rows: Vec<Vec<String>> = self
            .rows
            .iter()
            .map(|(v, steps, bits, sq)| {
                let mut row = vec![
                    self.exp.curves[self.exp.variants[*v].curve].label.clone(),
                    format!("{:.1}", *bits as f64 / (*steps).max(1) as f64),
                ];
                if self.truth.is_some() {
                    row.extend(
                        sq.iter()
                            .map(|s| format!("{:.4}", s / (*steps).max(1) as f64)),
                    );
                }
                row
            })
            .collect();
        let mut all = vec![header];
        all.extend(rows);
        results::text_table(&all, 1)
    }
}

/// `hushfuse center`.
pub(crate) fn center(
    scenario: &str,
    listen: &str,
    run: &LiveRun,
    pacing: &Pacing,
    out: Option<&Path>,
    resume: bool,
) -> Result<(), Failure> {
    let (exp, text) = load(scenario, run, None)?;
    center_options(pacing, true)?;
    variants(&exp, pacing)?;
    secure_end(&exp, run, live::wire::CENTER_ADDRESS)?;
    let socket = UdpSocket::bind(address(listen, "--listen")?)
        .map_err(|e| Failure::Input(format!("--listen {listen}: {e}")))?;
    let dir = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(format!("{}-live", exp.name)));
    eprintln!(
        "center of {} listening on {}, writing {}",
        exp.name,
        socket
            .local_addr()
            .map_err(|e| Failure::Run(e.to_string()))?,
        dir.display()
    );
    let table = serve(&exp, &text, run, pacing, &socket, &dir, resume, None)?;
    print_out(&table);
    Ok(())
}

/// Where a node's readings come from.
pub(crate) enum Source<'a> {
    Simulated,
    Csv(&'a Path),
    Stdin,
}

/// `hushfuse node`.
pub(crate) fn node(
    scenario: &str,
    sensor: usize,
    connect: &str,
    run: &LiveRun,
    source: Source,
    give_up: f64,
) -> Result<(), Failure> {
    let center = address(connect, "--connect")?;
    let (exp, text, readings): (Experiment, String, Box<dyn live::Readings>) = match source {
        Source::Csv(path) => {
            let name = path.display().to_string();
            let csv = std::fs::read_to_string(path)
                .map_err(|e| Failure::Input(format!("{name}: cannot read: {e}")))?;
            let meas = replay::parse_measurements(&csv, &name)
                .map_err(|e| Failure::Input(e.to_string()))?;
            let steps = replay::steps_of(&meas, None).map_err(|e| Failure::Input(e.to_string()))?;
            let (exp, text) = load(scenario, run, Some(steps))?;
            let rec =
                replay::recorded(&exp, &meas, None).map_err(|e| Failure::Input(e.to_string()))?;
            let mine = own_readings(&rec, sensor);
            (exp, text, Box::new(live::Recorded(mine)))
        }
        Source::Simulated => {
            let (exp, text) = load(scenario, run, None)?;
            let data = runner::draw_trial(&exp, run.trial);
            let rec = replay::Recorded::from_trial(&data);
            let mine = own_readings(&rec, sensor);
            (exp, text, Box::new(live::Recorded(mine)))
        }
        Source::Stdin => {
            let (exp, text) = load(scenario, run, None)?;
            let dim = exp.system.sensors.get(sensor).map_or(1, |s| s.meas_dim());
            let lines =
                live::BackgroundLines::spawn(std::io::BufReader::new(std::io::stdin()), dim);
            (exp, text, Box::new(lines))
        }
    };
    let fp = live::fingerprint(&exp, &text, run.trial);
    let end = secure_end(&exp, run, live::wire::sensor_address(sensor))?;
    let mut node = Node::new(&exp, sensor, run.trial, readings, end).map_err(Failure::Input)?;
    let opts = NodeOptions {
        center,
        hello_every: Duration::from_secs(1),
        give_up_after: seconds("--give-up", give_up)?,
    };
    live::run_node(&mut node, fp, &opts).map_err(|e| Failure::Run(format!("sensor {sensor}: {e}")))
}

fn own_readings(rec: &replay::Recorded, sensor: usize) -> Vec<Option<hushfuse::linalg::Vector>> {
    rec.measurements
        .iter()
        .zip(&rec.available)
        .map(|(m, a)| match (m.get(sensor), a.get(sensor)) {
            (Some(z), Some(true)) => Some(z.clone()),
            _ => None,
        })
        .collect()
}

/// `hushfuse channel-proxy`.
pub(crate) fn channel_proxy(
    scenario: &str,
    listen: &str,
    center: &str,
    run: &LiveRun,
) -> Result<(), Failure> {
    let (exp, _) = load(scenario, run, None)?;
    let center = address(center, "--center")?;
    let socket = UdpSocket::bind(address(listen, "--listen")?)
        .map_err(|e| Failure::Input(format!("--listen {listen}: {e}")))?;
    let fates = live::proxy::Fates::new(&exp, run.trial).map_err(Failure::Input)?;
    // The address first, alone on its line: `hushfuse live` reads it.
    println!(
        "{}",
        socket
            .local_addr()
            .map_err(|e| Failure::Run(e.to_string()))?
    );
    use std::io::Write;
    let _ = std::io::stdout().flush();
    live::proxy::run_proxy(&socket, center, fates).map_err(Failure::Run)
}

/// The recording `hushfuse live` replays (`--measurements`, `--truth`) and its steps.
#[allow(clippy::type_complexity)]
fn recorded_tables(
    measurements: Option<&Path>,
    truth: Option<&Path>,
) -> Result<
    (
        Option<(replay::MeasTable, Option<replay::TruthTable>)>,
        Option<usize>,
    ),
    Failure,
> {
    let mut tables = None;
    let data_steps = match measurements {
        Some(p) => {
            let name = p.display().to_string();
            let csv = std::fs::read_to_string(p)
                .map_err(|e| Failure::Input(format!("{name}: cannot read: {e}")))?;
            let meas = replay::parse_measurements(&csv, &name)
                .map_err(|e| Failure::Input(e.to_string()))?;
            let truth_table = match truth {
                Some(t) => {
                    let tname = t.display().to_string();
                    let text = std::fs::read_to_string(t)
                        .map_err(|e| Failure::Input(format!("{tname}: cannot read: {e}")))?;
                    Some(
                        replay::parse_truth(&text, &tname)
                            .map_err(|e| Failure::Input(e.to_string()))?,
                    )
                }
                None => None,
            };
            let steps = replay::steps_of(&meas, truth_table.as_ref())
                .map_err(|e| Failure::Input(e.to_string()))?;
            tables = Some((meas, truth_table));
            Some(steps)
        }
        None if truth.is_some() => {
            return Err(Failure::Input(
                "--truth goes with --measurements (simulated readings have their own truth)".into(),
            ))
        }
        None => None,
    };
    Ok((tables, data_steps))
}

/// `hushfuse live`: the center here, a proxy when the scenario's link loses packets, and one
/// node process per sensor, all on localhost.
pub(crate) fn live_all(
    scenario: &str,
    run: &LiveRun,
    pacing: &Pacing,
    measurements: Option<&Path>,
    truth: Option<&Path>,
    out: Option<&Path>,
) -> Result<(), Failure> {
    let (tables, data_steps) = recorded_tables(measurements, truth)?;
    let run = LiveRun {
        steps: run.steps.or(data_steps),
        ..run.clone()
    };
    let (exp, text) = load(scenario, &run, None)?;
    // Every option checked before a process starts or the folder is touched.
    center_options(pacing, true)?;
    variants(&exp, pacing)?;
    let dir = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("hushfuse-out").join(format!("{}-live", exp.name)));
    let mut run = run;
    if exp.security.is_secured() && run.key.is_none() {
        // A fresh key for this run, in its folder: frames of earlier runs do not verify.
        LiveFolder::refuse_interrupted(&exp, &dir).map_err(Failure::Input)?;
        std::fs::create_dir_all(&dir)
            .map_err(|e| Failure::Run(format!("cannot create {}: {e}", dir.display())))?;
        let key = dir.join(output::LIVE_KEY);
        live::secure::LiveKeys::remove(&key).map_err(Failure::Run)?;
        live::secure::LiveKeys::create(&key, exp.system.n_sensors()).map_err(Failure::Run)?;
        run.key = Some(key);
    }
    secure_end(&exp, &run, live::wire::CENTER_ADDRESS)?;
    let socket = UdpSocket::bind("127.0.0.1:0").map_err(|e| Failure::Run(e.to_string()))?;
    let center_addr = socket
        .local_addr()
        .map_err(|e| Failure::Run(e.to_string()))?;
    let exe = std::env::current_exe().map_err(|e| Failure::Run(e.to_string()))?;
    let common = |cmd: &mut std::process::Command| {
        cmd.arg("--trial").arg(run.trial.to_string());
        cmd.arg("--steps").arg(exp.steps.to_string());
        if let Some(s) = run.seed {
            cmd.arg("--seed").arg(s.to_string());
        }
        if let Some(p) = run.loss {
            cmd.arg("--loss").arg(p.to_string());
        }
        if let Some(k) = &run.key {
            cmd.arg("--key").arg(k);
        }
    };
    let mut children = Children(Vec::new());
    stop_children_on_signal();
    let lossy = exp.variants.iter().any(|v| v.channel.is_some());
    let node_target = if lossy {
        let mut cmd = std::process::Command::new(&exe);
        cmd.args([
            "channel-proxy",
            scenario,
            "--listen",
            "127.0.0.1:0",
            "--center",
        ])
        .arg(center_addr.to_string())
        .stdout(std::process::Stdio::piped());
        common(&mut cmd);
        let mut child = spawn_child(&mut cmd)
            .map_err(|e| Failure::Run(format!("cannot start the channel proxy: {e}")))?;
        let mut line = String::new();
        let stdout = child.stdout.take().expect("piped");
        std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut line)
            .map_err(|e| Failure::Run(format!("the channel proxy: {e}")))?;
        children.0.push(("channel proxy".into(), child));
        address(line.trim(), "the channel proxy's address")?
    } else {
        center_addr
    };
    for i in 0..exp.system.n_sensors() {
        let mut cmd = std::process::Command::new(&exe);
        cmd.args(["node", scenario, "--sensor"])
            .arg(i.to_string())
            .arg("--connect")
            .arg(node_target.to_string());
        common(&mut cmd);
        if let Some(m) = measurements {
            cmd.arg("--measurements").arg(m);
        }
        let child = spawn_child(&mut cmd)
            .map_err(|e| Failure::Run(format!("cannot start node {i}: {e}")))?;
        children.0.push((format!("node {i}"), child));
    }
    eprintln!(
        "live run of {}: center {center_addr}, {} node processes{}, writing {}",
        exp.name,
        exp.system.n_sensors(),
        if lossy {
            " behind the channel proxy"
        } else {
            ""
        },
        dir.display()
    );
    let start = Instant::now();
    // The truth to score the estimates with: the recording's, or the simulated trial's.
    let truth = match &tables {
        Some((meas, truth)) => {
            replay::recorded(&exp, meas, truth.as_ref())
                .map_err(|e| Failure::Input(e.to_string()))?
                .truth
        }
        None => Some(runner::draw_trial(&exp, run.trial).truth),
    };
    let table = serve(
        &exp,
        &text,
        &run,
        pacing,
        &socket,
        &dir,
        false,
        truth.as_deref(),
    )?;
    children.wait()?;
    print_out(&table);
    print_out(&format!(
        "{}: {} schemes x {} steps live in {:.1} s\nwrote {}: {}, {}, {}\n",
        exp.name,
        variants(&exp, pacing)?.len(),
        exp.steps,
        start.elapsed().as_secs_f64(),
        dir.display(),
        live::ESTIMATES,
        live::LOG,
        live::JOURNAL
    ));
    Ok(())
}

/// The process ids of the children `hushfuse live` started, for its signal handler.
static CHILD_PIDS: std::sync::Mutex<Vec<u32>> = std::sync::Mutex::new(Vec::new());

/// Starts a child of `hushfuse live` that cannot outlive it: its id is kept for the Ctrl-C /
/// SIGTERM handler ([`stop_children_on_signal`]), and on Linux the kernel sends it SIGTERM
/// when this process dies in any way (`PR_SET_PDEATHSIG`, for a SIGKILL no handler sees).
fn spawn_child(cmd: &mut std::process::Command) -> std::io::Result<std::process::Child> {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: prctl is async-signal-safe and touches only the child being started.
        unsafe {
            cmd.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    let child = cmd.spawn()?;
    if let Ok(mut pids) = CHILD_PIDS.lock() {
        pids.push(child.id());
    }
    Ok(child)
}

/// On Ctrl-C or SIGTERM: SIGTERM to every child, then exit 130. The center's journal is
/// synced at every step, so what was fused is kept.
fn stop_children_on_signal() {
    let _ = ctrlc::set_handler(|| {
        if let Ok(pids) = CHILD_PIDS.lock() {
            for &pid in pids.iter() {
                if let Ok(pid) = i32::try_from(pid) {
                    // SAFETY: kill(2) on a process id; at worst the child is already gone.
                    unsafe {
                        libc::kill(pid, libc::SIGTERM);
                    }
                }
            }
        }
        eprintln!("stopped: the node processes were ended");
        std::process::exit(130);
    });
}

/// The processes `hushfuse live` started: waited for (nodes end when the center ends the
/// run), killed if the center fails.
struct Children(Vec<(String, std::process::Child)>);

impl Children {
    fn wait(&mut self) -> Result<(), Failure> {
        let mut failed = Vec::new();
        for (name, child) in self.0.drain(..) {
            let mut child = child;
            let deadline = Instant::now() + Duration::from_secs(10);
            let status = loop {
                match child.try_wait() {
                    Ok(Some(s)) => break Some(s),
                    Ok(None) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(20))
                    }
                    _ => {
                        let _ = child.kill();
                        let _ = child.wait();
                        break None;
                    }
                }
            };
            if !status.is_some_and(|s| s.success()) && name != "channel proxy" {
                failed.push(name);
            }
        }
        match failed.is_empty() {
            true => Ok(()),
            false => Err(Failure::Run(format!(
                "{} did not end cleanly",
                failed.join(", ")
            ))),
        }
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        for (_, c) in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}
