//! Reproductions that are computations, not Monte Carlo runs: Zhang et al.'s (2016) bandwidth tables
//! (Tables 1-6) and its covariance-correction coefficients (Table 7). The paper's printed
//! values live in the report's TOML file; ours are computed here by the codecs and quantizers
//! themselves.
use crate::link::codec802154::{self, strategy_table, Strategy, MPDU_OCTETS, PPDU_OCTETS};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// A table report file: which computation, and the paper's numbers.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TableReportFile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// `zhang-tables` or `zhang-table7`.
    pub report: String,
    pub citation: String,
    #[serde(default)]
    pub notes: Vec<String>,
    /// Printed values: `table`, `row` (as in [`computed`]), `value`, and `decimals` printed.
    pub published: Vec<PrintedValue>,
}

/// One printed number.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PrintedValue {
    pub table: String,
    pub row: String,
    pub value: f64,
    /// Decimals the paper prints (0 for integers); ours is rounded the same way to compare.
    #[serde(default)]
    pub decimals: u32,
}

/// Our value beside the paper's.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TableComparison {
    pub table: String,
    pub row: String,
    pub paper: f64,
    pub ours: Option<f64>,
    pub matches: bool,
}

/// Every value we compute for a report, keyed by (table, row).
pub fn computed(report: &str) -> Result<Vec<(String, String, f64)>, String> {
    let mut v = Vec::new();
    match report {
        "zhang-tables" => {
            for (table, strategy) in [
                ("Table 2", Strategy::FlagZone),
                ("Table 4", Strategy::NoFlagZone),
            ] {
                for row in codec802154::scheme_table(strategy, 3) {
                    v.push((
                        table.to_string(),
                        format!("L for c_i <= {}", row.max_payload_bits),
                        row.levels as f64,
                    ));
                }
            }
            for (table, rows) in [
                ("Table 5", codec802154::table_5()),
                ("Table 6", codec802154::table_6()),
            ] {
                for r in rows {
                    let l = r.levels;
                    v.push((
                        table.to_string(),
                        format!("Zhang c_i at L = {l}"),
                        f64::from(r.zhang),
                    ));
                    v.push((
                        table.to_string(),
                        format!("You c_i at L = {l}"),
                        f64::from(r.you),
                    ));
                    v.push((
                        table.to_string(),
                        format!("Msechu c_i at L = {l}"),
                        f64::from(r.msechu),
                    ));
                }
            }
        }
        "zhang-table7" => {
            for r in codec802154::table_7().map_err(|e| e.to_string())? {
                let c = r.max_payload_bits;
                v.push(("Table 7".into(), format!("Zhang rho, c_i <= {c}"), r.zhang));
                v.push(("Table 7".into(), format!("You rho, c_i <= {c}"), r.you));
                v.push((
                    "Table 7".into(),
                    format!("Msechu rho, c_i <= {c}"),
                    r.msechu,
                ));
            }
        }
        other => {
            return Err(format!(
                "unknown report {other:?}; expected zhang-tables or zhang-table7"
            ))
        }
    }
    Ok(v)
}

/// Compares the paper's printed values with ours, rounded to the printed decimals. A printed
/// value naming a (table, row) we do not compute is refused, with the valid rows listed.
pub fn compare(file: &TableReportFile) -> Result<Vec<TableComparison>, String> {
    let ours = computed(&file.report)?;
    for (i, p) in file.published.iter().enumerate() {
        if !ours.iter().any(|(t, r, _)| *t == p.table && *r == p.row) {
            let valid: String = ours
                .iter()
                .map(|(t, r, _)| format!("\n  table = {t:?}, row = {r:?}"))
                .collect();
            let what = if ours.iter().any(|(t, _, _)| *t == p.table) {
                format!("no row {:?} in table {:?}", p.row, p.table)
            } else {
                format!("no table {:?} (row {:?})", p.table, p.row)
            };
            return Err(format!(
                "field `published[{i}]`: {what}; report {:?} has these rows:{valid}",
                file.report
            ));
        }
    }
    Ok(file
        .published
        .iter()
        .map(|p| {
            let value = ours
                .iter()
                .find(|(t, r, _)| *t == p.table && *r == p.row)
                .map(|(_, _, v)| *v);
            let scale = 10f64.powi(p.decimals as i32);
            let matches = value
                .is_some_and(|v| ((v * scale).round() - (p.value * scale).round()).abs() < 0.5);
            TableComparison {
                table: p.table.clone(),
                row: p.row.clone(),
                paper: p.value,
                ours: value,
                matches,
            }
        })
        .collect())
}

/// Human-readable report, with Tables 1 and 3 as our codec lays them out.
pub fn render(file: &TableReportFile, rows: &[TableComparison]) -> String {
    let mut out = format!("Reproducing: {}\n", file.citation);
    for n in &file.notes {
        let _ = writeln!(out, "  note: {n}");
    }
    let _ = writeln!(
        out,
        "\n{:<8} {:<28} {:>10} {:>12}  match",
        "table", "row", "paper", "ours"
    );
    for r in rows {
        let dec = file
            .published
            .iter()
            .find(|p| p.table == r.table && p.row == r.row)
            .map_or(0, |p| p.decimals as usize);
        let ours = r.ours.map_or("missing".to_string(), |v| {
            format!(
                "{v:.prec$}",
                prec = dec.max(if dec > 0 { dec + 2 } else { 0 })
            )
        });
        let _ = writeln!(
            out,
            "{:<8} {:<28} {:>10.prec$} {:>12}  {}",
            r.table,
            r.row,
            r.paper,
            ours,
            if r.matches { "yes" } else { "NO" },
            prec = dec
        );
    }
    let matched = rows.iter().filter(|r| r.matches).count();
    let _ = writeln!(
        out,
        "\n{matched} of {} printed values reproduced.",
        rows.len()
    );
    if file.report == "zhang-tables" {
        for (name, strategy) in [
            ("Table 1 (with flag zone)", Strategy::FlagZone),
            ("Table 3 (without flag zone)", Strategy::NoFlagZone),
        ] {
            let _ = writeln!(out, "\n{name}, as our codec lays it out:\n  flag  a_i  quantization zone                          b_i  c_i");
            for r in strategy_table(strategy, 3) {
                let _ = writeln!(
                    out,
                    "  {:<5} {:>3}  {:<42} {:>3}  {:>3}",
                    r.flag,
                    r.flag_bits,
                    r.quantization_zone(),
                    r.quant_bits,
                    r.payload_bits
                );
            }
        }
        let _ = writeln!(
            out,
            "\nOn air every non-silent message is one {MPDU_OCTETS}-octet 802.15.4 MAC frame ({} bits; {} bits with PHY preamble, SFD and PHR), whatever its payload c_i: the savings of Tables 5-6 are in the payload, and only silence saves a frame.",
            8 * MPDU_OCTETS,
            8 * PPDU_OCTETS
        );
    }
    out
}
