//! The rows' notes in the HTML report ([`crate::metrics::notes`]): what differs on a row from
//! the others, under the results table as the terminal prints it under its table.
use std::fmt::Write as _;

/// A "Notes" heading and one item per note, each through `esc` (the report's HTML escaping);
/// nothing when there are none.
pub fn list(h: &mut String, notes: &[String], esc: fn(&str) -> String) {
    if !notes.is_empty() {
        h.push_str("<h3>Notes</h3>\n<ul class=\"notes\">\n");
        for n in notes {
            let _ = writeln!(h, "<li>{}</li>", esc(n));
        }
        h.push_str("</ul>\n");
    }
}
