//! The rows' notes: an entry's `note = "..."` says what differs on its row from the others
//! (a sensor the other schemes do not have, information they lack), so that a table whose rows
//! are not all like for like says so under it.
use crate::metrics::results::Summary;
use std::fmt::Write as _;

/// One line per scheme entry with a note, `label: note`, in table order (a swept entry's
/// variants share their entry's note: once).
pub fn lines(summary: &Summary) -> Vec<String> {
    let mut seen = std::collections::BTreeSet::new();
    summary
        .schemes
        .iter()
        .filter_map(|s| {
            let note = s.note.as_ref()?;
            seen.insert(s.curve).then(|| format!("{}: {note}", s.name))
        })
        .collect()
}

/// The [`lines`] as the terminal prints them under a table (a plain run's, after its warnings,
/// and each budget's of `--budget`/`--budgets`): a blank line, then one `note: ...` line each;
/// empty when no row has a note.
pub fn block(summary: &Summary) -> String {
    let notes = lines(summary);
    let mut out = String::new();
    if !notes.is_empty() {
        out.push('\n');
        for n in notes {
            let _ = writeln!(out, "note: {n}");
        }
    }
    out
}
