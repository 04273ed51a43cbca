//! The all-data KF's step from an information sum made inside the network
//! ([`crate::network::aggregate`]): the operations of the direct linear step (predict,
//! `Information::from_gaussian`, the sum added, `to_gaussian`), with the relays' sum in place
//! of the center's own sum over the arrived measurements (Dormann et al., Section II,
//! eq. (8)-(9) for a subset).
use super::CentralizedKf;
use crate::filter::information::Information;
use crate::filter::kf;
use crate::scheme::SchemeError;

impl CentralizedKf {
    /// One step fusing `sum` (`None`: nothing arrived, a time update only).
    pub(super) fn fuse_sum(&mut self, sum: Option<&Information>) -> Result<(), SchemeError> {
        // Off the shared schedule for good: which sums arrive is the network's draw.
        self.schedule = None;
        self.steps_done += 1;
        let predicted = kf::predict(&self.system.transition, &self.est);
        let Some(sum) = sum else {
            self.est = predicted;
            return Ok(());
        };
        let mut info = Information::from_gaussian(&predicted)?;
        info.matrix += &sum.matrix;
        info.vector += &sum.vector;
        self.est = info.to_gaussian()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::filter::information::Information;
    use crate::link::Received;
    use crate::scheme::Scheme;

    /// The center fed the sum of every sensor's H^T R^{-1} z and H^T R^{-1} H gives the all-data
    /// KF's estimate to 1e-12, step after step; with no sum, its time update.
    #[test]
    fn the_sum_gives_the_all_data_estimate() {
        let text = crate::scenario::builtin::get("arena-1d").expect("built-in");
        let exp = crate::scenario::build::load(text, "arena-1d").expect("loads");
        let system = exp.system.clone();
        let scheme = super::super::CentralizedScheme::new(system.clone(), 1.0).expect("scheme");
        assert!(scheme.aggregable());
        let mut direct = scheme.build().expect("build").center;
        let mut summed = scheme.build().expect("build").center;
        let n = system.state_dim();
        for k in 1..=20usize {
            let zs: Vec<_> = (0..system.n_sensors())
                .map(|i| crate::linalg::Vector::from_element(1, (k * (i + 1)) as f64 * 0.37 - 2.0))
                .collect();
            let inbox: Vec<_> = zs.iter().cloned().map(Received::Measurement).collect();
            let mut sum = Information {
                matrix: crate::linalg::Matrix::zeros(n, n),
                vector: crate::linalg::Vector::zeros(n),
            };
            for (i, z) in zs.iter().enumerate() {
                let s = system.sensors[i].as_linear().expect("linear");
                sum.vector += s.ht_rinv() * z;
                sum.matrix += s.information();
            }
            direct.step(k, &inbox).expect("direct");
            summed
                .fuse_information(k, (k % 5 != 0).then_some(&sum))
                .expect("sum");
            if k % 5 == 0 {
                // The direct center had data, this one had none: compare from here afresh.
                summed = scheme.build().expect("build").center;
                direct = scheme.build().expect("build").center;
                continue;
            }
            let (a, b) = (direct.estimate(), summed.estimate());
            let scale = a.cov.amax().max(a.mean.amax());
            assert!((&a.mean - &b.mean).amax() <= 1e-12 * scale, "mean at {k}");
            assert!((&a.cov - &b.cov).amax() <= 1e-12 * scale, "cov at {k}");
        }
        // No sum: the time update alone.
        let mut center = scheme.build().expect("build").center;
        center.fuse_information(1, None).expect("predict");
        let predicted = crate::filter::kf::predict(&system.transition, &system.prior);
        assert_eq!(center.estimate(), &predicted);
    }
}
