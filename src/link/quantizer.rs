//! Sensor-side quantizers of the normalized innovation `ψ = (y - ŷ_{k|k-1}) / Δ`
//! (eq. (3) of Zhang, Li & Liu, Sci China Inf Sci 59:022316, 2016, "ZLL" below).
//!
//! Every quantizer here is a partition of the real line into cells `(τ_j, τ_{j+1}]`; what
//! the fusion centre needs about a received (or inferred) level is only its cell, through
//! the conditional mean `σ` of eq. (14)/(A28) (our [`InnovationQuantizer::reconstruction`])
//! and the covariance factor `η` of eq. (11)/(A30) ([`InnovationQuantizer::eta`]). The
//! schemes differ in how many cells they have, which thresholds they use and which cell
//! is *silent* (nothing is sent and the fusion centre infers that cell from the silence):
//!
//! | type | levels | silent level | paper |
//! |---|---|---|---|
//! | [`SignQuantizer`] | 2 (`sign ψ`) | none | SOI-KF, Ribeiro et al. (ZLL ref. \[7\]) |
//! | [`MsechuQuantizer`] | `2^c` | none | Msechu et al. (ZLL ref. \[8\]/\[9\]) |
//! | [`YouQuantizer`] | `2^c + 1` | the centre | You et al. (ZLL ref. \[10\]/\[11\]) |
//! | [`ZhangQuantizer`] | `4l + 1` | the centre | ZLL eq. (5) |
//!
//! All thresholds are Lloyd-Max thresholds for `N(0, 1)`: ZLL §3.1 says so for eq. (5), and
//! for the baselines the values of ZLL Table 7 (`ρ` = 0.6366, 0.8825 for `2^c`, 0.8098,
//! 0.9201 for `2^c + 1` levels) are exactly `1 - MSE` of the Lloyd-Max quantizers with
//! those level counts. That is no accident: with centroid reconstruction `MSE = 1 - ρ`, so
//! maximizing the covariance reduction `ρ` (Msechu et al.'s criterion) *is* Lloyd-Max.
//! The sign quantizer is the 2-level member of the family (threshold 0, levels
//! `±sqrt(2/π)`, `ρ = 2/π`).
//!
//! Levels are numbered `0..L` in increasing order of their cells; all methods are
//! allocation-free (tables are built once by the constructors).

use crate::stats::lloyd_max::{cell_moments, CellMoments, LloydMax, LloydMaxError, MAX_LEVELS};

/// A quantization level: the 0-based index of its cell, cells in increasing order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Level(u16);

impl Level {
    /// The level with cell index `index`.
    pub const fn new(index: u16) -> Self {
        Level(index)
    }

    /// The cell index.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// How a non-silent level of eq. (5) travels: ZLL §3.1 and Remark 1 — the same payload
/// means a different level depending on whether the frame was broadcast or sent
/// peer-to-peer, and the mode is read from the MAC header (see the codec module).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TxMode {
    /// Broadcast (`λ^b` levels).
    Broadcast,
    /// Peer-to-peer, i.e. unicast to the fusion centre (`λ^p` levels).
    PeerToPeer,
}

/// Why a quantizer could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum QuantizerError {
    /// The Lloyd-Max design failed.
    #[error(transparent)]
    Design(#[from] LloydMaxError),
    /// Thresholds must be finite and strictly increasing and leave every cell a
    /// representable probability.
    #[error("thresholds must be finite, strictly increasing, with non-negligible cells")]
    BadThresholds,
    /// Bit budget outside `1..=8`.
    #[error("bit budget {0} outside 1..=8")]
    BadBits(u8),
    /// Number of magnitudes `l` of eq. (5) outside `1..=(MAX_LEVELS - 1) / 4`.
    #[error("eq. (5) needs 1 <= l <= {max}, got {l}")]
    BadMagnitudes {
        /// Requested `l`.
        l: u16,
        /// Largest supported `l`.
        max: u16,
    },
}

/// The cells of a scalar quantizer with everything the fusion centre needs per cell,
/// precomputed: probability, conditional mean (`σ`, eq. (14)) and `η` (eq. (11)).
#[derive(Debug, Clone, PartialEq)]
pub struct CellTable {
    thresholds: Vec<f64>,
    moments: Vec<CellMoments>,
    rho: f64,
}

impl CellTable {
    /// Cells from `L - 1` finite, strictly increasing thresholds (any partition, not
    /// necessarily Lloyd-Max: reconstruction is always the cell's conditional mean).
    pub fn from_thresholds(thresholds: Vec<f64>) -> Result<Self, QuantizerError> {
        if thresholds.len() + 1 > MAX_LEVELS
            || thresholds.iter().any(|t| !t.is_finite())
            || thresholds.windows(2).any(|w| w[0] >= w[1])
        {
            return Err(QuantizerError::BadThresholds);
        }
        let levels = thresholds.len() + 1;
        let mut moments = Vec::with_capacity(levels);
        for i in 0..levels {
            let lo = if i == 0 {
                f64::NEG_INFINITY
            } else {
                thresholds[i - 1]
            };
            let hi = thresholds.get(i).copied().unwrap_or(f64::INFINITY);
            let m = cell_moments(lo, hi);
            if !(m.probability > 0.0 && m.mean.is_finite() && m.eta.is_finite()) {
                return Err(QuantizerError::BadThresholds);
            }
            moments.push(m);
        }
        // ρ of eq. (16): Σ_j P_j σ_j².
        let rho = moments
            .iter()
            .map(|m| m.probability * m.mean * m.mean)
            .sum();
        Ok(Self {
            thresholds,
            moments,
            rho,
        })
    }

    /// The `levels`-level Lloyd-Max quantizer of `N(0, 1)`.
    pub fn lloyd_max(levels: usize) -> Result<Self, QuantizerError> {
        Self::from_thresholds(LloydMax::design(levels)?.thresholds)
    }

    /// Number of levels `L`.
    pub fn levels(&self) -> usize {
        self.moments.len()
    }

    /// The `L - 1` finite thresholds (ZLL's `τ_2 … τ_L`).
    pub fn thresholds(&self) -> &[f64] {
        &self.thresholds
    }

    /// Level whose cell `(lo, hi]` contains `psi` (right-closed as in eq. (5)); NaN is
    /// treated as `0.0`, the innovation's mean, so an upstream numerical failure maps to
    /// the least informative level rather than an extreme one.
    pub fn quantize(&self, psi: f64) -> Level {
        let psi = if psi.is_nan() { 0.0 } else { psi };
        // At most MAX_LEVELS - 1 < u16::MAX thresholds, so the index fits.
        Level(self.thresholds.partition_point(|&t| t < psi) as u16)
    }

    /// The cell `(lo, hi]` of `level`, with infinite outer ends.
    ///
    /// # Panics
    /// If `level.index() >= self.levels()`.
    pub fn cell(&self, level: Level) -> (f64, f64) {
        let i = level.index();
        assert!(i < self.levels(), "level {i} out of range");
        let lo = if i == 0 {
            f64::NEG_INFINITY
        } else {
            self.thresholds[i - 1]
        };
        let hi = self.thresholds.get(i).copied().unwrap_or(f64::INFINITY);
        (lo, hi)
    }

    /// Probability, conditional mean and `η` of `level`'s cell.
    ///
    /// # Panics
    /// If `level.index() >= self.levels()`.
    pub fn moments(&self, level: Level) -> CellMoments {
        self.moments[level.index()]
    }

    /// `ρ` of eq. (16).
    pub fn rho(&self) -> f64 {
        self.rho
    }
}

/// What the fusion code needs from a sensor-side quantizer of the normalized innovation.
///
/// Object safe, so fusion code can hold a `&dyn InnovationQuantizer`. Methods taking a
/// [`Level`] panic if it is out of range for this quantizer (a programming error: levels
/// come from [`quantize`](Self::quantize) or from a codec built for the same quantizer).
pub trait InnovationQuantizer {
    /// The cell table (thresholds and per-cell moments).
    fn table(&self) -> &CellTable;

    /// True for the level that is never transmitted (its reception is inferred from
    /// silence, ZLL §3.1: "In the case of `d = 0`, there will be no transmission").
    fn is_silent(&self, level: Level) -> bool;

    /// Number of levels `L`.
    fn levels(&self) -> usize {
        self.table().levels()
    }

    /// `d = q[ψ]`, eq. (4).
    fn quantize(&self, normalized_innovation: f64) -> Level {
        self.table().quantize(normalized_innovation)
    }

    /// Cell `(τ_j, τ_{j+1}]` of a level.
    fn cell(&self, level: Level) -> (f64, f64) {
        self.table().cell(level)
    }

    /// What the fusion centre uses in place of `ψ`: `σ = E[ψ | ψ ∈ cell]`, eq. (14)/(A28).
    /// For Lloyd-Max thresholds this equals the Lloyd-Max reconstruction level; the value
    /// of the symbols `λ` in eq. (5) never enters the filter.
    fn reconstruction(&self, level: Level) -> f64 {
        self.table().moments(level).mean
    }

    /// `η = 1 - Var[ψ | ψ ∈ cell]`, eq. (11)/(A30): the covariance update (10) is the
    /// analog Kalman update scaled by `η`.
    fn eta(&self, level: Level) -> f64 {
        self.table().moments(level).eta
    }

    /// Prior probability `Φ(τ_{j+1}) - Φ(τ_j)` of a level.
    fn probability(&self, level: Level) -> f64 {
        self.table().moments(level).probability
    }

    /// `ρ` of eq. (16): the expected covariance-reduction factor (`E[η]`), 1 for analog.
    fn rho(&self) -> f64 {
        self.table().rho()
    }

    /// Probability that nothing is transmitted.
    fn silence_probability(&self) -> f64 {
        (0..self.levels())
            .map(|i| Level(i as u16))
            .filter(|&l| self.is_silent(l))
            .map(|l| self.probability(l))
            .sum()
    }
}

/// SOI-KF's quantizer (Ribeiro, Giannakis & Roumeliotis 2006; ZLL ref. \[7\]): the sign of
/// the innovation, one bit, always transmitted. The fusion centre's `σ` is
/// `±sqrt(2/π)` and `ρ = 2/π ≈ 0.6366` (ZLL Table 7, Msechu column, `c ≤ 1`).
#[derive(Debug, Clone, PartialEq)]
pub struct SignQuantizer {
    table: CellTable,
}

impl SignQuantizer {
    /// The sign quantizer (threshold 0).
    pub fn new() -> Self {
        Self {
            table: CellTable::from_thresholds(vec![0.0])
                .expect("a single threshold at 0 is a valid partition"),
        }
    }
}

impl Default for SignQuantizer {
    fn default() -> Self {
        Self::new()
    }
}

impl InnovationQuantizer for SignQuantizer {
    fn table(&self) -> &CellTable {
        &self.table
    }
    fn is_silent(&self, _level: Level) -> bool {
        false
    }
}

fn check_bits(bits: u8) -> Result<(), QuantizerError> {
    if (1..=8).contains(&bits) {
        Ok(())
    } else {
        Err(QuantizerError::BadBits(bits))
    }
}

/// Msechu et al.'s `c`-bit quantizer (ZLL §4.1: `L = 2^c`): `2^c` Lloyd-Max cells, every
/// level transmitted with `c` bits. With `c = 1` it coincides with [`SignQuantizer`].
#[derive(Debug, Clone, PartialEq)]
pub struct MsechuQuantizer {
    bits: u8,
    table: CellTable,
}

impl MsechuQuantizer {
    /// `bits` in `1..=8`.
    pub fn new(bits: u8) -> Result<Self, QuantizerError> {
        check_bits(bits)?;
        Ok(Self {
            bits,
            table: CellTable::lloyd_max(1 << bits)?,
        })
    }

    /// Bits per transmission `c`.
    pub fn bits(&self) -> u8 {
        self.bits
    }
}

impl InnovationQuantizer for MsechuQuantizer {
    fn table(&self) -> &CellTable {
        &self.table
    }
    fn is_silent(&self, _level: Level) -> bool {
        false
    }
}

/// You et al.'s `c`-bit quantizer (ZLL §4.1: `L = 2^c + 1`): `2^c + 1` Lloyd-Max cells; the
/// centre cell (around 0) is not transmitted, the other `2^c` levels are sent with `c` bits.
#[derive(Debug, Clone, PartialEq)]
pub struct YouQuantizer {
    bits: u8,
    table: CellTable,
}

impl YouQuantizer {
    /// `bits` in `1..=8`.
    pub fn new(bits: u8) -> Result<Self, QuantizerError> {
        check_bits(bits)?;
        Ok(Self {
            bits,
            table: CellTable::lloyd_max((1 << bits) + 1)?,
        })
    }

    /// Bits per transmission `c`.
    pub fn bits(&self) -> u8 {
        self.bits
    }

    /// The silent centre level.
    pub fn silent_level(&self) -> Level {
        Level(1 << (self.bits - 1))
    }
}

impl InnovationQuantizer for YouQuantizer {
    fn table(&self) -> &CellTable {
        &self.table
    }
    fn is_silent(&self, level: Level) -> bool {
        level == self.silent_level()
    }
}

/// A non-silent level of eq. (5): `±λ_t^b` or `±λ_t^p`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ZhangSymbol {
    /// Magnitude index `t` in `1..=l` (1 is nearest to the silent centre).
    pub magnitude: u16,
    /// True for a negative innovation.
    pub negative: bool,
    /// Transmission mode, which tells `λ_t^b` from `λ_t^p`.
    pub mode: TxMode,
}

/// Largest `l` with `4l + 1 ≤ MAX_LEVELS`.
pub const MAX_ZHANG_MAGNITUDES: u16 = ((MAX_LEVELS - 1) / 4) as u16;

/// Symbol of `level` in the `4l + 1`-level quantizer of eq. (5); `None` for the silent
/// centre or an out-of-range level.
///
/// Layout (eq. (5)): going outward from the silent centre cell, the cells are
/// `λ_1^p, λ_1^b, λ_2^p, λ_2^b, …, λ_l^p, λ_l^b` on each side, i.e. for each magnitude the
/// peer-to-peer level is the inner one. Sign: eq. (5) as printed labels the cells left of
/// the centre `+λ` and those right of it `-λ`; that only names the symbols (the filter
/// uses the cell through (14) and (11), not `λ`), so here a positive innovation gets a
/// positive symbol.
pub fn zhang_symbol(l: u16, level: Level) -> Option<ZhangSymbol> {
    let centre = 2 * usize::from(l);
    let i = level.index();
    if i > 2 * centre || i == centre {
        return None;
    }
    let k = i.abs_diff(centre); // 1..=2l, outward position
    Some(ZhangSymbol {
        magnitude: k.div_ceil(2) as u16,
        negative: i < centre,
        mode: if k % 2 == 1 {
            TxMode::PeerToPeer
        } else {
            TxMode::Broadcast
        },
    })
}

/// Inverse of [`zhang_symbol`]; `None` if the magnitude is outside `1..=l`.
pub fn zhang_level(l: u16, symbol: ZhangSymbol) -> Option<Level> {
    if symbol.magnitude == 0 || symbol.magnitude > l {
        return None;
    }
    let k = 2 * symbol.magnitude - u16::from(symbol.mode == TxMode::PeerToPeer);
    let centre = 2 * l;
    Some(Level(if symbol.negative {
        centre - k
    } else {
        centre + k
    }))
}

/// ZLL's quantizer, eq. (5): `L = 4l + 1` Lloyd-Max cells; the centre one (`d = 0`) is not
/// transmitted, each of the others is a magnitude `t`, a sign and a transmission mode.
#[derive(Debug, Clone, PartialEq)]
pub struct ZhangQuantizer {
    l: u16,
    table: CellTable,
}

impl ZhangQuantizer {
    /// The quantizer with `l` magnitudes per sign and mode (`L = 4l + 1`), `l` in
    /// `1..=MAX_ZHANG_MAGNITUDES`. ZLL Table 2 uses `l = 1, 5, 17`; Table 4 `l = 1, 3, 7`.
    pub fn new(l: u16) -> Result<Self, QuantizerError> {
        if l == 0 || l > MAX_ZHANG_MAGNITUDES {
            return Err(QuantizerError::BadMagnitudes {
                l,
                max: MAX_ZHANG_MAGNITUDES,
            });
        }
        Ok(Self {
            l,
            table: CellTable::lloyd_max(4 * usize::from(l) + 1)?,
        })
    }

    /// Magnitudes per sign and mode, `l`.
    pub fn magnitudes(&self) -> u16 {
        self.l
    }

    /// The silent centre level (`d = 0`).
    pub fn silent_level(&self) -> Level {
        Level(2 * self.l)
    }

    /// `±λ_t^{b,p}` of a level; `None` for the silent level.
    ///
    /// # Panics
    /// If the level is out of range.
    pub fn symbol(&self, level: Level) -> Option<ZhangSymbol> {
        assert!(level.index() < self.levels(), "level out of range");
        zhang_symbol(self.l, level)
    }

    /// Level of a symbol; `None` if its magnitude is not in `1..=l`.
    pub fn level(&self, symbol: ZhangSymbol) -> Option<Level> {
        zhang_level(self.l, symbol)
    }

    /// Transmission mode of a level; `None` for the silent level.
    pub fn mode(&self, level: Level) -> Option<TxMode> {
        self.symbol(level).map(|s| s.mode)
    }
}

impl InnovationQuantizer for ZhangQuantizer {
    fn table(&self) -> &CellTable {
        &self.table
    }
    fn is_silent(&self, level: Level) -> bool {
        level == self.silent_level()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn all_quantizers() -> Vec<Box<dyn InnovationQuantizer>> {
        let mut v: Vec<Box<dyn InnovationQuantizer>> = vec![Box::new(SignQuantizer::new())];
        for c in 1..=8 {
            v.push(Box::new(MsechuQuantizer::new(c).unwrap()));
            v.push(Box::new(YouQuantizer::new(c).unwrap()));
        }
        for l in [1, 2, 3, 5, 7, 17, MAX_ZHANG_MAGNITUDES] {
            v.push(Box::new(ZhangQuantizer::new(l).unwrap()));
        }
        v
    }

    #[test]
    fn quantize_lands_in_its_cell() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x9a17_0002);
        for q in all_quantizers() {
            for _ in 0..10_000 {
                // Mostly N(0,1)-scale values plus some far out.
                let x: f64 = if rng.random_bool(0.9) {
                    rng.random_range(-4.0..4.0)
                } else {
                    rng.random_range(-40.0..40.0)
                };
                let level = q.quantize(x);
                assert!(level.index() < q.levels());
                let (lo, hi) = q.cell(level);
                assert!(lo < x && x <= hi, "x={x} level {level:?} cell ({lo}, {hi}]");
            }
        }
    }

    /// Reconstruction = conditional mean from eq. (14) must equal the Lloyd-Max level
    /// (centroid condition); both are computed independently, agreement to 1e-12 is
    /// rounding level.
    #[test]
    fn reconstruction_is_lloyd_max_level() {
        for l in [1u16, 5, 17] {
            let q = ZhangQuantizer::new(l).unwrap();
            let lm = LloydMax::design(q.levels()).unwrap();
            for i in 0..q.levels() {
                let r = q.reconstruction(Level::new(i as u16));
                assert!((r - lm.levels[i]).abs() < 1e-12);
            }
            assert!((q.rho() - (1.0 - lm.mse())).abs() < 1e-12);
        }
    }

    #[test]
    fn sign_quantizer_is_soi_kf() {
        let q = SignQuantizer::new();
        let a = (2.0 / std::f64::consts::PI).sqrt();
        assert_eq!(q.levels(), 2);
        assert_eq!(q.quantize(-0.1), Level::new(0));
        assert_eq!(q.quantize(0.1), Level::new(1));
        assert!((q.reconstruction(Level::new(1)) - a).abs() < 1e-15);
        assert!((q.reconstruction(Level::new(0)) + a).abs() < 1e-15);
        assert!((q.rho() - 2.0 / std::f64::consts::PI).abs() < 1e-15);
        assert!(!q.is_silent(Level::new(0)) && !q.is_silent(Level::new(1)));
        assert_eq!(q.silence_probability(), 0.0);
        assert_eq!(MsechuQuantizer::new(1).unwrap().table(), q.table());
    }

    /// ZLL Table 7, printed to 4 decimals (so tolerance is half a unit of the last digit).
    #[test]
    #[allow(clippy::approx_constant)] // 0.6366 is the paper's printed ρ, not a stand-in for 2/π
    fn rho_matches_table_7() {
        let close = |x: f64, y: f64| (x - y).abs() <= 5e-5;
        assert!(close(ZhangQuantizer::new(1).unwrap().rho(), 0.9201));
        assert!(close(ZhangQuantizer::new(5).unwrap().rho(), 0.9943));
        assert!(close(YouQuantizer::new(1).unwrap().rho(), 0.8098));
        assert!(close(YouQuantizer::new(2).unwrap().rho(), 0.9201));
        assert!(close(MsechuQuantizer::new(1).unwrap().rho(), 0.6366));
        assert!(close(MsechuQuantizer::new(2).unwrap().rho(), 0.8825));
    }

    #[test]
    fn silent_levels() {
        let z = ZhangQuantizer::new(5).unwrap();
        for i in 0..21u16 {
            assert_eq!(z.is_silent(Level::new(i)), i == 10);
        }
        let y = YouQuantizer::new(2).unwrap();
        for i in 0..5u16 {
            assert_eq!(y.is_silent(Level::new(i)), i == 2);
        }
        // L = 5 Lloyd-Max: silent iff |ψ| ≤ 0.38228, probability 2Φ(0.38228) - 1 ≈ 0.29775.
        let z1 = ZhangQuantizer::new(1).unwrap();
        assert!((z1.silence_probability() - 0.29775).abs() < 1e-5);
        assert_eq!(z1.quantize(0.0), z1.silent_level());
        assert_eq!(z1.reconstruction(z1.silent_level()), 0.0);
    }

    #[test]
    fn zhang_symbols_follow_eq_5() {
        // L = 5: cells from -∞: -λ_1^b, -λ_1^p, 0, +λ_1^p, +λ_1^b.
        let q = ZhangQuantizer::new(1).unwrap();
        let s = |i: u16| q.symbol(Level::new(i));
        let sym = |t, neg, mode| {
            Some(ZhangSymbol {
                magnitude: t,
                negative: neg,
                mode,
            })
        };
        assert_eq!(s(0), sym(1, true, TxMode::Broadcast));
        assert_eq!(s(1), sym(1, true, TxMode::PeerToPeer));
        assert_eq!(s(2), None);
        assert_eq!(s(3), sym(1, false, TxMode::PeerToPeer));
        assert_eq!(s(4), sym(1, false, TxMode::Broadcast));
        // Round trip and counts for a larger l.
        for l in [1u16, 3, 5, 7, 17, MAX_ZHANG_MAGNITUDES] {
            let q = ZhangQuantizer::new(l).unwrap();
            let mut per_mode = [0usize; 2];
            for i in 0..q.levels() {
                let level = Level::new(i as u16);
                match q.symbol(level) {
                    None => assert!(q.is_silent(level)),
                    Some(sym) => {
                        assert!((1..=l).contains(&sym.magnitude));
                        assert_eq!(q.level(sym), Some(level));
                        assert_eq!(sym.negative, q.reconstruction(level) < 0.0);
                        per_mode[usize::from(sym.mode == TxMode::Broadcast)] += 1;
                    }
                }
            }
            assert_eq!(per_mode, [2 * usize::from(l); 2]);
        }
        let bad = ZhangSymbol {
            magnitude: 2,
            negative: false,
            mode: TxMode::Broadcast,
        };
        assert_eq!(zhang_level(1, bad), None);
        assert_eq!(zhang_level(2, bad), Some(Level::new(8)));
        assert_eq!(zhang_symbol(1, Level::new(5)), None);
    }

    #[test]
    fn eta_expectation_is_rho_and_cells_are_probabilities() {
        for q in all_quantizers() {
            let mut p_sum = 0.0;
            let mut e_eta = 0.0;
            for i in 0..q.levels() {
                let level = Level::new(i as u16);
                let (p, eta) = (q.probability(level), q.eta(level));
                assert!(p > 0.0 && eta > 0.0 && eta < 1.0);
                p_sum += p;
                e_eta += p * eta;
            }
            assert!((p_sum - 1.0).abs() < 1e-13);
            assert!((e_eta - q.rho()).abs() < 1e-12);
        }
    }

    #[test]
    fn constructor_errors() {
        assert_eq!(MsechuQuantizer::new(0), Err(QuantizerError::BadBits(0)));
        assert_eq!(YouQuantizer::new(9), Err(QuantizerError::BadBits(9)));
        assert!(ZhangQuantizer::new(0).is_err());
        assert!(ZhangQuantizer::new(MAX_ZHANG_MAGNITUDES + 1).is_err());
        assert_eq!(
            CellTable::from_thresholds(vec![0.0, 0.0]),
            Err(QuantizerError::BadThresholds)
        );
        assert_eq!(
            CellTable::from_thresholds(vec![f64::NAN]),
            Err(QuantizerError::BadThresholds)
        );
        assert_eq!(
            CellTable::from_thresholds(vec![40.0, 41.0]),
            Err(QuantizerError::BadThresholds)
        );
    }
}
