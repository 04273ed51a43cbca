//! `hushfuse channel-proxy`: a UDP relay between the nodes and the center that applies a
//! scenario's `[channel]` to the frames, with the fates the simulation draws for the same
//! seed and trial ([`crate::network::channel::FateTable`]): sensor i's frame of step k is
//! dropped when the uplink slot (i, k) is lost, and the feedback of step k (k >= 2) is taken
//! out of sensor i's step announcement when its downlink slot is lost (the sensor keeps the
//! feedback it last heard, as in [`crate::engine::link_layer`]). Every scheme meets the same
//! fates, as in the simulation. Control datagrams pass untouched: they stand for what the MAC
//! of a real network does on its own (beacons, association), not for the estimator's packets.
use super::wire::{self, Datagram, Kind};
use crate::network::channel::FateTable;
use crate::scenario::experiment::Experiment;
use std::collections::HashMap;
use std::net::{SocketAddr, UdpSocket};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A variant's (uplink, downlink) fate tables; `None` for an ideal link.
type Tables = (Option<Arc<FateTable>>, Option<Arc<FateTable>>);

/// The fates of one trial, per variant (variants share the tables of equal links).
pub struct Fates {
    per_variant: Vec<Tables>,
    /// The run's security: a relay reads a sealed datagram's envelope, and alters none.
    security: crate::link::security::SecuritySpec,
    /// The scenario's sensors: the proxy relays for at most a few peers per sensor.
    sensors: usize,
}

/// Peers (node addresses) the proxy relays for, per sensor of the scenario, beyond
/// [`EXTRA_PEERS`]: room for restarted nodes, never a socket and a thread per junk sender.
const PEERS_PER_SENSOR: usize = 4;
/// Peers beyond [`PEERS_PER_SENSOR`] per sensor.
const EXTRA_PEERS: usize = 16;

impl Fates {
    pub fn new(exp: &Experiment, trial: usize) -> Result<Self, String> {
        super::check_live(exp)?;
        let mut drawn: Vec<(usize, Arc<FateTable>, Option<Arc<FateTable>>)> = Vec::new();
        let mut per_variant = Vec::with_capacity(exp.variants.len());
        for (v, var) in exp.variants.iter().enumerate() {
            let Some(specs) = var.channel.as_deref() else {
                per_variant.push((None, None));
                continue;
            };
            let same = drawn
                .iter()
                .find(|(w, _, _)| exp.variants[*w].channel.as_deref() == Some(specs));
            let (up, down) = match same {
                Some((_, up, down)) => (up.clone(), down.clone()),
                None => {
                    let draw = |down| {
                        Arc::new(FateTable::draw(
                            specs,
                            exp.steps,
                            exp.seed,
                            trial as u64,
                            down,
                        ))
                    };
                    let lossy_down = !specs.iter().all(|s| s.downlink_spec().is_lossless());
                    let up = draw(false);
                    let down = lossy_down.then(|| draw(true));
                    drawn.push((v, up.clone(), down.clone()));
                    (up, down)
                }
            };
            per_variant.push((Some(up), down));
        }
        Ok(Self {
            per_variant,
            security: exp.security,
            sensors: exp.system.n_sensors(),
        })
    }

    /// The datagram in `octets`, and whether it came sealed (its envelope read, not verified:
    /// the receiver does that).
    fn read(&self, octets: &[u8]) -> Option<(Datagram, bool)> {
        match Datagram::decode(octets) {
            Ok(d) => Some((d, false)),
            Err(_) if self.security.is_secured() => {
                Datagram::decode(super::secure::unsealed_part(octets, &self.security))
                    .ok()
                    .map(|d| (d, true))
            }
            Err(_) => None,
        }
    }

    /// The datagram as the link lets it through (`None`: lost).
    pub fn apply(&self, octets: &[u8]) -> Option<Vec<u8>> {
        let Some((mut d, sealed)) = self.read(octets) else {
            // Not ours to judge: the receiver counts it.
            return Some(octets.to_vec());
        };
        let (i, v, k) = (
            usize::from(d.sensor),
            usize::from(d.variant),
            d.step as usize,
        );
        let Some((up, down)) = self.per_variant.get(v) else {
            return Some(octets.to_vec());
        };
        let in_table = |t: &FateTable| i < t.sensors() && (1..=t.steps()).contains(&k);
        match d.kind {
            Kind::Frame => match up {
                Some(t) if in_table(t) && t.get(i, k).lost => None,
                _ => Some(octets.to_vec()),
            },
            // A sealed announcement is never altered (`check_live` refuses lost feedback when
            // the feedback is secured).
            Kind::Step if !sealed && d.flags & wire::STEP_CATCH_UP == 0 && k >= 2 => match down {
                Some(t) if in_table(t) && t.get(i, k).lost => {
                    d.flags &=
                        !(wire::STEP_PREDICTION | wire::STEP_PREDICTION_COV | wire::STEP_REFERENCE);
                    d.body.clear();
                    Some(d.encode())
                }
                _ => Some(octets.to_vec()),
            },
            _ => Some(octets.to_vec()),
        }
    }
}

/// Relays datagrams between nodes (who send to `listen`) and the center at `center`, through
/// `fates`, until the center ends the run. Each node gets a socket of its own towards the
/// center, so the center sees one address per node.
pub fn run_proxy(listen: &UdpSocket, center: SocketAddr, fates: Fates) -> Result<(), String> {
    let fates = Arc::new(fates);
    let upstream: Arc<Mutex<HashMap<SocketAddr, Arc<UdpSocket>>>> = Arc::default();
    let ended = Arc::new(std::sync::atomic::AtomicBool::new(false));
    listen
        .set_read_timeout(Some(Duration::from_millis(200)))
        .map_err(|e| e.to_string())?;
    let mut buf = [0u8; 2048];
    let mut quiet = 0u32;
    loop {
        let (len, node) = match listen.recv_from(&mut buf) {
            Ok(x) => x,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                if ended.load(std::sync::atomic::Ordering::Relaxed) {
                    quiet += 1;
                    if quiet > 10 {
                        return Ok(());
                    }
                }
                continue;
            }
            Err(e) => return Err(format!("cannot receive: {e}")),
        };
        let sock = {
            let mut map = upstream.lock().expect("no panic holds it");
            match map.get(&node) {
                Some(s) => s.clone(),
                // A new peer only for a datagram of ours from one of the scenario's sensors, and
                // only while the table has room: junk from many ports opens nothing.
                None if fates
                    .read(&buf[..len])
                    .is_none_or(|(d, _)| usize::from(d.sensor) >= fates.sensors)
                    || map.len() >= PEERS_PER_SENSOR * fates.sensors + EXTRA_PEERS =>
                {
                    continue
                }
                None => {
                    let bind = if center.is_ipv4() {
                        "0.0.0.0:0"
                    } else {
                        "[::]:0"
                    };
                    let s = Arc::new(
                        UdpSocket::bind(bind).map_err(|e| format!("cannot open a socket: {e}"))?,
                    );
                    map.insert(node, s.clone());
                    let (s2, back, fates, ended) = (
                        s.clone(),
                        listen.try_clone().map_err(|e| e.to_string())?,
                        fates.clone(),
                        ended.clone(),
                    );
                    let spawned = std::thread::Builder::new()
                        .spawn(move || downstream(&s2, &back, node, &fates, &ended));
                    if spawned.is_err() {
                        // No thread to be had: this peer is not relayed (as if lost).
                        map.remove(&node);
                        continue;
                    }
                    s
                }
            }
        };
        if let Some(out) = fates.apply(&buf[..len]) {
            let _ = sock.send_to(&out, center);
        }
    }
}

/// Center -> node, through the downlink's fates.
fn downstream(
    from_center: &UdpSocket,
    to_nodes: &UdpSocket,
    node: SocketAddr,
    fates: &Fates,
    ended: &std::sync::atomic::AtomicBool,
) {
    let mut buf = [0u8; 2048];
    while let Ok((len, _)) = from_center.recv_from(&mut buf) {
        if fates
            .read(&buf[..len])
            .is_some_and(|(d, _)| d.kind == Kind::End)
        {
            ended.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        if let Some(out) = fates.apply(&buf[..len]) {
            let _ = to_nodes.send_to(&out, node);
        }
    }
}
