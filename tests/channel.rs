//! The link model in the engine: lost packets reach the center as silences but cost their
//! bits; every scheme meets the same fate in a slot; a channel changes no other draw; and the
//! Kalman filter's variance under losses is the data-free recursion given the arrivals
//! (Sinopoli et al. 2004), exactly.
use hushfuse::engine::replay::{self, Recorded};
use hushfuse::engine::runner;
use hushfuse::engine::trace::{self, Link};
use hushfuse::network::channel::{stability, FateTable};

#[test]
fn late_packets_and_a_lossy_downlink_are_counted() {
    let channel =
        "[channel]\nkind = \"ideal\"\ndelay = 2\ndownlink = { kind = \"bernoulli\", loss = 0.5 }\n";
    let s = summary(&scalar(channel, KF, 20));
    let link = s.schemes[0].link.as_ref().unwrap();
    // Every message is two steps late (within the horizon of a fixed delay: none dropped).
    assert_eq!(link.late, 1.0);
    assert_eq!(link.delivered, 0.0);
    assert_eq!(link.dropped_late, 0.0);
    // The all-data KF sends no feedback: nothing on the downlink to lose.
    assert_eq!(link.downlink_lost, 0.0);
    // A center with feedback (Zheng et al.'s CFwMD) loses half its feedback packets from step
    // 2 on (the first, made from the prior, counts as received). 20 x 59 slots at p = 0.5:
    // SE = sqrt(0.25 / 1180) = 0.0146; 4 SE.
    let pf = "[[schemes]]\nkind = \"censored-pf\"\nl = 1.0\nparticles = 100\nfeedback = \"prediction\"\n";
    let downlink = "[channel]\nkind = \"ideal\"\ndownlink = { kind = \"bernoulli\", loss = 0.5 }\n";
    let s = summary(&scalar(downlink, pf, 20));
    let link = s.schemes[0].link.as_ref().unwrap();
    let after_first = link.downlink_lost_per_step[1..].iter().sum::<f64>() / 59.0;
    assert_eq!(link.downlink_lost_per_step[0], 0.0);
    assert!((after_first - 0.5).abs() < 4.0 * 0.0146, "{after_first}");
}
use hushfuse::scenario::build;
#[path = "common/scalar.rs"]
mod scalar;
use scalar::{scalar_system, summary};

/// The scalar system of Sinopoli et al. with a = 1.2 and one sensor.
fn scalar(channel: &str, schemes: &str, trials: usize) -> String {
    scalar_system(1.2, 1, 60, channel, schemes, trials)
}

const KF: &str = "[[schemes]]\nkind = \"centralized-kf\"\n";

#[test]
fn a_link_that_loses_nothing_changes_no_number() {
    let ideal = summary(&scalar("", KF, 40));
    let zero = summary(&scalar(
        "[channel]\nkind = \"bernoulli\"\nloss = 0.0\n",
        KF,
        40,
    ));
    let mut b = serde_json::to_value(&zero.schemes).unwrap();
    // The lossless link's section says so, and everything else is the ideal run's.
    let link = b[0]
        .as_object_mut()
        .unwrap()
        .remove("link")
        .expect("a link section");
    assert_eq!(link["lost"], 0.0);
    assert_eq!(link["delivered"], 1.0);
    assert_eq!(serde_json::to_value(&ideal.schemes).unwrap(), b);
    assert!(ideal.schemes[0].link.is_none());
}

#[test]
fn the_kalman_variance_under_losses_is_the_data_free_recursion_of_the_arrivals() {
    let channel = "[channel]\nkind = \"bernoulli\"\nloss = 0.4\n";
    let text = scalar(channel, KF, 50);
    let exp = build::load(&text, "scalar.toml").unwrap();
    let s = summary(&text);
    // The same arrivals, drawn independently of the engine from the link's own stream.
    let specs = exp.channel.as_deref().unwrap();
    let mut mean_post = vec![0.0; exp.steps];
    for trial in 0..exp.trials {
        let fates = FateTable::draw(specs, exp.steps, exp.seed, trial as u64, false);
        let arrivals: Vec<bool> = (1..=exp.steps).map(|k| !fates.get(0, k).lost).collect();
        // Prior of step 1 is a^2 P0 + q; the path gives the priors, the posterior follows.
        let priors = stability::prior_variance_path(1.2, 1.0, 1.0, 1.44 + 1.0, &arrivals);
        for k in 0..exp.steps {
            let p = priors[k];
            let post = if arrivals[k] {
                p - p * p / (p + 1.0)
            } else {
                p
            };
            mean_post[k] += post / exp.trials as f64;
        }
    }
    for (k, (got, want)) in s.schemes[0].trace.iter().zip(&mean_post).enumerate() {
        assert!(
            (got - want).abs() <= 1e-9 * want.abs(),
            "step {}: the run's mean variance {got}, the recursion's {want}",
            k + 1
        );
    }
    // summary.json counts them: sent = delivered + lost, at the link's rate. 3000 slots at
    // p = 0.4: SE = sqrt(0.4 * 0.6 / 3000) = 0.0089; 4 SE.
    let link = s.schemes[0].link.as_ref().expect("a link section");
    assert_eq!(link.sent, 1.0);
    assert!((link.delivered + link.lost - link.sent).abs() < 1e-12);
    assert!(
        (link.loss_fraction.unwrap() - 0.4).abs() < 4.0 * 0.0089,
        "{:?}",
        link.loss_fraction
    );
    assert_eq!(link.late, 0.0);
    // And far from the ideal link's steady state: losses are not silences for free.
    let ideal = summary(&scalar("", KF, 50));
    assert!(s.schemes[0].steady_state.trace > 1.2 * ideal.schemes[0].steady_state.trace);
}

#[test]
fn every_scheme_meets_the_same_fate_in_a_slot_and_losses_cost_their_bits() {
    let schemes = format!("{KF}[[schemes]]\nkind = \"send-on-delta\"\ndelta = 1.0\n");
    let text = scalar("[channel]\nkind = \"bernoulli\"\nloss = 0.3\n", &schemes, 1);
    let exp = build::load(&text, "scalar.toml").unwrap();
    let mut sent = 0usize;
    let mut lost = 0usize;
    let mut both = 0usize;
    for trial in 0..200 {
        let t = trace::trace(&exp, trial, false).unwrap();
        for k in 0..exp.steps {
            let (a, b) = (t.variants[0].links[k][0], t.variants[1].links[k][0]);
            // The all-data KF sends at every step: its links are the link's fates.
            assert!(matches!(a, Link::Sent | Link::Lost));
            sent += 1;
            lost += usize::from(a == Link::Lost);
            if matches!(b, Link::Sent | Link::Lost) {
                assert_eq!(a, b, "trial {trial}, step {}: different fates", k + 1);
                both += 1;
            }
        }
    }
    assert!(both > 100, "send-on-delta sent only {both} times");
    // 12000 slots at p = 0.3: SE = sqrt(0.3 * 0.7 / 12000) = 0.0042; 4 SE.
    let rate = lost as f64 / sent as f64;
    assert!((rate - 0.3).abs() < 4.0 * 0.0042, "loss rate {rate}");
    // A lost packet was sent: its payload bits count.
    let data = runner::draw_trial(&exp, 0);
    let r = replay::replay(&exp, &Recorded::from_trial(&data), 0).unwrap();
    let links = &r.variants[0].links;
    let bits = &r.variants[0].bits;
    let lost_bits: u64 = (0..exp.steps)
        .filter(|&k| links[k][0] == Link::Lost)
        .map(|k| bits[k][0])
        .sum();
    assert!(lost_bits > 0);
}

#[test]
fn bad_channel_tables_are_refused_naming_the_key() {
    let cases = [
        (
            "[channel]\nkind = \"bernoulli\"\n",
            "channel",
            "needs `loss`",
        ),
        (
            "[channel]\nkind = \"bernoulli\"\nloss = 1.5\n",
            "channel",
            "not a probability",
        ),
        ("[channel]\nkind = \"lossy\"\n", "", "lossy"),
    ];
    for (channel, field, words) in cases {
        let e = build::load(&scalar(channel, KF, 2), "scalar.toml").unwrap_err();
        assert!(
            e.field.starts_with(field) && e.to_string().contains(words),
            "{channel}: {e}"
        );
    }
    // A sensor's own table, named by its index.
    let text = scalar("", KF, 2).replace(
        "R = [[1.0]]",
        "R = [[1.0]]\nchannel = { kind = \"gilbert-elliott\", p_gb = 0.1 }",
    );
    let e = build::load(&text, "scalar.toml").unwrap_err();
    assert_eq!(e.field, "sensors[0].channel");
    assert!(e.to_string().contains("needs `p_bg`"), "{e}");
}

/// Zheng et al.'s CFwMD center under a lossy link: the published likelihood reads every lost
/// packet as "inside the band" and is overconfident; the loss-aware one (`link_loss`) is not.
#[test]
fn the_loss_aware_censored_pf_center_is_consistent_where_the_published_one_is_not() {
    let channel = "[channel]\nkind = \"bernoulli\"\nloss = 0.5\n";
    let pf = |link_loss: f64| {
        format!("[[schemes]]\nkind = \"censored-pf\"\nl = 1.0\nparticles = 400\nlink_loss = {link_loss}\nlabel = \"p{link_loss}\"\n")
    };
    let text = scalar(channel, &(pf(0.0) + &pf(0.5)), 200)
        .replace("F = [[1.2]]", "F = [[0.95]]")
        .replace(
            "[[sensors]]\nH = [[1.0]]\nR = [[1.0]]",
            "[[sensors]]\nH = [[1.0]]\nR = [[1.0]]\n[[sensors]]\nH = [[1.0]]\nR = [[1.0]]",
        );
    let s = summary(&text);
    let (published, aware) = (&s.schemes[0].steady_state, &s.schemes[1].steady_state);
    // `cargo test --release --test channel loss_aware -- --nocapture` prints the figures.
    eprintln!(
        "published ANEES {:.2} ± {:.2}, MSE {:.2}; loss-aware ANEES {:.2} ± {:.2}, MSE {:.2}",
        published.anees, published.anees_se, published.mse, aware.anees, aware.anees_se, aware.mse
    );
    // ANEES of a consistent filter is 1; its standard error comes from the per-trial means.
    // (Seen: published 2.50 ± 0.12, loss-aware 1.04 ± 0.03; steady-state MSE 1.11 and 0.98.)
    assert!(
        (aware.anees - 1.0).abs() < 4.0 * aware.anees_se,
        "loss-aware ANEES {} ± {}",
        aware.anees,
        aware.anees_se
    );
    assert!(
        published.anees > aware.anees + 4.0 * (published.anees_se + aware.anees_se),
        "published ANEES {} ± {}, loss-aware {} ± {}",
        published.anees,
        published.anees_se,
        aware.anees,
        aware.anees_se
    );
}

/// A message two steps late is fused when it arrives: the center's estimate at every step is
/// the in-order Kalman filter on the measurements that have arrived by then.
#[test]
fn late_packets_are_re_fused_into_the_in_order_filter() {
    use hushfuse::link::{Message, Received, Transmission};
    let text = scalar("[channel]\nkind = \"ideal\"\ndelay = 2\n", KF, 1);
    let exp = build::load(&text, "scalar.toml").unwrap();
    for trial in 0..3 {
        let t = trace::trace(&exp, trial, false).unwrap();
        let data = runner::draw_trial(&exp, trial);
        for k in 1..=exp.steps {
            // A fresh all-data KF fed z_1..z_{k-2} and silences at k-1 and k.
            let mut inst = exp.variants[0].scheme.build_with_seed(0).unwrap();
            for j in 1..=k {
                let inbox = if j + 2 <= k {
                    // The measurement as it crosses the network (singles).
                    let z = data.measurements[j - 1][0].clone();
                    vec![Received::from(Transmission::Send(Message::Measurement(z)))]
                } else {
                    vec![Received::Silent]
                };
                inst.center.step(j, &inbox).unwrap();
            }
            let (got, want) = (&t.variants[0].estimates[k - 1], inst.center.estimate());
            let d_mean = (&got.mean - &want.mean).abs().max();
            let d_cov = (&got.cov - &want.cov).abs().max();
            assert!(
                d_mean <= 1e-12 && d_cov <= 1e-12,
                "trial {trial}, step {k}: re-fused estimate differs by {d_mean:e} (mean), {d_cov:e} (cov)"
            );
        }
    }
}

#[test]
fn packets_later_than_the_horizon_are_dropped_and_counted() {
    // Geometric delays of mean 3 with a horizon of 1 step: P(delay = 0) = 1/4,
    // P(delay = 1) = 3/16, the rest (9/16) is dropped. 60 x 400 slots: SE <= 0.0033; 4 SE.
    let channel =
        "[channel]\nkind = \"ideal\"\ndelay = { kind = \"geometric\", mean = 3.0, horizon = 1 }\n";
    let s = summary(&scalar(channel, KF, 400));
    let link = s.schemes[0].link.as_ref().unwrap();
    for (got, want) in [
        (link.delivered, 0.25),
        (link.late, 3.0 / 16.0),
        (link.dropped_late, 9.0 / 16.0),
    ] {
        assert!((got - want).abs() < 4.0 * 0.0033, "{got} vs {want}");
    }
}

/// A replay of trial K's data meets trial K's link, so it reproduces the run's trial K, and a
/// Gilbert-Elliott link loses at its stationary rate in the engine too.
#[test]
fn a_replay_meets_the_runs_link_and_bursts_lose_at_the_stationary_rate() {
    let channel = "[channel]\nkind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.3\n";
    let schemes = format!("{KF}[[schemes]]\nkind = \"send-on-delta\"\ndelta = 1.0\n");
    let text = scalar(channel, &schemes, 1);
    let exp = build::load(&text, "scalar.toml").unwrap();
    let run = runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
    let data = runner::draw_trial(&exp, 0);
    let replayed = replay::replay(&exp, &Recorded::from_trial(&data), 0).unwrap();
    assert_eq!(replayed.sums.as_deref(), Some(run.as_slice()));
    // pi_bad = p_gb / (p_gb + p_bg) = 0.25, every packet lost there: the KF (which always
    // sends) loses 25%. Bursts correlate the slots: with lambda = 1 - p_gb - p_bg = 0.6 the
    // variance of the mean over n slots is about pi (1 - pi) (1 + lambda) / (1 - lambda) / n;
    // 400 trials x 60 steps: SE = 0.0056; 4 SE.
    let s = summary(&scalar(channel, KF, 400));
    let lost = s.schemes[0].link.as_ref().unwrap().loss_fraction.unwrap();
    assert!((lost - 0.25).abs() < 4.0 * 0.0056, "{lost}");
}
