//! In-network aggregation of information contributions over a routing tree: every node sends
//! one frame per step that carries the sum of its subtree's information, so the sink receives
//! the exact all-data Kalman update in one frame per link (the sum of H_i^T R_i^{-1} H_i and
//! H_i^T R_i^{-1} z_i over the sensors whose reports reached it; Dormann et al., Section II, the
//! centralized KF fuses a sum, eq. (8)-(9) for a subset).
//!
//! # The frames
//!
//! - A node whose frame would hold one sensor's report only (a sensor none of whose children
//!   sent it anything this step, or a relay with one report from below) sends that report, the
//!   measurement z as the sensor sent it on the star: it is the shortest message that holds
//!   that information, and the node that sums it turns it into H^T R^{-1} z and H^T R^{-1} H,
//!   which it knows from the model. (A single report thus travels as per-source forwarding
//!   sends it.)
//! - A node holding more than one report sends the sum (y, Y): the n entries of the
//!   vector and the n(n+1)/2 distinct entries of the symmetric matrix ([`super::estimate_reals`]), each a
//!   single as priced. The matrix must travel: under losses the sink cannot know whose
//!   contributions a sum holds.
//! - A node with nothing to send (no measurement of its own, no child's frame arrived) is
//!   silent. A frame lost on a link loses its whole subtree's information for the step: the
//!   sink's update is then the all-data update over the reports that arrived, which the KF
//!   handles exactly (a missing measurement carries no information for the all-data KF).
//!
//! Reports that must not be merged (censored, quantized, triggered: their silences mean
//! something, and a sum hides who was silent) are forwarded per source instead
//! ([`crate::network::channel::route`]); only schemes that say so
//! ([`crate::scheme::Scheme::aggregable`]) aggregate.
use crate::filter::information::Information;
use crate::linalg::{Matrix, Vector};
use crate::link::codec802154::mpdu_bits_for_payload;
use crate::link::{round_as_sent, Received, BITS_PER_COMPONENT};
use crate::network::channel::route::Routes;
use crate::network::channel::{Fate, FateTable};
use crate::network::topology::tally::Tally;
use crate::network::Traffic;

/// What a node puts on its uplink at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// Nothing to send.
    None,
    /// The measurement of one sensor (the node's own, or the one report it holds), as the
    /// sensor sent it on the star.
    Measurement(usize),
    /// An information sum ([`super::estimate_reals`] reals).
    Sum,
}

/// The order in which the nodes of `routes` fold: every node after all its children (deepest
/// first, lower index first among nodes of equal depth), the sink excluded.
pub fn fold_order(routes: &Routes) -> Vec<usize> {
    let depth = |mut n: usize| {
        let mut d = 0usize;
        while let Some((p, _)) = &routes.uplinks[n] {
            n = *p;
            d += 1;
        }
        d
    };
    let mut order: Vec<(usize, usize)> = (0..routes.uplinks.len())
        .filter(|&n| routes.uplinks[n].is_some())
        .map(|n| (depth(n), n))
        .collect();
    order.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    order.into_iter().map(|(_, n)| n).collect()
}

/// Sums information up a routing tree, one step at a time, in buffers kept from step to step.
#[derive(Debug, Clone)]
pub struct Folder {
    order: Vec<usize>,
    parent: Vec<Option<usize>>,
    sink: usize,
    dim: usize,
    /// Per node, one after the other: the sum it holds this step, y (dim) then Y (dim × dim,
    /// column-major). One flat buffer: a thousand nodes' sums stay in a few pages.
    sums: Vec<f64>,
    /// The sink's sum after the last fold.
    held: Information,
    /// Per node: how many contributions its sum holds (its own, and one per child's frame).
    parts: Vec<u32>,
    /// Per node: the sensor whose report it holds when it holds one only (then it sends that).
    single: Vec<Option<usize>>,
}

/// `to[i] += from[i]` for every i.
fn add(to: &mut [f64], from: &[f64]) {
    for (t, f) in to.iter_mut().zip(from) {
        *t += f;
    }
}

impl Folder {
    /// A folder over `routes` for state dimension `dim`.
    pub fn new(routes: &Routes, dim: usize) -> Self {
        let nodes = routes.uplinks.len();
        Folder {
            order: fold_order(routes),
            parent: routes
                .uplinks
                .iter()
                .map(|u| u.as_ref().map(|(p, _)| *p))
                .collect(),
            sink: routes
                .uplinks
                .iter()
                .position(Option::is_none)
                .expect("a routing tree has a sink"),
            dim,
            sums: vec![0.0; nodes * (dim + dim * dim)],
            held: Information {
                matrix: Matrix::zeros(dim, dim),
                vector: Vector::zeros(dim),
            },
            parts: vec![0; nodes],
            single: vec![None; nodes],
        }
    }

    fn stride(&self) -> usize {
        self.dim + self.dim * self.dim
    }

    /// A new step: every node holds nothing.
    pub fn start(&mut self) {
        let w = self.stride();
        for (n, p) in self.parts.iter_mut().enumerate() {
            if *p > 0 {
                self.sums[n * w..(n + 1) * w].fill(0.0);
            }
            *p = 0;
        }
        self.single.fill(None);
    }

    /// Node `node`'s own contribution (y_i = H^T R^{-1} z, Y_i = H^T R^{-1} H) this step.
    pub fn add_own(&mut self, node: usize, vector: &Vector, matrix: &Matrix) {
        let (w, d) = (self.stride(), self.dim);
        let sum = &mut self.sums[node * w..(node + 1) * w];
        add(&mut sum[..d], vector.as_slice());
        add(&mut sum[d..], matrix.as_slice());
        self.parts[node] += 1;
        self.single[node] = (self.parts[node] == 1).then_some(node);
    }

    /// Folds the step's contributions up the tree: every node, children first, sends one frame
    /// to its parent when it holds anything; `send(node, frame)` puts it on the link and says
    /// whether it arrived; `on_air` makes a sum's reals (y, then Y) what its frame carries (the
    /// singles it is priced as). Returns the sum the sink holds, `None` when nothing reached it.
    pub fn fold(
        &mut self,
        mut send: impl FnMut(usize, Frame) -> bool,
        on_air: impl Fn(&mut [f64]),
    ) -> Option<&Information> {
        let w = self.stride();
        for idx in 0..self.order.len() {
            let n = self.order[idx];
            if self.parts[n] == 0 {
                send(n, Frame::None);
                continue;
            }
            let frame = match self.single[n] {
                Some(s) => Frame::Measurement(s),
                None => {
                    on_air(&mut self.sums[n * w..(n + 1) * w]);
                    Frame::Sum
                }
            };
            if !send(n, frame) {
                continue;
            }
            let p = self.parent[n].expect("only nodes with a parent fold");
            let (from, to) = pair_mut(&mut self.sums, w, n, p);
            add(to, from);
            self.parts[p] += 1;
            self.single[p] = match (self.parts[p], frame) {
                (1, Frame::Measurement(s)) => Some(s),
                _ => None,
            };
        }
        let d = self.dim;
        let sink = &self.sums[self.sink * w..(self.sink + 1) * w];
        self.held.vector.as_mut_slice().copy_from_slice(&sink[..d]);
        self.held.matrix.as_mut_slice().copy_from_slice(&sink[d..]);
        self.held()
    }

    /// The sum the sink holds after the last [`Folder::fold`] (`None`: nothing reached it).
    pub fn held(&self) -> Option<&Information> {
        (self.parts[self.sink] > 0).then_some(&self.held)
    }
}

/// One trial's aggregation in the link layer: what each sensor's measurement adds, the folder,
/// and what a sum frame costs.
#[derive(Debug, Clone)]
pub struct Aggregation {
    folder: Folder,
    /// Per sensor: (H^T R^{-1}, H^T R^{-1} H).
    sensors: Vec<(Matrix, Matrix)>,
    work: Vector,
    /// Payload and MAC-frame bits of a sum frame.
    sum_bits: (u64, u64),
}

impl Aggregation {
    /// The aggregation over `routes` of sensors with `sensors[i] = (H_i^T R_i^{-1},
    /// H_i^T R_i^{-1} H_i)` (state dimension their rows).
    pub fn new(routes: &Routes, sensors: Vec<(Matrix, Matrix)>) -> Self {
        let dim = sensors.first().map_or(0, |(a, _)| a.nrows());
        let payload = super::estimate_reals(dim) * BITS_PER_COMPONENT;
        Aggregation {
            folder: Folder::new(routes, dim),
            sensors,
            work: Vector::zeros(dim),
            sum_bits: (payload, mpdu_bits_for_payload(payload)),
        }
    }

    /// Step `k`: the measurements in `inbox` (as they went on air) summed up the tree, every
    /// node's frame meeting its fate of `node_up` and counted in `tally` and `traffic` (which
    /// has the sensors' decisions already: `messages`, `senders`). Returns nothing; the sink's
    /// sum is [`Aggregation::held`].
    pub fn deliver(
        &mut self,
        k: usize,
        inbox: &[Received],
        routes: &Routes,
        node_up: &FateTable,
        tally: &mut Tally,
        traffic: &mut Traffic,
    ) {
        self.folder.start();
        for (i, r) in inbox.iter().enumerate() {
            if let Received::Measurement(z) = r {
                let (ht_rinv, info) = &self.sensors[i];
                self.work.gemv(1.0, ht_rinv, z, 0.0);
                self.folder.add_own(i, &self.work, info);
            }
        }
        let sum_bits = self.sum_bits;
        self.folder.fold(
            |n, frame| {
                let (payload, mac) = match frame {
                    Frame::None => return false,
                    Frame::Measurement(s) => match &inbox[s] {
                        Received::Measurement(z) => {
                            let bits = z.len() as u64 * BITS_PER_COMPONENT;
                            (bits, mpdu_bits_for_payload(bits))
                        }
                        _ => unreachable!("a report held is a measurement that was sent"),
                    },
                    Frame::Sum => sum_bits,
                };
                let f = node_up.get(n, k);
                traffic.add_frames(&f, payload, mac);
                tally.hop(routes, n, &f, mac, frame != Frame::Measurement(n))
            },
            round_as_sent,
        );
    }

    /// The sum the sink holds after the last [`Aggregation::deliver`].
    pub fn held(&self) -> Option<&Information> {
        self.folder.held()
    }
}

/// Per (sensor, step): whether the sensor's report reached the sink inside the sums, that is
/// whether every node of its route delivered its frame of the step (`node_up`, no delay: a
/// network that aggregates has none). O(nodes) a step: parents first, each node reaches the
/// sink when its parent does and its own frame arrived.
pub fn composed(routes: &Routes, node_up: &FateTable, steps: usize) -> FateTable {
    let mut parents_first = fold_order(routes);
    parents_first.reverse();
    let sensors = routes.senders.len();
    let mut reaches = vec![true; routes.uplinks.len()];
    let mut fates = vec![Fate::default(); sensors * steps];
    for k in 1..=steps {
        for &n in &parents_first {
            let (p, _) = routes.uplinks[n]
                .as_ref()
                .expect("only nodes with a parent");
            reaches[n] = reaches[*p] && !node_up.get(n, k).lost;
        }
        for s in 0..sensors {
            fates[s * steps + (k - 1)].lost = !reaches[s];
        }
    }
    FateTable::from_fates(sensors, steps, fates)
}

/// Blocks `a` and `b` (of `w` entries each) of `v`, the first to read, the second to write
/// (`a != b`).
fn pair_mut(v: &mut [f64], w: usize, a: usize, b: usize) -> (&[f64], &mut [f64]) {
    assert_ne!(a, b, "a node is never its own parent");
    if a < b {
        let (lo, hi) = v.split_at_mut(b * w);
        (&lo[a * w..(a + 1) * w], &mut hi[..w])
    } else {
        let (lo, hi) = v.split_at_mut(a * w);
        (&hi[..w], &mut lo[b * w..(b + 1) * w])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::channel::ChannelSpec;
    use proptest::prelude::*;

    /// Routes of a tree given by its parents (`None`: the sink).
    fn routes(parent: &[Option<usize>]) -> Routes {
        let uplinks = parent
            .iter()
            .map(|p| p.map(|p| (p, ChannelSpec::default())))
            .collect();
        Routes {
            uplinks,
            senders: Vec::new(),
        }
    }

    fn info(dim: usize, seed: &[f64]) -> (Vector, Matrix) {
        let v = Vector::from_fn(dim, |i, _| seed[i % seed.len()] * (i as f64 + 1.0));
        let a = Matrix::from_fn(dim, dim, |i, j| seed[(i + 2 * j) % seed.len()]);
        (v, &a * a.transpose())
    }

    #[test]
    fn the_frames_a_line_sends() {
        // s0 -> s1 -> sink: s0 sends its measurement, s1 a sum of two, the sink holds both.
        let r = routes(&[Some(1), Some(2), None]);
        let mut f = Folder::new(&r, 2);
        f.start();
        let (v0, m0) = info(2, &[1.0, 2.0]);
        let (v1, m1) = info(2, &[3.0, -1.0]);
        f.add_own(0, &v0, &m0);
        f.add_own(1, &v1, &m1);
        let mut frames = Vec::new();
        let sum = f.fold(
            |n, fr| {
                frames.push((n, fr));
                true
            },
            |_| {},
        );
        let sum = sum.expect("both arrived");
        assert_eq!(sum.vector, &v0 + &v1);
        assert_eq!(sum.matrix, &m0 + &m1);
        assert_eq!(frames, [(0, Frame::Measurement(0)), (1, Frame::Sum)]);
        // s0's frame lost: s1 sends its own measurement only; then nothing at all.
        f.start();
        f.add_own(0, &v0, &m0);
        f.add_own(1, &v1, &m1);
        let mut frames = Vec::new();
        let sum = f.fold(
            |n, fr| {
                frames.push((n, fr));
                n != 0
            },
            |_| {},
        );
        assert_eq!(sum.expect("s1 arrived").vector, v1);
        assert_eq!(
            frames,
            [(0, Frame::Measurement(0)), (1, Frame::Measurement(1))]
        );
        // A relay holding one report passes it on as it came: s0 -> r(1) -> sink.
        let r = routes(&[Some(1), Some(2), None]);
        let mut f = Folder::new(&r, 2);
        f.start();
        f.add_own(0, &v0, &m0);
        let mut frames = Vec::new();
        f.fold(
            |n, fr| {
                frames.push((n, fr));
                true
            },
            |_| {},
        );
        assert_eq!(
            frames,
            [(0, Frame::Measurement(0)), (1, Frame::Measurement(0))]
        );
        f.start();
        assert!(f.fold(|_, fr| fr != Frame::None, |_| {}).is_none());
        assert_eq!(crate::network::estimate_reals(2), 5);
        assert_eq!(crate::network::estimate_reals(4), 14);
    }

    /// A random tree over `n` nodes whose sink is the last: each node's parent is a later node.
    fn tree() -> impl Strategy<Value = Vec<Option<usize>>> {
        (2usize..40).prop_flat_map(|n| {
            let parents: Vec<_> = (0..n - 1)
                .map(|i| (i + 1..n).prop_map(Some).boxed())
                .collect();
            parents.prop_map(|mut p| {
                p.push(None);
                p
            })
        })
    }

    proptest! {
        /// On any tree, with every frame delivered, the sink holds the direct sum of every
        /// node's contribution to 1e-12 (the all-data KF's information; its update from it is
        /// tested in `crate::scheme::centralized`).
        #[test]
        fn the_sink_holds_the_direct_sum(parent in tree(), dim in 1usize..5, salt in 0.1f64..3.0) {
            let r = routes(&parent);
            let nodes = parent.len();
            let mut f = Folder::new(&r, dim);
            f.start();
            let mut direct = (Vector::zeros(dim), Matrix::zeros(dim, dim));
            // Every node but the sink contributes (relays too: the fold does not care).
            for n in 0..nodes - 1 {
                let (v, m) = info(dim, &[salt * (n as f64 + 1.0), 1.0 / (n as f64 + salt), -0.5]);
                f.add_own(n, &v, &m);
                direct.0 += &v;
                direct.1 += &m;
            }
            let sum = f.fold(|_, _| true, |_| {}).expect("every frame arrives").clone();
            let scale = direct.1.amax().max(direct.0.amax());
            prop_assert!((&sum.vector - &direct.0).amax() <= 1e-12 * scale);
            prop_assert!((&sum.matrix - &direct.1).amax() <= 1e-12 * scale);
        }

        /// With frames lost, the sink holds exactly the contributions whose every hop arrived.
        #[test]
        fn a_lost_frame_loses_its_subtree(parent in tree(), lost_mask in any::<u64>()) {
            let r = routes(&parent);
            let nodes = parent.len();
            let lost = |n: usize| (lost_mask >> (n % 64)) & 1 == 1;
            let reaches = |mut n: usize| loop {
                match parent[n] {
                    None => return true,
                    Some(_) if lost(n) => return false,
                    Some(p) => n = p,
                }
            };
            let mut f = Folder::new(&r, 1);
            f.start();
            let mut expected = 0.0;
            for n in 0..nodes - 1 {
                let w = (n + 1) as f64;
                f.add_own(n, &Vector::from_element(1, w), &Matrix::from_element(1, 1, 1.0));
                if reaches(n) {
                    expected += w;
                }
            }
            let got = f.fold(|n, fr| fr != Frame::None && !lost(n), |_| {}).map_or(0.0, |s| s.vector[0]);
            prop_assert_eq!(got, expected);
        }
    }
}
