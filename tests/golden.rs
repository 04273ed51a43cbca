//! Refactors and speed-ups change no number: every built-in scenario, run at a few trials,
//! gives a `summary.json` whose bytes hash to the value recorded when it was last changed on
//! purpose. The paper scenarios' hashes were recorded from commit 66c57f1, before the scheme
//! registry redesign (issue 9), and the redesign reproduces them exactly; seed 002's were
//! recorded when it was added.
//!
//! When a change is *meant* to move numbers, rerun with `HUSHFUSE_PRINT_GOLDEN=1 cargo test
//! --release --test golden -- --nocapture`, paste the printed table, and say in the commit
//! which numbers moved and why.
use std::process::Command;

/// (built-in scenario, trials, FNV-1a 64 of summary.json, its length in bytes).
const GOLDEN: &[(&str, usize, u64, usize)] = &[
    ("default", 8, 0x84d787d3825f4f91, 185150),
    ("dormann-fig1", 8, 0x61adf45ae3ccaeed, 1723963),
    ("zhang-fig4", 8, 0x8d7403a05985f0c2, 74953),
    ("zhang-fig5", 8, 0x6eb6cb2173312abe, 75395),
    ("zhang-table7", 8, 0x783ef80a514673b4, 1065),
    ("zhang-tables", 8, 0xdb5625c0f613852d, 2560),
    ("zheng-fig1", 8, 0x009271c7666306d6, 21551),
    ("zheng-fig10-table3", 2, 0x6d5b1e8abf02fbdd, 27607),
    ("zheng-fig2-table1", 8, 0xb65dcb21fcabb5de, 48082),
    ("zheng-fig3", 8, 0x5feaf8b60b1553b6, 26436),
    ("zheng-fig4", 8, 0xa278cb0571fcd683, 21700),
    ("zheng-fig5-table2", 8, 0x6c84d3c03d7ea1b0, 31402),
    ("zheng-fig6", 8, 0xa8d98d61138222ca, 26224),
    ("zheng-fig8", 2, 0xbebc241dcafd5e52, 18205),
    ("zheng-fig9", 2, 0xf274e685a2589ab5, 77196),
    ("zheng-nofb-n4", 8, 0x328997a2e93dd3f5, 42993),
    ("geng-oscillator", 8, 0x8372d0499cc4ae14, 394220),
    ("geng-tracking", 8, 0xe11d54e34653bc3f, 112508),
    ("arena-1d", 4, 0x7061d80bde7a5014, 262809),
    ("arena-nca", 4, 0x713d143c62d15845, 240744),
    ("arena-rss", 4, 0xf60e83ef1a72f429, 39040),
    ("arena-wsn", 4, 0xf0a12315937cc84c, 114139),
    ("arena-tobit", 4, 0x7ee4d06ae840ba3d, 315770),
];

/// FNV-1a, 64 bits: a stable hash written out (std's hasher may change between releases).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[test]
fn every_builtin_summary_is_byte_identical_to_its_record() {
    let dir = tempfile::tempdir().unwrap();
    let print = std::env::var_os("HUSHFUSE_PRINT_GOLDEN").is_some();
    let mut changed = Vec::new();
    for &(id, trials, hash, len) in GOLDEN {
        let out_dir = dir.path().join(id);
        let out = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
            .args(["reproduce", id, "--trials", &trials.to_string(), "--out"])
            .arg(&out_dir)
            .output()
            .expect("binary runs");
        assert_eq!(
            out.status.code(),
            Some(0),
            "{id}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let bytes = std::fs::read(out_dir.join("summary.json")).unwrap();
        let got = fnv1a(&bytes);
        if print {
            println!("    (\"{id}\", {trials}, 0x{got:016x}, {}),", bytes.len());
        }
        if got != hash || bytes.len() != len {
            changed.push(format!(
                "{id}: hash 0x{got:016x} ({} bytes), recorded 0x{hash:016x} ({len} bytes)",
                bytes.len()
            ));
        }
    }
    // Every built-in scenario is covered.
    let listed = Command::new(env!("CARGO_BIN_EXE_hushfuse"))
        .arg("list")
        .output()
        .unwrap();
    for line in String::from_utf8_lossy(&listed.stdout).lines() {
        let id = line.split_whitespace().next().unwrap_or_default();
        assert!(
            GOLDEN.iter().any(|g| g.0 == id),
            "built-in {id} has no golden record"
        );
    }
    assert!(
        changed.is_empty(),
        "summary.json changed:\n{}",
        changed.join("\n")
    );
}
