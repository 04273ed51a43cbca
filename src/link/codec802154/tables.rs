//! The paper's tables as data: ZLL Tables 1 and 3 (the zone layouts of the dynamic strategy),
//! 2 and 4 (the transmission schemes), 5 and 6 (payload bits at equal level count against the
//! baselines) and 7 (`ρ`, eq. (16), at equal payload budget), each derived from the codecs' own
//! arithmetic, so that a CLI can print them and the tests can compare them with the printed
//! paper. Apart from the codecs because nothing on the link uses them.
use super::dynamic::{Strategy, ZoneCode, ZoneLayout, MAX_ZONE_BITS};
use super::fixed::{msechu_payload_bits, you_payload_bits};
use crate::link::quantizer::{
    InnovationQuantizer, MsechuQuantizer, QuantizerError, YouQuantizer, ZhangQuantizer,
};

/// One row of ZLL Table 1 (or Table 3, where `flag` is always empty).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StrategyRow {
    /// Flag-zone bits as printed (`""`, `"0"`, `"01"`, …).
    pub flag: String,
    /// `a_i`.
    pub flag_bits: u8,
    /// First and last magnitude `t` of the quantization-zone group.
    pub magnitudes: (usize, usize),
    /// `b_i`.
    pub quant_bits: u8,
    /// `c_i = a_i + b_i`.
    pub payload_bits: u8,
}

impl StrategyRow {
    /// The "Quantization zone" cell, e.g. `±λ_2^{b,p}, ±λ_3^{b,p}`.
    pub fn quantization_zone(&self) -> String {
        (self.magnitudes.0..=self.magnitudes.1)
            .map(|t| format!("±λ_{t}^{{b,p}}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Rows of Table 1 ([`Strategy::FlagZone`]) or Table 3 ([`Strategy::NoFlagZone`]) up to
/// `c_max` payload bits, derived from the codec's own zone arithmetic.
pub fn strategy_table(strategy: Strategy, c_max: u8) -> Vec<StrategyRow> {
    let mut rows = Vec::new();
    for c in 1..=c_max.min(MAX_ZONE_BITS) {
        let flag_lengths = match strategy {
            Strategy::FlagZone => 0..c,
            Strategy::NoFlagZone => 0..1,
        };
        for a in flag_lengths {
            let b = c - a;
            for flag in 0..(1u16 << a) {
                let layout = ZoneLayout {
                    flag_bits: a,
                    quant_bits: b,
                };
                let code = |offset: u8| ZoneCode {
                    layout,
                    flag: flag as u8,
                    offset,
                };
                let last = ((1u16 << (b - 1)) - 1) as u8;
                let (Some(first_t), Some(last_t)) =
                    (strategy.magnitude(code(0)), strategy.magnitude(code(last)))
                else {
                    continue;
                };
                rows.push(StrategyRow {
                    flag: (0..a)
                        .rev()
                        .map(|k| if flag >> k & 1 == 1 { '1' } else { '0' })
                        .collect(),
                    flag_bits: a,
                    magnitudes: (first_t, last_t),
                    quant_bits: b,
                    payload_bits: c,
                });
            }
        }
    }
    rows
}

/// ZLL Table 1 (dynamic transmission strategy).
pub fn table_1() -> Vec<StrategyRow> {
    strategy_table(Strategy::FlagZone, 3)
}

/// ZLL Table 3 (dynamic transmission strategy without flag zone).
pub fn table_3() -> Vec<StrategyRow> {
    strategy_table(Strategy::NoFlagZone, 3)
}

/// One row of ZLL Table 2 / Table 4.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SchemeRow {
    /// Largest magnitude `l`: `d ∈ {0, ±λ_1^{b,p}, …, ±λ_l^{b,p}}`.
    pub max_magnitude: usize,
    /// `L = 4l + 1`.
    pub levels: usize,
    /// `c_i ≤ this`.
    pub max_payload_bits: u8,
}

impl SchemeRow {
    /// The `d_k^i` cell, e.g. `{0, ±λ_1^{b,p}, …, ±λ_5^{b,p}}`.
    pub fn symbol_set(&self) -> String {
        match self.max_magnitude {
            1 => "{0, ±λ_1^{b,p}}".to_string(),
            l => format!("{{0, ±λ_1^{{b,p}}, …, ±λ_{l}^{{b,p}}}}"),
        }
    }
}

/// Rows of Table 2 / Table 4 for `c_max = 1..=max_bits`.
pub fn scheme_table(strategy: Strategy, max_bits: u8) -> Vec<SchemeRow> {
    (1..=max_bits)
        .map(|c| SchemeRow {
            max_magnitude: strategy.max_magnitude(c),
            levels: strategy.levels(c),
            max_payload_bits: c,
        })
        .collect()
}

/// ZLL Table 2 (transmission scheme).
pub fn table_2() -> Vec<SchemeRow> {
    scheme_table(Strategy::FlagZone, 3)
}

/// ZLL Table 4 (transmission scheme without flag zone).
pub fn table_4() -> Vec<SchemeRow> {
    scheme_table(Strategy::NoFlagZone, 3)
}

/// One row of ZLL Table 5 / Table 6: maximal payload bits at equal level count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BandwidthRow {
    /// `L`.
    pub levels: usize,
    /// ZLL's dynamic strategy.
    pub zhang: u8,
    /// You et al. (`L = 2^c + 1`).
    pub you: u8,
    /// Msechu et al. (`L = 2^c`).
    pub msechu: u8,
}

/// Rows for the given level counts (each of the form `4l + 1`, at least 5).
pub fn bandwidth_table(strategy: Strategy, levels: &[usize]) -> Option<Vec<BandwidthRow>> {
    levels
        .iter()
        .map(|&l| {
            Some(BandwidthRow {
                levels: l,
                zhang: strategy.payload_bits_for_levels(l)?,
                you: you_payload_bits(l)?,
                msechu: msechu_payload_bits(l)?,
            })
        })
        .collect()
}

/// ZLL Table 5 (L = 5, 21; with flag zone).
pub fn table_5() -> Vec<BandwidthRow> {
    bandwidth_table(Strategy::FlagZone, &[5, 21]).expect("5 and 21 are of the form 4l + 1")
}

/// ZLL Table 6 (L = 5, 13; without flag zone).
pub fn table_6() -> Vec<BandwidthRow> {
    bandwidth_table(Strategy::NoFlagZone, &[5, 13]).expect("5 and 13 are of the form 4l + 1")
}

/// One row of ZLL Table 7: `ρ` (eq. (16)) at equal payload budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RhoRow {
    /// `c_i ≤ this`.
    pub max_payload_bits: u8,
    /// ZLL, with flag zone (`L` of Table 2).
    pub zhang: f64,
    /// You et al. (`2^c + 1` levels).
    pub you: f64,
    /// Msechu et al. (`2^c` levels).
    pub msechu: f64,
}

/// ZLL Table 7 (`c ≤ 1, 2`), computed from the Lloyd-Max designs.
pub fn table_7() -> Result<Vec<RhoRow>, QuantizerError> {
    (1..=2u8)
        .map(|c| {
            let l = Strategy::FlagZone.max_magnitude(c) as u16;
            Ok(RhoRow {
                max_payload_bits: c,
                zhang: ZhangQuantizer::new(l)?.rho(),
                you: YouQuantizer::new(c)?.rho(),
                msechu: MsechuQuantizer::new(c)?.rho(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::tests::link;
    use super::super::*;

    /// ZLL Table 1 as printed: (flag zone, a_i, quantization zone t-range, b_i, c_i).
    /// (flag zone, a_i, quantization-zone magnitudes, b_i, c_i)
    type Table1Row<'a> = (&'a str, u8, (usize, usize), u8, u8);

    #[test]
    fn table_1_as_printed() {
        let printed: [Table1Row; 11] = [
            ("", 0, (1, 1), 1, 1),
            ("", 0, (2, 3), 2, 2),
            ("0", 1, (4, 4), 1, 2),
            ("1", 1, (5, 5), 1, 2),
            ("", 0, (6, 9), 3, 3),
            ("0", 1, (10, 11), 2, 3),
            ("1", 1, (12, 13), 2, 3),
            ("00", 2, (14, 14), 1, 3),
            ("01", 2, (15, 15), 1, 3),
            ("10", 2, (16, 16), 1, 3),
            ("11", 2, (17, 17), 1, 3),
        ];
        let rows = table_1();
        assert_eq!(rows.len(), printed.len());
        for (row, p) in rows.iter().zip(printed) {
            assert_eq!(
                (
                    row.flag.as_str(),
                    row.flag_bits,
                    row.magnitudes,
                    row.quant_bits,
                    row.payload_bits
                ),
                p
            );
        }
        assert_eq!(
            rows[4].quantization_zone(),
            "±λ_6^{b,p}, ±λ_7^{b,p}, ±λ_8^{b,p}, ±λ_9^{b,p}"
        );
    }

    /// ZLL Table 3 as printed: (t-range, b_i, c_i).
    #[test]
    fn table_3_as_printed() {
        let printed = [((1, 1), 1, 1), ((2, 3), 2, 2), ((4, 7), 3, 3)];
        let rows = table_3();
        assert_eq!(rows.len(), 3);
        for (row, p) in rows.iter().zip(printed) {
            assert_eq!(row.flag, "");
            assert_eq!((row.magnitudes, row.quant_bits, row.payload_bits), p);
        }
    }

    /// ZLL Tables 2 and 4 as printed: (l in "±λ_l", L, c_i ≤).
    #[test]
    fn tables_2_and_4_as_printed() {
        let t2 = [(1, 5, 1), (5, 21, 2), (17, 69, 3)];
        let t4 = [(1, 5, 1), (3, 13, 2), (7, 29, 3)];
        for (rows, printed) in [(table_2(), t2), (table_4(), t4)] {
            assert_eq!(rows.len(), 3);
            for (row, p) in rows.iter().zip(printed) {
                assert_eq!((row.max_magnitude, row.levels, row.max_payload_bits), p);
            }
        }
        assert_eq!(table_2()[0].symbol_set(), "{0, ±λ_1^{b,p}}");
        assert_eq!(table_2()[1].symbol_set(), "{0, ±λ_1^{b,p}, …, ±λ_5^{b,p}}");
        // The codecs realize them: a c_max codec carries exactly L levels.
        for (s, rows) in [
            (Strategy::FlagZone, table_2()),
            (Strategy::NoFlagZone, table_4()),
        ] {
            for row in rows {
                let codec = DynamicCodec::new(s, row.max_payload_bits, link()).unwrap();
                assert_eq!(codec.levels(), row.levels);
            }
        }
    }

    /// ZLL Tables 5 and 6 as printed: (L, Zhang, You, Msechu).
    #[test]
    fn tables_5_and_6_as_printed() {
        let t5 = [(5, 1, 2, 3), (21, 2, 5, 5)];
        let t6 = [(5, 1, 2, 3), (13, 2, 4, 4)];
        for (rows, printed) in [(table_5(), t5), (table_6(), t6)] {
            assert_eq!(rows.len(), 2);
            for (row, p) in rows.iter().zip(printed) {
                assert_eq!((row.levels, row.zhang, row.you, row.msechu), p);
            }
        }
        // And the fixed-length codecs realize the baseline columns.
        for l in [5, 13, 21] {
            let you = FixedLengthCodec::new(l, true, link()).unwrap();
            let msechu = FixedLengthCodec::new(l, false, link()).unwrap();
            assert_eq!(Some(you.max_payload_bits()), you_payload_bits(l));
            assert_eq!(Some(msechu.max_payload_bits()), msechu_payload_bits(l));
        }
        assert_eq!(bandwidth_table(Strategy::FlagZone, &[6]), None);
    }

    /// ZLL Table 7, printed to 4 decimals.
    #[test]
    #[allow(clippy::approx_constant)] // 0.6366 is the paper's printed ρ, not a stand-in for 2/π
    fn table_7_as_printed() {
        let printed = [(1, 0.9201, 0.8098, 0.6366), (2, 0.9943, 0.9201, 0.8825)];
        let rows = table_7().unwrap();
        assert_eq!(rows.len(), 2);
        for (row, p) in rows.iter().zip(printed) {
            assert_eq!(row.max_payload_bits, p.0);
            assert!((row.zhang - p.1).abs() <= 5e-5);
            assert!((row.you - p.2).abs() <= 5e-5);
            assert!((row.msechu - p.3).abs() <= 5e-5);
        }
    }
}
