//! Nonlinear scalar sensors with their Jacobians: range (Zhang et al. (2016), eq. (17)) and received signal
//! strength (Zheng et al. (2014), Section VII-C). Both measure a target whose planar position sits at two
//! state indices.
use super::{MeasurementModel, ModelError};
use crate::linalg::{Matrix, Vector};
use multiversion::multiversion;

/// Where the target's position lives in the state, and where the sensor is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Sensor position (x_i, y_i).
    pub position: [f64; 2],
    /// State indices of the target's x and y.
    pub indices: [usize; 2],
    /// State dimension.
    pub state_dim: usize,
}

impl Placement {
    /// The target's x and y components of a particle cloud (`component(j)` is state component
    /// `j` of every particle).
    fn target_xy<'a>(&self, component: &dyn Fn(usize) -> &'a [f64]) -> (&'a [f64], &'a [f64]) {
        (component(self.indices[0]), component(self.indices[1]))
    }

    fn check(&self) -> Result<(), ModelError> {
        if self.indices.iter().any(|&i| i >= self.state_dim) || self.indices[0] == self.indices[1] {
            return Err(ModelError::Dimension {
                what: "position indices",
                expected: format!(
                    "two distinct indices below the state dimension {}",
                    self.state_dim
                ),
                got: format!("{:?}", self.indices),
            });
        }
        if self.position.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::Parameter {
                what: "sensor position",
                value: self.position[0] + self.position[1],
            });
        }
        Ok(())
    }

    /// (dx, dy, d) from the sensor to the target.
    #[inline]
    fn offset(&self, x: &Vector) -> (f64, f64, f64) {
        let dx = x[self.indices[0]] - self.position[0];
        let dy = x[self.indices[1]] - self.position[1];
        (dx, dy, (dx * dx + dy * dy).sqrt())
    }
}

fn scalar_noise(r: f64) -> Result<(Matrix, Matrix), ModelError> {
    if !(r.is_finite() && r > 0.0) {
        return Err(ModelError::Parameter {
            what: "measurement noise variance r",
            value: r,
        });
    }
    Ok((
        Matrix::from_element(1, 1, r),
        Matrix::from_element(1, 1, r.sqrt()),
    ))
}

/// Range sensor z = ||p - s|| + v, v ~ N(0, r) (Zhang et al. (2016), eq. (17)).
#[derive(Debug, Clone)]
pub struct RangeSensor {
    placement: Placement,
    r: Matrix,
    r_sqrt: Matrix,
}

impl RangeSensor {
    pub fn new(placement: Placement, r: f64) -> Result<Self, ModelError> {
        placement.check()?;
        let (r, r_sqrt) = scalar_noise(r)?;
        Ok(Self {
            placement,
            r,
            r_sqrt,
        })
    }
    pub fn placement(&self) -> &Placement {
        &self.placement
    }
}

impl MeasurementModel for RangeSensor {
    fn state_dim(&self) -> usize {
        self.placement.state_dim
    }
    fn meas_dim(&self) -> usize {
        1
    }
    fn predict(&self, x: &Vector) -> Vector {
        Vector::from_element(1, self.placement.offset(x).2)
    }
    /// d(d)/dp = (dx, dy) / d; at d = 0 the range is not differentiable and we return the
    /// zero row (the measurement carries no first-order information there).
    fn jacobian(&self, x: &Vector) -> Matrix {
        let (dx, dy, d) = self.placement.offset(x);
        let mut h = Matrix::zeros(1, self.placement.state_dim);
        if d > 0.0 {
            h[(0, self.placement.indices[0])] = dx / d;
            h[(0, self.placement.indices[1])] = dy / d;
        }
        h
    }
    fn noise_cov(&self) -> &Matrix {
        &self.r
    }
    fn noise_sqrt(&self) -> &Matrix {
        &self.r_sqrt
    }
    fn position(&self) -> Option<[f64; 2]> {
        Some(self.placement.position)
    }
    fn target_indices(&self) -> Option<[usize; 2]> {
        Some(self.placement.indices)
    }
    fn predict_many<'a>(&self, component: &dyn Fn(usize) -> &'a [f64], n: usize, out: &mut [f64]) {
        let (xs, ys) = self.placement.target_xy(component);
        range_many(self.placement.position, xs, ys, &mut out[..n]);
    }
}

/// `out[p] = |(xs[p], ys[p]) - s|` (the range sensor over a particle cloud). Compiled also
/// for AVX2 and picked at run time (same IEEE operations, bit-identical results).
#[multiversion(targets("x86_64+avx2"))]
fn range_many([sx, sy]: [f64; 2], xs: &[f64], ys: &[f64], out: &mut [f64]) {
    for ((o, x), y) in out.iter_mut().zip(xs).zip(ys) {
        let (dx, dy) = (x - sx, y - sy);
        *o = (dx * dx + dy * dy).sqrt();
    }
}

/// `out[p] = sqrt(P0 / (1 + alpha d_p^n))` (the RSS sensor over a particle cloud), with the
/// exponent 2 of Zheng et al.'s (2014) experiments free of `powf`. Multiversioned like [`range_many`]:
/// the divide and square root dominate, and AVX2 does four at a time.
#[multiversion(targets("x86_64+avx2"))]
fn rss_many(
    [sx, sy]: [f64; 2],
    p0: f64,
    alpha: f64,
    exponent: f64,
    xs: &[f64],
    ys: &[f64],
    out: &mut [f64],
) {
    if exponent == 2.0 {
        for ((o, x), y) in out.iter_mut().zip(xs).zip(ys) {
            let (dx, dy) = (x - sx, y - sy);
            *o = (p0 / (1.0 + alpha * (dx * dx + dy * dy))).sqrt();
        }
    } else {
        for ((o, x), y) in out.iter_mut().zip(xs).zip(ys) {
            let d2 = (x - sx) * (x - sx) + (y - sy) * (y - sy);
            *o = (p0 / (1.0 + alpha * d2.powf(0.5 * exponent))).sqrt();
        }
    }
}

/// Received-signal-strength sensor z = sqrt(P0 / (1 + alpha d^n)) + v, v ~ N(0, r)
/// (Zheng et al. (2014), Section VII-C).
#[derive(Debug, Clone)]
pub struct RssSensor {
    placement: Placement,
    p0: f64,
    alpha: f64,
    exponent: f64,
    r: Matrix,
    r_sqrt: Matrix,
}

impl RssSensor {
    pub fn new(
        placement: Placement,
        p0: f64,
        alpha: f64,
        exponent: f64,
        r: f64,
    ) -> Result<Self, ModelError> {
        placement.check()?;
        for (what, v) in [
            ("signal power P0", p0),
            ("path-loss alpha", alpha),
            ("path-loss exponent n", exponent),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ModelError::Parameter { what, value: v });
            }
        }
        let (r, r_sqrt) = scalar_noise(r)?;
        Ok(Self {
            placement,
            p0,
            alpha,
            exponent,
            r,
            r_sqrt,
        })
    }

    /// Noise-free amplitude at distance d.
    #[inline]
    pub fn amplitude(&self, d: f64) -> f64 {
        (self.p0 / (1.0 + self.alpha * d.powf(self.exponent))).sqrt()
    }
}

impl MeasurementModel for RssSensor {
    fn state_dim(&self) -> usize {
        self.placement.state_dim
    }
    fn meas_dim(&self) -> usize {
        1
    }
    fn predict(&self, x: &Vector) -> Vector {
        Vector::from_element(1, self.amplitude(self.placement.offset(x).2))
    }
    /// dh/dd = -(alpha n d^{n-1} / 2) sqrt(P0) (1 + alpha d^n)^{-3/2}, times (dx, dy)/d.
    fn jacobian(&self, x: &Vector) -> Matrix {
        let (dx, dy, d) = self.placement.offset(x);
        let mut h = Matrix::zeros(1, self.placement.state_dim);
        if d > 0.0 {
            let g = 1.0 + self.alpha * d.powf(self.exponent);
            let dh_dd = -0.5
                * self.alpha
                * self.exponent
                * d.powf(self.exponent - 1.0)
                * self.p0.sqrt()
                * g.powf(-1.5);
            h[(0, self.placement.indices[0])] = dh_dd * dx / d;
            h[(0, self.placement.indices[1])] = dh_dd * dy / d;
        }
        h
    }
    fn noise_cov(&self) -> &Matrix {
        &self.r
    }
    fn noise_sqrt(&self) -> &Matrix {
        &self.r_sqrt
    }
    fn position(&self) -> Option<[f64; 2]> {
        Some(self.placement.position)
    }
    fn target_indices(&self) -> Option<[usize; 2]> {
        Some(self.placement.indices)
    }
    /// The particle filter's hot loop: for the common exponent n = 2 no power function is
    /// needed, so the loop is a multiply-add, a division and a square root per particle.
    fn predict_many<'a>(&self, component: &dyn Fn(usize) -> &'a [f64], n: usize, out: &mut [f64]) {
        let (xs, ys) = self.placement.target_xy(component);
        rss_many(
            self.placement.position,
            self.p0,
            self.alpha,
            self.exponent,
            xs,
            ys,
            &mut out[..n],
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn numeric_jacobian(s: &dyn MeasurementModel, x: &Vector) -> Matrix {
        let mut h = Matrix::zeros(1, x.len());
        for j in 0..x.len() {
            let e = 1e-6;
            let mut xp = x.clone();
            let mut xm = x.clone();
            xp[j] += e;
            xm[j] -= e;
            h[(0, j)] = (s.predict(&xp)[0] - s.predict(&xm)[0]) / (2.0 * e);
        }
        h
    }

    #[test]
    fn range_value_and_jacobian() {
        let p = Placement {
            position: [1.0, 2.0],
            indices: [0, 2],
            state_dim: 4,
        };
        let s = RangeSensor::new(p, 4.0).unwrap();
        let x = Vector::from_vec(vec![4.0, 0.3, 6.0, -1.0]);
        assert!((s.predict(&x)[0] - 5.0).abs() < 1e-15); // 3-4-5 triangle
        let h = s.jacobian(&x);
        assert!((h[(0, 0)] - 0.6).abs() < 1e-15 && (h[(0, 2)] - 0.8).abs() < 1e-15);
        assert!((&h - numeric_jacobian(&s, &x)).amax() < 1e-8);
    }

    #[test]
    fn rss_value_and_jacobian() {
        let p = Placement {
            position: [0.0, 0.0],
            indices: [0, 2],
            state_dim: 4,
        };
        let s = RssSensor::new(p, 1000.0, 1.0, 2.0, 1.0).unwrap();
        let x = Vector::from_vec(vec![3.0, 0.0, 4.0, 0.0]);
        // sqrt(1000 / (1 + 25)).
        assert!((s.predict(&x)[0] - (1000.0f64 / 26.0).sqrt()).abs() < 1e-12);
        assert!((s.jacobian(&x) - numeric_jacobian(&s, &x)).amax() < 1e-7);
    }

    #[test]
    fn predict_many_matches_predict() {
        let p = Placement {
            position: [1.0, -2.0],
            indices: [0, 2],
            state_dim: 4,
        };
        let sensors: Vec<Box<dyn MeasurementModel>> = vec![
            Box::new(RangeSensor::new(p, 1.0).unwrap()),
            Box::new(RssSensor::new(p, 1000.0, 1.0, 2.0, 1.0).unwrap()),
            Box::new(RssSensor::new(p, 1000.0, 0.5, 3.0, 1.0).unwrap()),
        ];
        let comps: Vec<Vec<f64>> = (0..4)
            .map(|j| (0..5).map(|p| (p * 3 + j) as f64 * 0.7 - 2.0).collect())
            .collect();
        for s in &sensors {
            let mut out = vec![0.0; 5];
            s.predict_many(&|j| comps[j].as_slice(), 5, &mut out);
            for (p, o) in out.iter().enumerate() {
                let x = Vector::from_fn(4, |j, _| comps[j][p]);
                assert!((o - s.predict(&x)[0]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn rejects_bad_parameters() {
        let bad = Placement {
            position: [0.0, 0.0],
            indices: [0, 5],
            state_dim: 4,
        };
        assert!(RangeSensor::new(bad, 1.0).is_err());
        let p = Placement {
            position: [0.0, 0.0],
            indices: [0, 2],
            state_dim: 4,
        };
        assert!(RangeSensor::new(p, 0.0).is_err());
        assert!(RssSensor::new(p, -1.0, 1.0, 2.0, 1.0).is_err());
    }
}
