//! Scenario file -> validated experiment. Every check names the file, the field and what was
//! expected, so a user can fix a file without reading Rust. The pieces live in their own files:
//! [`crate::scenario::system`] (model, prior, sensors, groups), [`crate::scenario::sweep`] (sweep expansion),
//! [`crate::scenario::schemes`] (schemes through the registry), [`crate::scenario::paper_check`] (the `[paper]`
//! section) and [`crate::scenario::limits`] (what the run would ask of the machine).
use crate::filter::Gaussian;
use crate::network::channel::ChannelSpec;
use crate::network::radio::RadioSpec;
use crate::scenario::limits::{self, Limits};
use crate::scenario::ScenarioFile;
use crate::scheme::System;
use std::sync::Arc;

pub(crate) use crate::scenario::error::Ctx;
pub use crate::scenario::error::ScenarioError;
pub use crate::scenario::experiment::{Curve, Experiment, Variant};

/// What a caller may change about a scenario as it is loaded.
#[derive(Debug, Clone, Copy, Default)]
pub struct LoadOptions {
    /// Replaces the file's `trials` (`--trials`).
    pub trials: Option<usize>,
    /// Replaces the file's `seed` (`--seed`).
    pub seed: Option<u64>,
    /// Worker threads the run will use (0: one per core), for the memory estimate.
    pub threads: usize,
    /// `None`: the default limits.
    pub limits: Option<Limits>,
    /// Build the system, its data and its links only, no scheme (`variants` and `curves`
    /// empty): what drawing a trial's truth and readings needs, so that it is neither refused
    /// for nor made to compute the schemes' memory (Python's `simulate`). The memory estimate
    /// is then one trial's data on one thread.
    pub data_only: bool,
}

/// Most steps per trial: every step is stored per variant, and data-independent recursions
/// are precomputed this far.
pub const MAX_STEPS: usize = 10_000_000;

/// Which kind of file a text is, told by its structure: a table report has a top-level
/// `report` key and no `schemes`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    Scenario,
    TableReport,
}

/// Tells a scenario from a table report by its keys (not by searching the text).
pub fn file_kind(text: &str, file: &str) -> Result<FileKind, ScenarioError> {
    let table: toml::Table = toml::from_str(text).map_err(|e| toml_error(text, file, &e, ""))?;
    Ok(
        if table.contains_key("report") && !table.contains_key("schemes") {
            FileKind::TableReport
        } else {
            FileKind::Scenario
        },
    )
}

/// A parse error, with the field path serde saw, the key it names and the line.
fn toml_error(text: &str, file: &str, e: &toml::de::Error, path: &str) -> ScenarioError {
    let message = e.message().to_string();
    let key = ["unknown field `", "missing field `"].iter().find_map(|p| {
        let rest = &message[message.find(p)? + p.len()..];
        Some(rest[..rest.find('`')?].to_string())
    });
    let path = if path == "." || path == "?" { "" } else { path };
    let mut field = match (path.is_empty(), key) {
        (true, Some(k)) => k,
        (false, Some(k)) if !path.ends_with(&k) => format!("{path}.{k}"),
        _ => path.to_string(),
    };
    if let Some(span) = e.span() {
        let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
        field = if field.is_empty() {
            format!("line {line}")
        } else {
            format!("{field} (line {line})")
        };
    }
    ScenarioError {
        file: file.to_string(),
        field,
        message,
        limit: None,
    }
}

/// Largest magnitude of a finite number in a scenario: squared errors and covariance products
/// of larger numbers overflow double precision (infinities are allowed where a field says so,
/// e.g. a censoring threshold).
pub const MAX_MAGNITUDE: f64 = 1e100;

/// Refuses finite numbers beyond [`MAX_MAGNITUDE`] anywhere in the file, naming the key.
fn check_magnitudes(value: &toml::Value, path: &str, file: &str) -> Result<(), ScenarioError> {
    let bad = |x: f64| x.is_finite() && x.abs() > MAX_MAGNITUDE;
    match value {
        toml::Value::Float(x) if bad(*x) => Err(ScenarioError {
            file: file.to_string(),
            field: path.to_string(),
            message: format!(
                "{x:e} is too large: numbers must stay within ±{MAX_MAGNITUDE:e} so that squared errors stay finite; rescale the units"
            ),
            limit: None,
        }),
        toml::Value::Table(t) => t.iter().try_for_each(|(k, v)| {
            let p = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            check_magnitudes(v, &p, file)
        }),
        toml::Value::Array(a) => a
            .iter()
            .enumerate()
            .try_for_each(|(i, v)| check_magnitudes(v, &format!("{path}[{i}]"), file)),
        _ => Ok(()),
    }
}

/// Parses TOML text into the file structure.
pub fn parse(text: &str, file: &str) -> Result<ScenarioFile, ScenarioError> {
    let raw: toml::Table = toml::from_str(text).map_err(|e| toml_error(text, file, &e, ""))?;
    check_magnitudes(&toml::Value::Table(raw), "", file)?;
    let de = toml::Deserializer::new(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        toml_error(text, file, e.inner(), &path)
    })
}

/// Turns an `every_scheme` scenario into the plain one it stands for: `schemes` gets every
/// applicable registry kind ([`crate::scenario::every_scheme`]) and the flag is cleared.
/// Calibration uses it to set knobs on an explicit list.
pub fn expand_every_scheme(spec: &mut ScenarioFile, file: &str) -> Result<(), ScenarioError> {
    if spec.every_scheme {
        let ctx = Ctx { file };
        let parts = crate::scenario::system::build_system(&ctx, spec)?;
        spec.schemes = crate::scenario::every_scheme::expand(&ctx, &spec.schemes, &parts.system)?;
        spec.every_scheme = false;
    }
    Ok(())
}

/// Parses and validates a scenario with the default limits.
pub fn load(text: &str, file: &str) -> Result<Experiment, ScenarioError> {
    load_with(text, file, &LoadOptions::default())
}

/// Parses and validates a scenario.
pub fn load_with(text: &str, file: &str, opts: &LoadOptions) -> Result<Experiment, ScenarioError> {
    let mut parsed = parse(text, file)?;
    if let Some(t) = opts.trials {
        parsed.trials = t;
    }
    if let Some(s) = opts.seed {
        parsed.seed = s;
    }
    build_with(parsed, file, opts)
}

/// Validates every field and builds the runtime objects (default limits).
pub fn build(file_spec: ScenarioFile, file: &str) -> Result<Experiment, ScenarioError> {
    build_with(file_spec, file, &LoadOptions::default())
}

/// An output folder name: one path component of letters, digits, `-`, `_` and `.`, not `.` or
/// `..` (`--out` writes anywhere).
pub fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty()
        || name == "."
        || name == ".."
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
    {
        return Err(format!(
            "expected a folder name of letters, digits, '-', '_' and '.' (no path separators, not \"..\"), got {name:?}; use --out to write elsewhere"
        ));
    }
    Ok(())
}

fn threads(opts: &LoadOptions) -> usize {
    if opts.threads > 0 {
        opts.threads
    } else {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    }
}

/// Validates every field and builds the runtime objects.
pub fn build_with(
    mut file_spec: ScenarioFile,
    file: &str,
    opts: &LoadOptions,
) -> Result<Experiment, ScenarioError> {
    let ctx = Ctx { file };
    let limits = opts.limits.unwrap_or_default();
    check_name(&file_spec.name).map_err(|m| ctx.err("name", m))?;
    if file_spec.trials == 0 {
        return Err(ctx.err("trials", "expected at least 1 trial"));
    }
    if file_spec.steps == 0 {
        return Err(ctx.err("steps", "expected at least 1 step"));
    }
    if file_spec.steps > MAX_STEPS {
        return Err(ctx.err(
            "steps",
            format!("at most {MAX_STEPS} steps, got {}", file_spec.steps),
        ));
    }
    let steady_from = file_spec
        .steady_state_from
        .unwrap_or(file_spec.steps / 2 + 1);
    if steady_from == 0 || steady_from > file_spec.steps {
        return Err(ctx.err(
            "steady_state_from",
            format!(
                "expected a step in 1..={}, got {steady_from}",
                file_spec.steps
            ),
        ));
    }
    let parts = crate::scenario::system::build_system(&ctx, &file_spec)?;
    let system = Arc::new(parts.system);
    let channel = crate::scenario::channel::build_channel(&ctx, &file_spec, system.n_sensors())?;
    let network = build_network(&ctx, &file_spec, system.n_sensors(), system.state_dim())?;
    let path_loss: Option<Vec<f64>> = network
        .as_ref()
        .map(|t| (0..system.n_sensors()).map(|i| t.path_loss(i)).collect());
    let radio = file_spec.radio.unwrap_or_default();
    radio
        .validate()
        .map_err(|e| ctx.err(format!("radio.{}", e.key), e.message))?;
    if file_spec.every_scheme {
        file_spec.schemes =
            crate::scenario::every_scheme::expand(&ctx, &file_spec.schemes, &system)?;
    }

    let link = (channel, radio, network);
    if opts.data_only {
        let data = limits::baseline(&system, parts.groups.len(), 0, 1, file_spec.steps, 1);
        limits::check(&data, &limits, file)?;
        let built = (system, parts.initial_truth, parts.groups, steady_from);
        return Ok(assemble(
            file_spec,
            file,
            built,
            (Vec::new(), Vec::new()),
            link,
        ));
    }
    // What the run needs before any scheme precomputes anything for `steps`.
    let workers = threads(opts);
    let entries = file_spec.schemes.len().max(1);
    // Any entry may build a per-step plan for `steps` steps as it is built.
    let before = limits::with_plans(
        limits::baseline(
            &system,
            parts.groups.len(),
            entries,
            file_spec.trials,
            file_spec.steps,
            workers,
        ),
        &system,
        entries,
        file_spec.steps,
    );
    limits::check(&before, &limits, file)?;

    let (curves, variants) = crate::scenario::schemes::build_schemes(
        &ctx,
        &file_spec.schemes,
        &system,
        file_spec.steps,
        (
            &link.0.clone().map(std::sync::Arc::new),
            path_loss.as_deref(),
        ),
    )?;
    check_decentralized(
        &ctx,
        link.2.as_deref(),
        &curves,
        &variants,
        (system.n_sensors(), file_spec.security.unwrap_or_default()),
    )?;
    if let Some(security) = &file_spec.security {
        check_security(security, &system).map_err(|m| ctx.err("security.level", m))?;
    }
    if link.2.is_some() {
        check_network_variants(&ctx, &link.0, &curves, &variants, file_spec.reals)?;
        check_aggregation(&ctx, link.2.as_deref(), &curves, &variants)?;
    }
    let estimate = limits::with_schemes(
        limits::baseline(
            &system,
            parts.groups.len(),
            variants.len(),
            file_spec.trials,
            file_spec.steps,
            workers,
        ),
        variants.iter().map(|v| v.scheme.as_ref()),
        file_spec.trials,
        file_spec.steps,
        workers,
    );
    let with_plan = variants
        .iter()
        .filter(|v| v.scheme.keeps_step_plan())
        .count();
    let estimate = limits::with_plans(estimate, &system, with_plan, file_spec.steps);
    let estimate = limits::with_refusion(
        estimate,
        &system,
        &variants,
        file_spec.trials,
        file_spec.steps,
        workers,
    );
    limits::check(&estimate, &limits, file)?;
    check_reals(&ctx, file_spec.reals, &curves, &variants)?;
    if let Some(paper) = &file_spec.paper {
        crate::scenario::paper_check::check(
            &ctx,
            paper,
            &curves,
            &variants,
            &parts.groups,
            &system,
        )?;
    }

    let built = (system, parts.initial_truth, parts.groups, steady_from);
    Ok(assemble(file_spec, file, built, (curves, variants), link))
}

/// Builds `[network]` ([`crate::network::topology`]): every bad topology is refused by field
/// and node. `None` without `[network]`, and for the one-hop star without links of its own
/// (today's network, run exactly as without the table). A sensor's own `channel` is refused
/// with a network: its links are `[[network.links]]`. `broadcast_estimate` needs a sink and an
/// estimate of an `n`-dimensional state that fits one frame.
fn build_network(
    ctx: &Ctx,
    file: &ScenarioFile,
    sensors: usize,
    n: usize,
) -> Result<Option<Arc<crate::network::topology::Topology>>, ScenarioError> {
    use crate::network::topology::Topology;
    let Some(spec) = &file.network else {
        return Ok(None);
    };
    // Sensors in the system's order: the file's, then each field's at its placement.
    let mut positions: Vec<Option<[f64; 2]>> = file.sensors.iter().map(|s| s.position).collect();
    for (j, field) in file.sensor_fields.iter().enumerate() {
        let placed = crate::scenario::system::sensor_field(ctx, j, field)?;
        positions.extend(placed.iter().map(|s| s.position));
    }
    positions.resize(sensors, None);
    let mut topology = Topology::build(spec, &positions, file.channel.as_ref())
        .map_err(|e| ctx.err(format!("network.{}", e.field), e.message))?;
    topology.security = file.security.unwrap_or_default();
    if topology.broadcast_estimate {
        check_broadcast_estimate(&topology, n)
            .map_err(|m| ctx.err("network.broadcast_estimate", m))?;
    }
    // A star that sends its estimate back keeps its network: the star's own loop prices no
    // estimate going down.
    if topology.is_star() && spec.links.is_empty() && !topology.broadcast_estimate {
        return Ok(None);
    }
    if let Some(i) = file.sensors.iter().position(|s| s.channel.is_some()) {
        return Err(ctx.err(
            format!("sensors[{i}].channel"),
            format!(
                "with a [network], a link's channel is given in [[network.links]] (between = [\"s{i}\", \"{}\"]), not by the sensor",
                topology
                    .parent[i]
                    .or(topology.sink())
                    .or(topology.neighbours(i).first().copied())
                    .map_or("…", |n| topology.nodes[n].name.as_str())
            ),
        ));
    }
    Ok(Some(Arc::new(topology)))
}

/// The sink's estimate must have a sink to come from and fit one 802.15.4 frame: its mean and
/// covariance (upper triangle) as singles, `n + n(n+1)/2` of them, at most 116 octets.
fn check_broadcast_estimate(
    net: &crate::network::topology::Topology,
    n: usize,
) -> Result<(), String> {
    net.sink_for("sending the estimate down the tree")?;
    let octets = 4 * crate::network::estimate_reals(n);
    let max = crate::link::codec802154::MAX_PAYLOAD_OCTETS - net.security.overhead_octets();
    if octets > max as u64 {
        return Err(format!(
            "the estimate of a {n}-dimensional state is {octets} octets as singles (mean and covariance), more than the {max} a frame carries{}",
            if net.security.is_secured() { " once secured" } else { "" }
        ));
    }
    Ok(())
}

/// `[security]` is priced on every frame: on the one-hop star by the step's traffic
/// (`Traffic::secure`), on a graph per hop and per node (`Tally`). A secured frame must still
/// fit 127 octets: the largest reading, and an estimate of the state (mean and covariance, which
/// estimate-sending schemes and the prediction feedback carry), in what the MIC and auxiliary
/// header leave of the 116 octets of payload (conservative: checked whatever the schemes send;
/// the decentralized schemes' own messages are checked by `Peers::check`).
fn check_security(
    security: &crate::link::security::SecuritySpec,
    system: &crate::scheme::System,
) -> Result<(), String> {
    if !security.is_secured() {
        return Ok(());
    }
    let level = security.level.name();
    let room = crate::link::codec802154::MAX_PAYLOAD_OCTETS - security.overhead_octets();
    let reading = system
        .sensors
        .iter()
        .map(|s| s.meas_dim())
        .max()
        .unwrap_or(0)
        * 4;
    let estimate = 4 * crate::network::estimate_reals(system.state_dim()) as usize;
    let largest = reading.max(estimate);
    if largest > room {
        return Err(format!(
            "a secured frame at level \"{level}\" carries at most {room} octets of payload \
             (116 less {} of auxiliary header and MIC); this system's largest message is {largest} \
             octets (a reading, or the state's estimate with its covariance as singles)",
            security.overhead_octets()
        ));
    }
    Ok(())
}

/// A network of peers (`sink = false`) runs only decentralized schemes (a center scheme needs
/// its sink); a decentralized scheme must fit the graph it runs on (weights given by hand, the
/// channel filter's tree), which is the network or, without one, the star.
fn check_decentralized(
    ctx: &Ctx,
    network: Option<&crate::network::topology::Topology>,
    curves: &[crate::scenario::experiment::Curve],
    variants: &[crate::scenario::experiment::Variant],
    (sensors, security): (usize, crate::link::security::SecuritySpec),
) -> Result<(), ScenarioError> {
    for v in variants {
        let label = &curves[v.curve].label;
        let field = format!("schemes[{}]", v.curve);
        match (v.scheme.peers(), network) {
            (None, Some(net)) if net.sink().is_none() => {
                return Err(ctx.err(
                    "network.sink",
                    format!(
                        "scheme {label} fuses at a sink, and this network has none (sink = false): a network of peers runs the decentralized schemes (`hushfuse list-schemes`)"
                    ),
                ))
            }
            (Some(peers), Some(net)) => peers
                .check(net)
                .map_err(|m| ctx.err(&field, format!("{label}: {m}")))?,
            (Some(peers), None) => peers
                .check(&{
                    let mut star = v.star(sensors);
                    star.security = security;
                    star
                })
                .map_err(|m| ctx.err(&field, format!("{label}: {m}")))?,
            _ => {}
        }
    }
    Ok(())
}

/// With a multi-hop `[network]` every hop's channel comes from the network, so a scheme entry
/// may not bring its own (`channel`, a sweep of channel keys, `--loss`), and reals are singles
/// (the doubles' extra bits are not priced per hop).
fn check_network_variants(
    ctx: &Ctx,
    channel: &Option<Vec<ChannelSpec>>,
    curves: &[crate::scenario::experiment::Curve],
    variants: &[crate::scenario::experiment::Variant],
    reals: crate::link::Reals,
) -> Result<(), ScenarioError> {
    if !reals.is_f32() {
        return Err(ctx.err(
            "reals",
            "\"f64\" is not supported with a multi-hop [network] yet (the extra bits are not priced per hop)",
        ));
    }
    for v in variants {
        if v.channel.as_deref() != channel.as_ref() {
            return Err(ctx.err(
                "network",
                format!(
                    "scheme {} brings its own channel (a `channel` key, a swept channel key or --loss); with a multi-hop [network] every hop's channel is the network's: give it in [channel] or [[network.links]]",
                    curves[v.curve].label
                ),
            ));
        }
    }
    Ok(())
}

/// The schemes whose relays sum information ([`crate::network::aggregate`]) need links that
/// deliver within the step (a relay cannot wait for a late child's frame) and no sequence
/// numbers (a sum has no single source to number).
fn check_aggregation(
    ctx: &Ctx,
    network: Option<&crate::network::topology::Topology>,
    curves: &[crate::scenario::experiment::Curve],
    variants: &[crate::scenario::experiment::Variant],
) -> Result<(), ScenarioError> {
    let Some(net) = network else { return Ok(()) };
    for v in variants.iter().filter(|v| v.aggregated(Some(net))) {
        let label = &curves[v.curve].label;
        if let Some(l) = net.links.iter().find(|l| !l.channel.delay().is_zero()) {
            return Err(ctx.err(
                "network.aggregate",
                format!(
                    "scheme {label} is summed by the relays, and the link {} – {} delays frames (a relay cannot wait for a late child's frame); set network.aggregate = false to forward its reports per source",
                    net.nodes[l.a].name, net.nodes[l.b].name
                ),
            ));
        }
        if v.sequence_bits > 0 {
            return Err(ctx.err(
                "network.aggregate",
                format!(
                    "scheme {label} has sequence_bits and is summed by the relays (a sum has no single source to number); set network.aggregate = false to forward its reports per source"
                ),
            ));
        }
    }
    Ok(())
}

/// Named state-component groups, as [`Experiment::groups`].
type Groups = Vec<(String, Vec<usize>)>;

/// The experiment of a checked scenario: its system (with the initial truth, the groups and
/// the first steady-state step), schemes and link.
fn assemble(
    file_spec: ScenarioFile,
    file: &str,
    (system, initial_truth, groups, steady_from): (Arc<System>, Gaussian, Groups, usize),
    (curves, variants): (Vec<Curve>, Vec<Variant>),
    (channel, radio, network): (
        Option<Vec<ChannelSpec>>,
        RadioSpec,
        Option<Arc<crate::network::topology::Topology>>,
    ),
) -> Experiment {
    Experiment {
        name: file_spec.name,
        description: file_spec.description,
        source: file.to_string(),
        system,
        initial_truth,
        groups,
        curves,
        variants,
        trials: file_spec.trials,
        steps: file_spec.steps,
        seed: file_spec.seed,
        steady_from,
        paper: file_spec.paper,
        channel,
        radio,
        network,
        reals: file_spec.reals,
        security: file_spec.security.unwrap_or_default(),
    }
}

/// `reals = "f64"` is carried by the engine's generic loop on links that deliver at once:
/// refused with sequence numbers, delays and retransmissions (whose packets the loop keeps
/// as they were priced, singles).
fn check_reals(
    ctx: &crate::scenario::error::Ctx,
    reals: crate::link::Reals,
    curves: &[crate::scenario::experiment::Curve],
    variants: &[crate::scenario::experiment::Variant],
) -> Result<(), ScenarioError> {
    if reals.is_f32() {
        return Ok(());
    }
    for v in variants {
        let delays = v.channel.as_deref().is_some_and(|specs| {
            specs
                .iter()
                .any(|s| !s.delay().is_zero() || s.arq.is_some())
        });
        if v.sequence_bits > 0 || delays {
            return Err(ctx.err(
                "reals",
                format!(
                    "\"f64\" is not supported with sequence numbers, delays or retransmissions (scheme {})",
                    curves[v.curve].label
                ),
            ));
        }
    }
    Ok(())
}
