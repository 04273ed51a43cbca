//! Whether the singles a scenario sends round its readings coarser than their noise.
//!
//! By default every real number crosses the network as a 32-bit single (`reals = "f32"`), whose
//! rounding is relative: half a unit in the last place of a value near 1e8 is 4. A sensor whose
//! noise σ is 1 then delivers readings whose rounding error is larger than their noise, and a
//! Kalman filter that trusts σ = 1 is overconfident (on a scalar a = 1.2 walk over 100 steps the
//! all-data KF's MSE came out 60% above its own covariance), with nothing in the numbers saying
//! why. The runner keeps the largest |reading| of every measurement component
//! ([`crate::metrics::Sums::reading_peaks`]); a summary warns where half a unit in the last place
//! of that reading exceeds a tenth of the component's noise standard deviation.
use crate::linalg::Vector;
use crate::scenario::experiment::Experiment;

/// The rounding is flagged where it exceeds this fraction of the noise σ.
pub const NOISE_FRACTION: f64 = 0.1;

/// Half a unit in the last place of `x` as a single: the largest error of rounding `x` to the
/// nearest single; infinite where `x` overflows a single.
pub fn half_ulp_f32(x: f64) -> f64 {
    let f = x.abs() as f32;
    if !f.is_finite() {
        return f64::INFINITY;
    }
    let next = f32::from_bits(f.to_bits() + 1);
    0.5 * (f64::from(next) - f64::from(f))
}

/// Raises `peaks` (one entry per measurement component, sensors in order) to the largest
/// |reading| of one trial's `measurements` (`measurements[k][i]` = z_{k+1}^i).
pub fn note_peaks(measurements: &[Vec<Vector>], peaks: &mut Vec<f64>) {
    let width: usize = measurements
        .first()
        .map_or(0, |z| z.iter().map(|v| v.len()).sum());
    if peaks.len() < width {
        peaks.resize(width, 0.0);
    }
    for step in measurements {
        let mut c = 0;
        for z in step {
            raise_peaks(&mut peaks[c..], z.as_slice());
            c += z.len();
        }
    }
}

/// Raises `peaks[j]` to `|z[j]|` where that is larger: one reading's components into the peaks
/// from its sensor's first component on (what [`note_peaks`] does per reading, and what the
/// drawer does as it draws). `max` ignores a NaN (a recorded hole is not a reading).
#[inline(always)]
pub fn raise_peaks(peaks: &mut [f64], z: &[f64]) {
    // A scalar reading (most sensors) without the loop's set-up.
    if let ([p, ..], [v]) = (&mut *peaks, z) {
        *p = p.max(v.abs());
        return;
    }
    for (p, v) in peaks.iter_mut().zip(z) {
        *p = p.max(v.abs());
    }
}

/// One warning per sensor some of whose components' largest reading rounds, as a single, by
/// more than [`NOISE_FRACTION`] of that component's noise σ; none when the scenario sends
/// doubles (`reals = "f64"`). Each names the sensor, the reading, the rounding and σ, and says
/// what to change.
pub fn rounding_warnings(exp: &Experiment, peaks: &[f64]) -> Vec<String> {
    if !exp.reals.is_f32() {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut c = 0;
    for (i, sensor) in exp.system.sensors.iter().enumerate() {
        let r = sensor.noise_cov();
        // The component whose rounding is largest against its σ.
        let mut worst: Option<(f64, usize, f64, f64)> = None;
        for j in 0..sensor.meas_dim() {
            let (peak, sigma) = (peaks.get(c + j).copied().unwrap_or(0.0), r[(j, j)].sqrt());
            let half = half_ulp_f32(peak);
            let ratio = half / sigma;
            if ratio > NOISE_FRACTION && worst.is_none_or(|w| ratio > w.0) {
                worst = Some((ratio, j, peak, sigma));
            }
        }
        c += sensor.meas_dim();
        if let Some((_, j, peak, sigma)) = worst {
            let component = if sensor.meas_dim() > 1 {
                format!(" (component {j})")
            } else {
                String::new()
            };
            out.push(format!(
                "sensor {i}{component}: readings reach {}, where a 32-bit single rounds by up to ±{}, more than {NOISE_FRACTION} of its noise σ = {}: readings sent as singles lose accuracy to rounding, and a filter that trusts σ is overconfident; set reals = \"f64\" (64 bits per real), or measure from an offset that keeps the readings small (the rounding is relative, so a change of scale alone does not help)",
                short(peak),
                short(half_ulp_f32(peak)),
                short(sigma)
            ));
        }
    }
    out
}

/// `x` in a few significant digits: plain between 1e-3 and 1e5, scientific beyond.
fn short(x: f64) -> String {
    if x == 0.0 || (1e-3..1e5).contains(&x.abs()) {
        let s = format!("{x:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{x:.3e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_ulp_by_hand() {
        // 1 as a single: the next single is 1 + 2^-23.
        assert_eq!(half_ulp_f32(1.0), 0.5 * 2f64.powi(-23));
        assert_eq!(half_ulp_f32(-1.0), 0.5 * 2f64.powi(-23));
        // 1e8 lies in [2^26, 2^27): a unit in the last place is 2^(26-23) = 8.
        assert_eq!(half_ulp_f32(1e8), 4.0);
        assert_eq!(half_ulp_f32(1e39), f64::INFINITY);
        assert!(half_ulp_f32(0.0) > 0.0 && half_ulp_f32(0.0) < 1e-44);
    }

    #[test]
    fn short_numbers() {
        assert_eq!(short(4.0), "4");
        assert_eq!(short(1.0), "1");
        assert_eq!(short(0.25), "0.25");
        assert_eq!(short(4.883e8), "4.883e8");
    }

    #[test]
    fn peaks_take_the_largest_magnitude_per_component() {
        let v = |x: &[f64]| Vector::from_column_slice(x);
        let m = vec![
            vec![v(&[1.0]), v(&[-3.0, 2.0])],
            vec![v(&[-5.0]), v(&[1.0, f64::NAN])],
        ];
        let mut peaks = Vec::new();
        note_peaks(&m, &mut peaks);
        assert_eq!(peaks, vec![5.0, 3.0, 2.0]);
        note_peaks(&[vec![v(&[6.0]), v(&[0.0, 0.0])]], &mut peaks);
        assert_eq!(peaks, vec![6.0, 3.0, 2.0]);
    }
}
