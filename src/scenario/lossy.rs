//! `--loss P`: a scenario run over a lossy link. Every sensor's `[channel]` becomes a Bernoulli
//! link losing each packet with probability P (the same losses for every scheme, drawn from the
//! link's own stream), and every scheme whose center has a loss-aware fusion (a `link_loss`
//! parameter, or a `loss_aware` switch) runs twice: as published (a missing packet read as a silence) and loss-aware,
//! labelled "… (loss-aware)", after the published ones. The comparison the user asked for — how wrong
//! does a center that trusts silence become, and what does knowing the loss rate buy — is then
//! one table.
use crate::scenario::build::{expand_every_scheme, parse};
use crate::scenario::error::{Ctx, ScenarioError};
use crate::scheme::registry;

/// The parameter by which a scheme's center learns the link's loss probability.
pub const LOSS_AWARE_PARAM: &str = "link_loss";

/// The switch of a center whose loss-aware fusion needs no loss probability (Dormann et al.'s
/// Algorithm 2: the computed second moment of a lost estimate's extrapolation).
pub const LOSS_AWARE_FLAG: &str = "loss_aware";

/// The suffix of the label of a loss-aware copy.
pub const LOSS_AWARE_SUFFIX: &str = " (loss-aware)";

/// Which parameter switches a registry kind's loss-aware fusion on, if it has one.
fn loss_aware_param(kind: &str) -> Option<&'static str> {
    let entry = registry::find(kind)?;
    [LOSS_AWARE_PARAM, LOSS_AWARE_FLAG]
        .into_iter()
        .find(|name| entry.params.iter().any(|p| p.name == *name))
}

/// Whether a registry kind has a loss-aware fusion.
pub fn has_loss_aware(kind: &str) -> bool {
    loss_aware_param(kind).is_some()
}

/// The scenario `text` (from `file`) with a Bernoulli `[channel]` of loss `p` replacing its
/// link(s) and a loss-aware copy of every scheme that has one. An `every_scheme` scenario is
/// expanded to its explicit list first (so that the copies do not replace the kind's registry
/// example). Entries that already set `link_loss`, and `p = 0` (where the copies would equal
/// the published schemes), get no copy. Per-sensor `channel` tables are removed: `--loss` is one
/// link for every sensor. A `[[schemes]]` entry with a `channel` of its own keeps it (its link
/// is what that entry is about, e.g. a sweep of the loss).
pub fn with_loss(text: &str, file: &str, p: f64) -> Result<String, ScenarioError> {
    let ctx = Ctx { file };
    if !(0.0..=1.0).contains(&p) {
        return Err(ctx.err(
            "--loss",
            format!("expected a probability in [0, 1], got {p}"),
        ));
    }
    let mut spec = parse(text, file)?;
    expand_every_scheme(&mut spec, file)?;
    let mut table: toml::Table = toml::from_str(text).map_err(|e| ctx.err("", e.message()))?;
    let mut channel = toml::Table::new();
    channel.insert("kind".into(), toml::Value::String("bernoulli".into()));
    channel.insert("loss".into(), toml::Value::Float(p));
    table.insert("channel".into(), toml::Value::Table(channel));
    if let Some(toml::Value::Array(sensors)) = table.get_mut("sensors") {
        for s in sensors.iter_mut().filter_map(toml::Value::as_table_mut) {
            s.remove("channel");
        }
    }
    table.remove("every_scheme");
    // The copies come after every published entry: a variant's coins come from its index, so
    // the published schemes keep the numbers they have with the same `[channel]` in a file.
    // Labels already taken (written, or the kind's default), so that a copy never clashes
    // with an entry the user wrote, e.g. one already labelled "… (loss-aware)".
    let mut taken: Vec<String> = spec.schemes.iter().filter_map(entry_label).collect();
    let copies: Vec<toml::Table> = spec
        .schemes
        .iter()
        .filter_map(|e| loss_aware_copy(e, p, &mut taken))
        .collect();
    let schemes: Vec<toml::Value> = spec
        .schemes
        .into_iter()
        .chain(copies)
        .map(toml::Value::Table)
        .collect();
    table.insert("schemes".into(), toml::Value::Array(schemes));
    toml::to_string(&table).map_err(|e| ctx.err("", e.to_string()))
}

/// The loss-aware copy of a `[[schemes]]` entry at loss `p`, or `None` when its kind has no
/// loss-aware fusion, it already sets one, or there is nothing to be aware of (`p = 0`; `p = 1`
/// is outside `link_loss`'s range: nothing ever arrives, so there is nothing to weigh).
fn loss_aware_copy(entry: &toml::Table, p: f64, taken: &mut Vec<String>) -> Option<toml::Table> {
    let kind = entry.get("kind")?.as_str()?;
    let param = loss_aware_param(kind)?;
    // An entry that sets or sweeps its loss awareness itself is what the user asked for.
    let swept = entry
        .get("sweep")
        .and_then(toml::Value::as_table)
        .is_some_and(|t| t.contains_key(param));
    // Zheng et al.'s exact fusion (CFwMD-exact) has no loss-aware likelihood.
    let exact = entry.get("fusion").and_then(toml::Value::as_str) == Some("exact");
    if !(p > 0.0 && p < 1.0) || entry.contains_key(param) || swept || exact {
        return None;
    }
    let label = entry_label(entry)?;
    // "X (loss-aware)", else "X (loss-aware, --loss)", else numbered.
    let mut free = format!("{label}{LOSS_AWARE_SUFFIX}");
    let mut n = 1;
    while taken.contains(&free) {
        n += 1;
        free = match n {
            2 => format!("{label} (loss-aware, --loss)"),
            _ => format!("{label} (loss-aware, --loss {n})"),
        };
    }
    taken.push(free.clone());
    let mut copy = entry.clone();
    copy.insert("label".into(), toml::Value::String(free));
    let value = if param == LOSS_AWARE_FLAG {
        toml::Value::Boolean(true)
    } else {
        toml::Value::Float(p)
    };
    copy.insert(param.into(), value);
    Some(copy)
}

/// The label of a `[[schemes]]` entry: its own, or its kind's.
fn entry_label(entry: &toml::Table) -> Option<String> {
    match entry.get("label").and_then(toml::Value::as_str) {
        Some(l) => Some(l.to_string()),
        None => Some(
            registry::find(entry.get("kind")?.as_str()?)?
                .label
                .to_string(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::build::load;
    use crate::scenario::builtin;

    fn labels(text: &str) -> Vec<String> {
        let exp = load(text, "t").expect("the lossy scenario loads");
        exp.curves.iter().map(|c| c.label.clone()).collect()
    }

    /// A scalar walk, two sensors, with the `[[schemes]]` entries `schemes`.
    fn scalar(schemes: &str) -> String {
        format!(
            "name = \"t\"\ntrials = 2\nsteps = 5\nseed = 1\n[model]\nkind = \"matrix\"\nF = [[0.9]]\nQ = [[1.0]]\n[prior]\nmean = [0.0]\ncov_diag = [1.0]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n{schemes}"
        )
    }

    /// An entry that sweeps its loss awareness is left as it is (it was refused: the copy set
    /// the key the sweep sweeps).
    #[test]
    fn a_swept_loss_awareness_gets_no_copy() {
        for entry in [
            "[[schemes]]\nkind = \"censored-pf\"\nl = 1.0\nparticles = 50\nsweep.link_loss = [0.0, 0.2]\n",
            "[[schemes]]\nkind = \"dkf-alg2-event\"\nalpha = 0.4\nb = 10.0\nsweep.loss_aware = [false, true]\n",
        ] {
            let text = scalar(entry);
            let lossy = with_loss(&text, "t", 0.2).unwrap();
            assert_eq!(labels(&lossy), labels(&text), "{entry}");
        }
    }

    /// A copy's label never clashes with one the user wrote.
    #[test]
    fn a_copy_takes_a_free_label() {
        let text = scalar(
            "[[schemes]]\nkind = \"censored-pf\"\nlabel = \"PF\"\nl = 1.0\nparticles = 50\n[[schemes]]\nkind = \"censored-pf\"\nlabel = \"PF (loss-aware)\"\nl = 1.0\nparticles = 50\nlink_loss = 0.1\n",
        );
        let lossy = with_loss(&text, "t", 0.2).unwrap();
        assert_eq!(
            labels(&lossy),
            ["PF", "PF (loss-aware)", "PF (loss-aware, --loss)"]
        );
    }

    #[test]
    fn every_loss_aware_scheme_gets_a_copy_after_the_published_ones() {
        let (text, _) = builtin::resolve("zheng-fig1", false).unwrap();
        let lossy = with_loss(&text, "zheng-fig1", 0.3).unwrap();
        let got = labels(&lossy);
        let plain = labels(&text);
        let exp = load(&lossy, "t").unwrap();
        // Each plain curve is there, in order, then the copies of those whose kind has one.
        let mut expected = plain.clone();
        for (label, curve) in plain.iter().zip(&load(&text, "t").unwrap().curves) {
            if has_loss_aware(&curve.kind) {
                expected.push(format!("{label}{LOSS_AWARE_SUFFIX}"));
            }
        }
        assert_eq!(got, expected);
        assert!(
            got.len() > plain.len(),
            "zheng-fig1 has a loss-aware center"
        );
        // Every sensor's link is Bernoulli 0.3, and the copies carry link_loss = 0.3.
        let specs = exp.channel.as_ref().expect("a channel");
        assert!(specs.iter().all(|s| s.key("loss") == Some(0.3)));
        for v in &exp.variants {
            let label = &exp.curves[v.curve].label;
            let has = v.params.contains_key(LOSS_AWARE_PARAM);
            assert_eq!(has, label.ends_with(LOSS_AWARE_SUFFIX), "{label}");
            if has {
                assert_eq!(
                    v.params[LOSS_AWARE_PARAM],
                    crate::scenario::ParamValue::Number(0.3)
                );
            }
        }
    }

    #[test]
    fn an_every_scheme_arena_is_expanded_before_the_copies_are_added() {
        let (text, _) = builtin::resolve("arena-1d", false).unwrap();
        let lossy = with_loss(&text, "arena-1d", 0.2).unwrap();
        let plain = labels(&text);
        let got = labels(&lossy);
        assert_eq!(got[..plain.len()], plain[..]);
        assert!(got[plain.len()..]
            .iter()
            .all(|l| l.ends_with(LOSS_AWARE_SUFFIX)));
        // Dormann et al.'s Algorithm 2 switches its loss-aware center on by a flag.
        let exp = load(&lossy, "t").unwrap();
        let alg2 = exp
            .variants
            .iter()
            .find(|v| v.params.contains_key(LOSS_AWARE_FLAG))
            .expect("a loss-aware Algorithm 2");
        assert_eq!(alg2.kind, "dkf-alg2-event");
        assert_eq!(
            alg2.params[LOSS_AWARE_FLAG],
            crate::scenario::ParamValue::Flag(true)
        );
    }

    #[test]
    fn no_copies_without_loss_and_bad_probabilities_are_refused() {
        let (text, _) = builtin::resolve("zheng-fig1", false).unwrap();
        let lossless = with_loss(&text, "zheng-fig1", 0.0).unwrap();
        assert_eq!(labels(&lossless), labels(&text));
        for p in [-0.1, 1.5, f64::NAN] {
            let e = with_loss(&text, "zheng-fig1", p).unwrap_err().to_string();
            assert!(e.contains("--loss"), "{e}");
        }
    }
}
