//! Many estimators of one trial (a decentralized scheme: every node estimates): the step's row
//! is the mean over the nodes, and each node's own squared error and NEES, and the nodes'
//! disagreement, are kept beside it ([`super::Sums::estimators`], [`super::Sums::disagreement`]).
use super::{link_counts, trace, traffic_counts, StepValues, Sums, TrialStat, TrialState};
use crate::filter::Gaussian;
use crate::linalg::Vector;
use crate::network::Traffic;

/// One estimator of a network (a node of a decentralized scheme): its per-trial steady-state
/// mean squared error and NEES, summed over trials with their squares.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EstimatorStat {
    pub mse: TrialStat,
    pub nees: TrialStat,
}

/// What a trial of a decentralized scheme carries besides the mean over its nodes.
#[derive(Debug, Default)]
pub(super) struct EstimatorState {
    /// Per node, the steady-state sums of its squared error and NEES.
    pub(super) acc: Vec<[f64; 2]>,
    /// The steady-state sum of the disagreement.
    pub(super) disagreement: f64,
    /// Work space: one node's error, the mean over nodes of each component's squared error,
    /// the mean estimate.
    err: Vec<f64>,
    sq: Vec<f64>,
    mean: Vec<f64>,
}

impl TrialState<'_> {
    /// Records step `k` of a decentralized scheme, whose every node estimates: `estimates[i]`
    /// is node i's. The step's values are the means over the nodes (squared error per
    /// component, NEES, trace; the degenerate and covered fields as fractions of the nodes);
    /// each node's squared error and NEES, and the nodes' disagreement, go to its running sums
    /// ([`Sums::estimators`], [`Sums::disagreement`]). `factors`, where given, are the estimates'
    /// covariances' Cholesky factors as NEES computes them (`linalg::fixed::nees_factor`, n²
    /// reals an estimate, in order): the same NEES without factoring again.
    pub fn record_estimators(
        &mut self,
        sums: &mut Sums,
        k: usize,
        truth: &Vector,
        (estimates, factors): (&[&Gaussian], Option<&[f64]>),
        traffic: Traffic,
    ) -> Result<(), crate::linalg::LinalgError> {
        let (n, m) = (truth.len(), estimates.len());
        assert!(m > 0, "record_estimators: no estimate");
        let mut st = self.estimators.take().unwrap_or_default();
        st.acc.resize(m, [0.0; 2]);
        st.err.resize(n, 0.0);
        st.sq.clear();
        st.sq.resize(n, 0.0);
        st.mean.clear();
        st.mean.resize(n, 0.0);
        let steady = k >= self.steady_from;
        let (mut nees_sum, mut trace_sum, mut degenerate) = (0.0, 0.0, 0usize);
        let mut covered = [0usize; 2];
        for (i, est) in estimates.iter().enumerate() {
            assert_eq!(est.mean.len(), n, "record: truth and estimate dimensions");
            for ((e, x), t) in st.err.iter_mut().zip(est.mean.iter()).zip(truth.iter()) {
                *e = x - t;
            }
            let factor = factors.and_then(|f| f.get(i * n * n..(i + 1) * n * n));
            let (nees, degen) = match self.nees(&st.err, est, factor) {
                Ok(v) => v,
                Err(e) => {
                    self.estimators = Some(st);
                    return Err(e);
                }
            };
            let se: f64 = st.err.iter().map(|e| e * e).sum();
            for ((q, e), (x, v)) in st
                .sq
                .iter_mut()
                .zip(&st.err)
                .zip(st.mean.iter_mut().zip(est.mean.iter()))
            {
                *q += e * e;
                *x += v;
            }
            nees_sum += nees;
            trace_sum += trace(&est.cov);
            degenerate += usize::from(degen);
            covered[0] += usize::from(nees <= self.nees_bound);
            covered[1] += usize::from(nees <= self.nees_bound_95);
            if steady {
                st.acc[i][0] += se;
                st.acc[i][1] += nees;
            }
        }
        let mf = m as f64;
        st.sq.iter_mut().for_each(|q| *q /= mf);
        st.mean.iter_mut().for_each(|x| *x /= mf);
        let disagreement = estimates
            .iter()
            .map(|est| {
                est.mean
                    .iter()
                    .zip(&st.mean)
                    .map(|(x, c)| (x - c) * (x - c))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / mf;
        if steady {
            st.disagreement += disagreement;
        }
        let link = link_counts(&traffic);
        if link.iter().any(|&c| c > 0) {
            sums.add_link(k, link);
        }
        if self.traffic.0 != traffic {
            self.traffic = (traffic, traffic_counts(traffic));
        }
        let step = StepValues {
            total: st.sq.iter().sum(),
            nees: nees_sum / mf,
            degenerate: degenerate as f64 / mf,
            covered: [covered[0] as f64 / mf, covered[1] as f64 / mf],
            trace: trace_sum / mf,
        };
        let counts = self.traffic.1;
        let sq = std::mem::take(&mut st.sq);
        self.accumulate_step(
            sums,
            k,
            &step,
            |idx| idx.iter().map(|&j| sq[j]).sum(),
            counts,
        );
        st.sq = sq;
        self.estimators = Some(st);
        Ok(())
    }
}
