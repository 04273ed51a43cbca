//! The driver's surfaces the star does not use (the star's are `tests/graph_driver.rs`, against
//! the engine): broadcast pricing by hand, lateral fates and the m-th message's own coins against
//! their binomial intervals, delays, and the errors that name the nodes.
use super::driver::GraphDriver;
use super::{Address, Envelope, NetworkNode, Outbox, Payload, Round};
use crate::linalg::Vector;
use crate::network::channel::ChannelSpec;
use crate::network::radio::PHY_OVERHEAD_BITS;
use crate::network::topology::spec::NetworkSpec;
use crate::network::topology::Topology;
use std::cell::RefCell;
use std::rc::Rc;

#[derive(Debug, Clone, PartialEq)]
struct Bytes(u64);

impl Payload for Bytes {
    fn mac_bits(&self) -> u64 {
        8 * self.0
    }
}

/// What a node heard: (step, round, message).
type Log = Rc<RefCell<Vec<(usize, usize, Envelope<Bytes>)>>>;

/// What a test node does: send `sends` in round `round` of every step, keep what arrives.
struct Scripted {
    round: usize,
    sends: Vec<(Address, u64)>,
    windows: u64,
    got: Log,
}

impl NetworkNode<Bytes> for Scripted {
    fn round(
        &mut self,
        at: Round,
        inbox: &[Envelope<Bytes>],
        out: &mut Outbox<Bytes>,
    ) -> Result<(), String> {
        for e in inbox {
            self.got.borrow_mut().push((at.k, at.round, e.clone()));
        }
        if at.round == self.round {
            for &(to, octets) in &self.sends {
                out.send(to, Bytes(octets));
            }
        }
        Ok(())
    }

    fn windows(&self, _k: usize) -> u64 {
        self.windows
    }
}

fn net(text: &str, sensors: usize, channel: &str) -> Topology {
    let spec: NetworkSpec = toml::from_str(text).unwrap();
    let c: ChannelSpec = toml::from_str(channel).unwrap();
    Topology::build(&spec, &vec![None; sensors], Some(&c)).unwrap()
}

/// One scripted node per node of `t`, node `n` sending `sends(n)` in round 0; their logs.
type Nodes = Vec<Box<dyn NetworkNode<Bytes>>>;

fn scripted(t: &Topology, sends: impl Fn(usize) -> Vec<(Address, u64)>) -> (Nodes, Vec<Log>) {
    let logs: Vec<Log> = (0..t.nodes.len()).map(|_| Log::default()).collect();
    let nodes = (0..t.nodes.len())
        .map(|n| {
            Box::new(Scripted {
                round: 0,
                sends: sends(n),
                windows: n as u64,
                got: logs[n].clone(),
            }) as Box<dyn NetworkNode<Bytes>>
        })
        .collect();
    (nodes, logs)
}

fn step(d: &mut GraphDriver<Bytes>, k: usize, nodes: &mut Nodes, sensors: usize) {
    let z = Vector::zeros(1);
    let readings = vec![Some(&z); sensors];
    d.step(k, nodes, &readings).unwrap();
}

#[test]
fn a_broadcast_is_one_frame_heard_by_every_neighbour() {
    // A triangle s0 – s1 – s2 – s0 plus the sink on s2 (ideal links): s0 broadcasts 25 octets.
    let t = net(
        "edges = [[\"s0\", \"s1\"], [\"s1\", \"s2\"], [\"s2\", \"s0\"], [\"s2\", \"sink\"]]",
        3,
        "kind = \"ideal\"",
    );
    let (mut nodes, logs) = scripted(&t, |n| {
        if n == 0 {
            vec![(Address::Neighbours, 25)]
        } else {
            vec![]
        }
    });
    let mut d = GraphDriver::new(&t, 2, 1, 7, 0);
    step(&mut d, 1, &mut nodes, 3);
    let ppdu = 200 + PHY_OVERHEAD_BITS;
    let c = d.counts();
    // frames_sent, frame_bits_sent, frames_received, frame_bits_received; listens last.
    assert_eq!(c[0][..4], [1, ppdu, 0, 0]);
    assert_eq!(c[1][..4], [0, 0, 1, ppdu]);
    assert_eq!(c[2][..4], [0, 0, 1, ppdu]);
    assert_eq!(c[3][..4], [0; 4]);
    // Each node's declared windows (here its index) are its listening.
    assert_eq!(c.iter().map(|x| x[11]).collect::<Vec<_>>(), [0, 1, 2, 3]);
    // Received in round 1, one hop, from s0.
    for n in [1, 2] {
        let got = logs[n].borrow();
        assert_eq!(got.len(), 1);
        let (k, round, e) = &got[0];
        assert_eq!((*k, *round, e.source, e.sender, e.hops), (1, 1, 0, 0, 1));
    }
    assert!(logs[3].borrow().is_empty());
}

#[test]
fn lateral_and_repeated_frames_meet_their_own_coins() {
    // s0 and s1 linked to each other and to the sink: the link s0 – s1 is off the tree. s0 sends
    // s1 two frames a step at loss 0.3: each arrives with probability 0.7 and both with 0.49
    // (independent coins), within 4 binomial standard errors over 4000 steps.
    let steps = 4000;
    let t = net(
        "edges = [[\"s0\", \"s1\"], [\"s0\", \"sink\"], [\"s1\", \"sink\"]]",
        2,
        "kind = \"bernoulli\"\nloss = 0.3",
    );
    let (mut nodes, logs) = scripted(&t, |n| {
        if n == 0 {
            vec![(Address::Node(1), 10), (Address::Node(1), 10)]
        } else {
            vec![]
        }
    });
    let mut d = GraphDriver::new(&t, 1, steps, 11, 3);
    for k in 1..=steps {
        step(&mut d, k, &mut nodes, 2);
    }
    // One round a step: what s0 sends at step k arrives in round 0 of step k + 1.
    let got = logs[1].borrow();
    let mut per_step = vec![0u32; steps + 1];
    for (_, _, e) in got.iter() {
        per_step[e.sent] += 1;
    }
    let n = steps as f64;
    let check = |observed: f64, p: f64, what: &str| {
        let se = (p * (1.0 - p) / n).sqrt();
        assert!(
            (observed - p).abs() < 4.0 * se,
            "{what}: {observed} vs {p} ± {se}"
        );
    };
    check(got.len() as f64 / (2.0 * n), 0.7, "one frame");
    check(
        per_step.iter().filter(|&&c| c == 2).count() as f64 / n,
        0.49,
        "both frames",
    );
}

#[test]
fn a_delayed_frame_arrives_at_the_first_round_of_its_step() {
    let t = net("", 1, "kind = \"ideal\"\ndelay = 2");
    let (mut nodes, logs) = scripted(&t, |n| {
        if n == 0 {
            vec![(Address::Node(1), 4)]
        } else {
            vec![]
        }
    });
    let mut d = GraphDriver::new(&t, 3, 4, 1, 0);
    for k in 1..=4 {
        step(&mut d, k, &mut nodes, 1);
    }
    let got = logs[1].borrow();
    let arrivals: Vec<_> = got.iter().map(|(k, r, e)| (*k, *r, e.sent)).collect();
    assert_eq!(arrivals, [(3, 0, 1), (4, 0, 2)]);
}

#[test]
fn a_unicast_off_the_tree_and_a_failing_node_are_named() {
    // A line s0 – s1 – sink: s1 cannot reach s0 by a route up the tree... but they are
    // neighbours; the sink's child s1 is reachable; s0 → s0 is no route, nor is the sink → s0.
    let t = net("edges = \"line\"", 2, "kind = \"ideal\"");
    for (from, to) in [(2, 0), (0, 0)] {
        let (mut nodes, _) = scripted(&t, |n| {
            if n == from {
                vec![(Address::Node(to), 1)]
            } else {
                vec![]
            }
        });
        let mut d = GraphDriver::new(&t, 1, 1, 1, 0);
        let z = Vector::zeros(1);
        let e = d.step(1, &mut nodes, &[Some(&z), Some(&z)]).unwrap_err();
        assert!(e.contains("no route from") && e.contains("to s0"), "{e}");
    }
    // Out of order, or the wrong number of nodes.
    let (mut nodes, _) = scripted(&t, |_| vec![]);
    let mut d = GraphDriver::new(&t, 1, 2, 1, 0);
    let z = Vector::zeros(1);
    assert!(d.step(2, &mut nodes, &[Some(&z), Some(&z)]).is_err());
    assert!(d.step(1, &mut nodes[..2], &[Some(&z), Some(&z)]).is_err());
    // A node's own error carries its name, step and round.
    struct Failing;
    impl NetworkNode<Bytes> for Failing {
        fn round(
            &mut self,
            _: Round,
            _: &[Envelope<Bytes>],
            _: &mut Outbox<Bytes>,
        ) -> Result<(), String> {
            Err("broken".into())
        }
        fn windows(&self, _: usize) -> u64 {
            0
        }
    }
    nodes[1] = Box::new(Failing);
    let e = d.step(1, &mut nodes, &[Some(&z), Some(&z)]).unwrap_err();
    assert_eq!(e, "node s1, step 1, round 0: broken");
}

#[test]
fn a_unicast_up_the_tree_is_paid_at_every_hop() {
    // s0 – r0 – sink, one 25-octet frame from s0 to the sink, ideal links with ARQ: each hop one
    // frame and one ACK; r0 forwards.
    let t = net(
        "relays = 1\nedges = \"line\"",
        1,
        "kind = \"ideal\"\narq = { max_retries = 3 }",
    );
    let (mut nodes, logs) = scripted(&t, |n| {
        if n == 0 {
            vec![(Address::Node(2), 25)]
        } else {
            vec![]
        }
    });
    let mut d = GraphDriver::new(&t, 2, 1, 1, 0);
    step(&mut d, 1, &mut nodes, 1);
    let ppdu = 200 + PHY_OVERHEAD_BITS;
    let c = d.counts();
    // sent, bits sent, received, bits received, acks sent, acks heard, ack waits, forwarded.
    assert_eq!(c[0][..8], [1, ppdu, 0, 0, 0, 1, 1, 0]);
    assert_eq!(c[1][..8], [1, ppdu, 1, ppdu, 1, 1, 1, 1]);
    assert_eq!(c[2][..8], [0, 0, 1, ppdu, 1, 0, 0, 0]);
    let got = logs[2].borrow();
    assert_eq!((got[0].2.source, got[0].2.sender, got[0].2.hops), (0, 1, 2));
}
