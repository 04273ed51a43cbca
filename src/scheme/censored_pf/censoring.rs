//! The censoring rules of Zheng et al. (2014): the NIS rule (4)/(31) with the threshold (8)/(32)/(43),
//! and the KL-divergence rule (24) with the threshold that Theorem 1 maps to.
use crate::filter::Gaussian;
use crate::linalg::{cholesky, Matrix, Vector};
use crate::scheme::SchemeError;
use crate::stats::chi2;

/// eta = chi^2_{n_nu}(l / N): the value a chi-square with `innovation_dim` degrees of freedom
/// exceeds with probability l / N, so that on average `l` of `n_sensors` sensors send
/// (Zheng et al. (2014), eq. (8), (32), (43)).
pub fn nis_threshold(innovation_dim: usize, l: f64, n_sensors: usize) -> Result<f64, SchemeError> {
    if !(l > 0.0 && l <= n_sensors as f64) {
        return Err(SchemeError::Unsupported(format!(
            "the average number of active sensors l must lie in (0, N = {n_sensors}], got {l}"
        )));
    }
    chi2::upper_quantile(innovation_dim as f64, l / n_sensors as f64)
        .map_err(|e| SchemeError::Unsupported(e.to_string()))
}

/// Normalized innovation squared nu^T S^{-1} nu (Zheng et al. (2014), eq. (4), (31)).
pub fn nis(nu: &Vector, s: &Matrix) -> Result<f64, SchemeError> {
    crate::linalg::mahalanobis_sq(nu, s).map_err(|source| SchemeError::Matrix {
        what: "innovation covariance S",
        source,
    })
}

/// KL divergence D(p || q) between Gaussians p = prior and q = posterior (Zheng et al. (2014), eq. (25)):
/// 1/2 {tr(P_q^{-1} P_p) - ln(|P_p| / |P_q|) - d} + 1/2 (m_q - m_p)^T P_q^{-1} (m_q - m_p).
pub fn kl_divergence(p: &Gaussian, q: &Gaussian) -> Result<f64, SchemeError> {
    let (cp, cq) = (chol(&p.cov)?, chol(&q.cov)?);
    let d = p.dim() as f64;
    let tr = (cq.solve(&p.cov)).trace();
    let logdet = |c: &nalgebra::Cholesky<f64, nalgebra::Dyn>| -> f64 {
        2.0 * c.l().diagonal().iter().map(|v| v.ln()).sum::<f64>()
    };
    let dm = &q.mean - &p.mean;
    let quad = dm.dot(&cq.solve(&dm));
    Ok(0.5 * (tr - (logdet(&cp) - logdet(&cq)) - d) + 0.5 * quad)
}

/// The whitened innovation of a vector sensor, q = S^{-1/2} nu, is
/// N(S^{-1/2} E[nu | x], S^{-1/2} R S^{-1/2}) (Zheng et al. (2014), eq. (35)-(38)); returns S^{-1/2}
/// (symmetric) and the covariance S^{-1/2} R S^{-1/2}, shared by every particle.
pub fn whitened_band(s: &Matrix, r: &Matrix) -> (Matrix, Matrix) {
    let eig = s.clone().symmetric_eigen();
    let s_inv_sqrt = &eig.eigenvectors
        * Matrix::from_diagonal(&eig.eigenvalues.map(|v| 1.0 / v.sqrt()))
        * eig.eigenvectors.transpose();
    let mut c = &s_inv_sqrt * r * &s_inv_sqrt;
    crate::linalg::symmetrize(&mut c);
    (s_inv_sqrt, c)
}

fn chol(m: &Matrix) -> Result<nalgebra::Cholesky<f64, nalgebra::Dyn>, SchemeError> {
    cholesky(m).map_err(|source| SchemeError::Matrix {
        what: "covariance",
        source,
    })
}

/// The KL threshold zeta that makes rule (24) send exactly when NIS >= eta (Theorem 1): with
/// x_{k|k} - x_{k|k-1} = w nu, the KL divergence is
/// 1/2 {tr(P_{k|k}^{-1} P_{k|k-1}) - ln(|P_{k|k-1}| / |P_{k|k}|) - d} + 1/2 nu^2 w^T P_{k|k}^{-1} w,
/// increasing in nu^2, so KL >= zeta iff nu^2 >= eta s, i.e. zeta is the KL divergence at
/// nu^2 = eta s (scalar measurements).
pub fn kl_threshold_for_nis(
    prior: &Gaussian,
    posterior_cov: &Matrix,
    gain: &Vector,
    s: f64,
    eta: f64,
) -> Result<f64, SchemeError> {
    let at_threshold = Gaussian::new(&prior.mean + gain * (eta * s).sqrt(), posterior_cov.clone());
    kl_divergence(prior, &at_threshold)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_gives_the_target_rate() {
        // N = 2, l = 1, scalar: P(chi^2_1 >= eta) = 1/2, eta = 0.454936423119572.
        assert!((nis_threshold(1, 1.0, 2).unwrap() - 0.454936423119572).abs() < 1e-12);
        assert_eq!(nis_threshold(1, 4.0, 4).unwrap(), 0.0);
        assert!(nis_threshold(1, 0.0, 4).is_err());
        assert!(nis_threshold(1, 5.0, 4).is_err());
    }

    #[test]
    fn kl_of_hand_computed_gaussians() {
        // 1-D: p = N(0, 2), q = N(1, 1): 1/2 (2 - ln 2 - 1) + 1/2 * 1.
        let p = Gaussian::new(
            Vector::from_element(1, 0.0),
            Matrix::from_element(1, 1, 2.0),
        );
        let q = Gaussian::new(
            Vector::from_element(1, 1.0),
            Matrix::from_element(1, 1, 1.0),
        );
        let expected = 0.5 * (2.0 - 2f64.ln() - 1.0) + 0.5;
        assert!((kl_divergence(&p, &q).unwrap() - expected).abs() < 1e-14);
    }
}
