//! `every_scheme = true`: a scenario (the arenas) that runs every scheme of the registry that
//! applies to its system, asking the registry instead of listing them. The schemes come in the
//! registry's order, each with its registry example's parameters; a `[[schemes]]` entry of a
//! kind replaces that kind's example (several entries of one kind: all of them, in file
//! order), so a file lists only what it sets differently (a knob's starting point, a label).
use crate::scenario::error::{Ctx, ScenarioError};
use crate::scheme::registry::{self, SchemeEntry};
use crate::scheme::System;

/// The entry table of a registry kind from its example (required parameters only).
fn example_table(entry: &SchemeEntry) -> toml::Table {
    let params: toml::Table = toml::from_str(entry.example)
        .unwrap_or_else(|e| panic!("the registry example of {} does not parse: {e}", entry.kind));
    // `kind` first, as a file writes it (the calibrated arenas write these tables out).
    let mut t = toml::Table::new();
    t.insert("kind".into(), toml::Value::String(entry.kind.into()));
    t.extend(params);
    t
}

/// The `[[schemes]]` tables of an `every_scheme` scenario on `system`: every registry kind that
/// applies, `listed` entries in place of their kind's example. A listed kind that is unknown or
/// does not apply is refused, naming the entry.
pub(crate) fn expand(
    ctx: &Ctx,
    listed: &[toml::Table],
    system: &System,
) -> Result<Vec<toml::Table>, ScenarioError> {
    let mut kinds = Vec::with_capacity(listed.len());
    for (i, t) in listed.iter().enumerate() {
        let field = format!("schemes[{i}].kind");
        let Some(kind) = t.get("kind").and_then(toml::Value::as_str) else {
            return Err(ctx.err(field, "expected the scheme's kind (a string)"));
        };
        let entry = registry::find(kind).ok_or_else(|| {
            ctx.err(
                &field,
                format!(
                    "unknown scheme kind {kind:?}; expected one of {} (`hushfuse list-schemes`)",
                    registry::kinds().join(", ")
                ),
            )
        })?;
        if !entry.applies.holds(system) {
            return Err(ctx.err(
                field,
                format!(
                    "{kind} does not apply to this system (it needs {}); with every_scheme = true, list only schemes that apply",
                    entry.applies.text()
                ),
            ));
        }
        kinds.push(entry.kind);
    }
    let mut out = Vec::new();
    for entry in registry::SCHEMES {
        if !entry.applies.holds(system) {
            continue;
        }
        let own: Vec<&toml::Table> = listed
            .iter()
            .zip(&kinds)
            .filter(|(_, k)| **k == entry.kind)
            .map(|(t, _)| t)
            .collect();
        if own.is_empty() {
            out.push(example_table(entry));
        } else {
            out.extend(own.into_iter().cloned());
        }
    }
    // Kinds registered at run time (`crate::scheme::external`) run where they are listed,
    // after the built-in ones.
    out.extend(
        listed
            .iter()
            .zip(&kinds)
            .filter(|(_, k)| !registry::SCHEMES.iter().any(|e| e.kind == **k))
            .map(|(t, _)| t.clone()),
    );
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::build;

    const HEAD: &str = r#"
name = "t"
trials = 2
steps = 5
seed = 1
every_scheme = true
[model]
kind = "constant-velocity-1d"
dt = 1.0
sigma2 = 0.1
[prior]
mean = [0.0, 1.0]
cov_diag = [1.0, 1.0]
[[sensors]]
H = [[1.0, 0.0]]
R = [[1.0]]
[[sensors]]
H = [[1.0, 0.0]]
R = [[2.0]]
"#;

    #[test]
    fn every_applicable_kind_runs_in_registry_order_with_listed_entries_in_place() {
        let text = format!(
            "{HEAD}\n[[schemes]]\nkind = \"send-on-delta\"\ndelta = 0.25\nlabel = \"mine\"\n"
        );
        let exp = build::load(&text, "t.toml").unwrap();
        let sys = &exp.system;
        let expected: Vec<&str> = registry::SCHEMES
            .iter()
            .filter(|e| e.applies.holds(sys))
            .map(|e| e.kind)
            .collect();
        let got: Vec<&str> = exp.variants.iter().map(|v| v.kind).collect();
        assert_eq!(got, expected);
        // Scalar linear sensors: every kind of the registry applies.
        assert_eq!(got.len(), registry::SCHEMES.len());
        let sod = exp
            .variants
            .iter()
            .position(|v| v.kind == "send-on-delta")
            .unwrap();
        assert_eq!(exp.curves[exp.variants[sod].curve].label, "mine");
    }

    fn two_d() -> String {
        let two = "H = [[1.0, 0.0], [0.0, 1.0]]\nR = [[1.0, 0.0], [0.0, 1.0]]";
        HEAD.replace("H = [[1.0, 0.0]]\nR = [[1.0]]", two)
            .replace("H = [[1.0, 0.0]]\nR = [[2.0]]", two)
    }

    #[test]
    fn a_listed_kind_that_does_not_apply_is_refused_by_name() {
        // 2-component sensors: the scalar-only schemes do not apply.
        let text = two_d() + "\n[[schemes]]\nkind = \"quantized-innovation\"\n";
        let e = build::load(&text, "t.toml").unwrap_err();
        assert_eq!(e.field, "schemes[0].kind");
        assert!(e.message.contains("does not apply"), "{e}");
        // Without it, the scalar-only kinds are left out and the rest run.
        let exp = build::load(&two_d(), "t.toml").unwrap();
        assert!(exp
            .variants
            .iter()
            .all(|v| v.kind != "quantized-innovation"));
        assert!(exp.variants.iter().any(|v| v.kind == "centralized-kf"));
    }

    #[test]
    fn an_unknown_listed_kind_is_refused() {
        let text = format!("{HEAD}\n[[schemes]]\nkind = \"no-such\"\n");
        let e = build::load(&text, "t.toml").unwrap_err();
        assert_eq!(e.field, "schemes[0].kind");
        assert!(e.message.contains("unknown scheme kind"), "{e}");
    }
}
