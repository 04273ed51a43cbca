//! The sensor side of a live run embedded in your own program (docs/live.md, "Embedding").
//!
//! Sensor 0 of arena-1d reads its position measurements from `my_sensor` (here a made-up
//! target at 1 m/s plus a fixed ripple; on a device, the ADC), runs the scheme's sensor side,
//! and sends real 802.15.4 frames to a center over UDP. To keep the example self-contained it
//! starts the center and the three other sensors itself, in threads; on a deployment the
//! center is `hushfuse center arena-1d --listen 0.0.0.0:7000 --scheme Send-on-delta` and
//! each device runs only `main`'s node part.
//!
//! Run: `cargo run --release --example embed_node`.
use hushfuse::engine::{replay, runner};
use hushfuse::linalg::Vector;
use hushfuse::live::{self, Center, CenterOptions, LiveFolder, Node, NodeOptions, Pace};
use std::net::UdpSocket;
use std::time::Duration;

/// This device's readings: one per step, `None` when the sensor has none.
struct MySensor;

impl live::Readings for MySensor {
    fn reading(&mut self, k: usize) -> Result<Option<Vector>, String> {
        let position = k as f64 + 0.3 * (k as f64 / 5.0).sin();
        Ok(Some(Vector::from_vec(vec![position])))
    }
}

fn main() -> Result<(), String> {
    let (text, source) = hushfuse::scenario::builtin::resolve("arena-1d", false)?;
    let (exp, _) = replay::load_experiment(&text, &source, 50, None, &Default::default())
        .map_err(|e| e.to_string())?;
    let fingerprint = live::fingerprint(&exp, &text, 0);
    let socket = UdpSocket::bind("127.0.0.1:0").map_err(|e| e.to_string())?;
    let center_addr = socket.local_addr().map_err(|e| e.to_string())?;
    let send_on_delta: Vec<usize> = (0..exp.variants.len())
        .filter(|&v| exp.curves[exp.variants[v].curve].label == "Send-on-delta")
        .collect();
    // What the journal's first line names: a resumed center must be this run.
    let run = live::RunId::new(&exp, &text, 0, None, &send_on_delta);
    let out = std::env::temp_dir().join("hushfuse-embed-node");
    std::thread::scope(|s| {
        s.spawn(|| -> Result<(), String> {
            let mut center = Center::new(&exp, 0, fingerprint, send_on_delta, None)?;
            let mut folder = LiveFolder::create(&exp, &out, "example", &run)?;
            let opts = CenterOptions {
                pace: Pace::Lockstep {
                    timeout: Duration::from_secs(5),
                },
                wait_for_nodes: Duration::from_secs(10),
                status: false,
            };
            live::run_center(&socket, &mut center, &opts, &mut folder)
        });
        // The other three sensors: trial 0's simulated readings.
        let data = runner::draw_trial(&exp, 0);
        for i in 1..4 {
            let readings: Vec<Option<Vector>> = data
                .measurements
                .iter()
                .map(|z| Some(z[i].clone()))
                .collect();
            let (exp, center_addr) = (&exp, center_addr);
            s.spawn(move || -> Result<(), String> {
                let mut node = Node::new(exp, i, 0, Box::new(live::Recorded(readings)), None)?;
                live::run_node(&mut node, fingerprint, &NodeOptions::to(center_addr))
            });
        }
        // The part a device runs: its sensor, its readings, the center's address.
        let mut node = Node::new(&exp, 0, 0, Box::new(MySensor), None)?;
        live::run_node(&mut node, fingerprint, &NodeOptions::to(center_addr))
    })?;
    println!("estimates: {}", out.join(live::ESTIMATES).display());
    Ok(())
}
