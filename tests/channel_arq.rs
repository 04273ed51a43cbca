//! Retransmission (`arq`) on a link, in the engine: a packet is lost only when every attempt is,
//! at the binomial rate of p^(1+n); every attempt costs its bits and each attempt that arrives
//! its 88-bit acknowledgement; a slot whose first attempt arrived meets the fate it has without
//! ARQ; bursts of a Gilbert–Elliott link defeat the retries. And behind a lossy downlink a
//! censoring sensor decides with the last feedback that reached it.
use hushfuse::engine::runner;
use hushfuse::engine::seeding;
use hushfuse::engine::trace::{self, Link};
use hushfuse::link::Received;
use hushfuse::metrics::link::LinkSummary;
use hushfuse::metrics::results;
use hushfuse::network::channel::{stability, FateTable};
use hushfuse::scenario::build;
use rand::Rng;
#[path = "common/scalar.rs"]
mod scalar;
use scalar::{scalar_system, summary};

fn scalar(a: f64, sensors: usize, channel: &str, schemes: &str, trials: usize) -> String {
    scalar_system(a, sensors, 60, channel, schemes, trials)
}

const KF: &str = "[[schemes]]\nkind = \"centralized-kf\"\n";

fn link(s: &results::Summary) -> &LinkSummary {
    s.schemes[0].link.as_ref().expect("a link section")
}

/// Bernoulli loss p with n retries: a packet is lost with probability p^(1+n) and takes
/// p (1 − p^n) / (1 − p) retries on average; every attempt is paid for.
#[test]
fn bernoulli_retries_deliver_at_the_binomial_rate() {
    for (p, n) in [(0.5f64, 2u32), (0.3, 1)] {
        let channel = format!(
            "[channel]\nkind = \"bernoulli\"\nloss = {p:?}\narq = {{ max_retries = {n} }}\n"
        );
        let s = summary(&scalar(0.95, 1, &channel, KF, 200));
        let l = link(&s);
        // The all-data KF sends once per step: 200 x 60 independent slots.
        let slots = 12_000.0;
        assert_eq!(l.sent, 1.0);
        let delivered = 1.0 - p.powi(n as i32 + 1);
        let se = (delivered * (1.0 - delivered) / slots).sqrt();
        let got = l.delivered / l.sent;
        assert!(
            (got - delivered).abs() < 4.0 * se,
            "p {p}, n {n}: delivered {got}, expected {delivered} ± {se}"
        );
        // Retries R = min(G, n), G geometric (failures before success) with success 1 − p:
        // P(R = j) = p^j (1 − p) for j < n, P(R = n) = p^n.
        let pr = |j: u32| {
            if j < n {
                p.powi(j as i32) * (1.0 - p)
            } else {
                p.powi(n as i32)
            }
        };
        let mean = p * (1.0 - p.powi(n as i32)) / (1.0 - p);
        let m1: f64 = (0..=n).map(|j| j as f64 * pr(j)).sum();
        assert!((m1 - mean).abs() < 1e-12, "the law's mean {m1} vs {mean}");
        let var: f64 = (0..=n).map(|j| (j as f64 - mean).powi(2) * pr(j)).sum();
        let se = (var / slots).sqrt();
        assert!(
            (l.retransmissions / l.sent - mean).abs() < 4.0 * se,
            "p {p}, n {n}: retries per packet {}, expected {mean} ± {se}",
            l.retransmissions
        );
        // Every attempt costs its 32 payload bits and 15-octet frame; ideal ACKs: one per
        // packet that arrived, none lost, so no duplicate.
        let attempts = l.sent + l.retransmissions;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
        assert!(close(s.schemes[0].bits_per_step, 32.0 * attempts));
        assert!(close(s.schemes[0].frame_bits_per_step, 120.0 * attempts));
        assert!(close(s.schemes[0].transmissions_per_step, 1.0));
        assert!(close(l.ack_frames, l.delivered));
        assert!(close(l.ack_bits, 88.0 * l.ack_frames));
        assert_eq!(l.duplicates, 0.0);
    }
}

/// Hand-computed counts: two sensors that always send. A loss-free link: one ACK of 88 bits per
/// packet, no retry. A downlink that loses every ACK: all 1 + 2 attempts go out and arrive, the
/// last two are duplicates, and each of the three gets its ACK.
#[test]
fn acknowledgements_are_counted_bit_for_bit() {
    let clean = "[channel]\nkind = \"bernoulli\"\nloss = 0.0\narq = { max_retries = 2 }\n";
    let s = summary(&scalar(0.95, 2, clean, KF, 3));
    let (sc, l) = (&s.schemes[0], link(&s));
    assert_eq!((l.sent, l.delivered, l.lost), (2.0, 2.0, 0.0));
    assert_eq!((l.retransmissions, l.duplicates), (0.0, 0.0));
    assert_eq!((l.ack_frames, l.ack_bits), (2.0, 176.0));
    assert_eq!((sc.bits_per_step, sc.frame_bits_per_step), (64.0, 240.0));
    assert_eq!(
        sc.downlink_bits_per_step, 0.0,
        "ACKs are not the scheme's feedback"
    );
    assert!(l.ack_bits_per_step.iter().all(|&b| b == 176.0));

    let deaf = "[channel]\nkind = \"ideal\"\ndownlink = { kind = \"bernoulli\", loss = 1.0 }\narq = { max_retries = 2 }\n";
    let s = summary(&scalar(0.95, 2, deaf, KF, 3));
    let (sc, l) = (&s.schemes[0], link(&s));
    assert_eq!((l.sent, l.delivered, l.lost), (2.0, 2.0, 0.0));
    assert_eq!((l.retransmissions, l.duplicates), (4.0, 4.0));
    assert_eq!((l.ack_frames, l.ack_bits), (6.0, 6.0 * 88.0));
    assert_eq!((sc.bits_per_step, sc.frame_bits_per_step), (192.0, 720.0));
    // The center fused one copy of each packet: the estimates are the ideal link's.
    let ideal = summary(&scalar(0.95, 2, "", KF, 3));
    assert_eq!(sc.mse, ideal.schemes[0].mse);
    assert_eq!(sc.trace, ideal.schemes[0].trace);

    // per_step.csv carries the counters with a channel, and not without one.
    let csv = hushfuse::metrics::per_step_csv::per_step_csv(&s);
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert!(
        header.ends_with(",sent,delivered,lost,late,dropped_late,downlink_lost,retransmissions,duplicates,ack_frames,ack_bits"),
        "{header}"
    );
    assert!(
        lines.next().unwrap().ends_with(",2,2,0,0,0,0,4,4,6,528"),
        "{csv}"
    );
    let plain = hushfuse::metrics::per_step_csv::per_step_csv(&ideal);
    assert!(plain
        .lines()
        .next()
        .unwrap()
        .ends_with(",downlink_bits,downlink_bits_se"));
}

/// The first attempt draws exactly what a link without `arq` draws: its loss coin is the first
/// number of the slot's generator, as before retransmission existed. A slot whose first
/// attempt arrived meets, with ARQ, the fate it has without.
#[test]
fn the_first_attempt_keeps_its_draw() {
    let plain = "[channel]\nkind = \"bernoulli\"\nloss = 0.3\n";
    let arq = "[channel]\nkind = \"bernoulli\"\nloss = 0.3\narq = { max_retries = 3 }\n";
    let load = |c: &str| build::load(&scalar(0.95, 2, c, KF, 4), "scalar.toml").unwrap();
    let (a, b) = (load(plain), load(arq));
    let (sa, sb) = (a.channel.as_deref().unwrap(), b.channel.as_deref().unwrap());
    let (mut first_lost, mut rescued) = (0, 0);
    for trial in 0..a.trials {
        let fa = FateTable::draw(sa, a.steps, a.seed, trial as u64, false);
        let fb = FateTable::draw(sb, b.steps, b.seed, trial as u64, false);
        for i in 0..2 {
            for k in 1..=a.steps {
                // The slot's first number, drawn here by hand.
                let mut rng = seeding::slot_rng(a.seed, trial as u64, i, k, false);
                let lost = rng.random::<f64>() < 0.3;
                assert_eq!(fa.get(i, k).lost, lost, "no ARQ: the coin of before");
                let f = fb.get(i, k);
                if lost {
                    first_lost += 1;
                    rescued += usize::from(!f.lost);
                    assert!(f.retries >= 1);
                } else {
                    assert_eq!(
                        f,
                        hushfuse::network::channel::Fate {
                            acks: 1,
                            ..fa.get(i, k)
                        }
                    );
                }
            }
        }
    }
    assert!(
        first_lost > 50 && rescued > 0,
        "{first_lost} lost, {rescued} rescued"
    );

    // In the engine: where the plain link delivered, the ARQ link delivers too; and a link that
    // loses nothing gives every number of the ideal run with ARQ on (one attempt a packet).
    for trial in 0..4 {
        let (ta, tb) = (
            trace::trace(&a, trial, false).unwrap(),
            trace::trace(&b, trial, false).unwrap(),
        );
        for (la, lb) in ta.variants[0].links.iter().zip(&tb.variants[0].links) {
            for (x, y) in la.iter().zip(lb) {
                assert!(*x == Link::Lost || x == y, "{x:?} became {y:?}");
            }
        }
    }
    let ideal = summary(&scalar(0.95, 2, "", KF, 40));
    let zero = summary(&scalar(
        0.95,
        2,
        "[channel]\nkind = \"bernoulli\"\nloss = 0.0\narq = { max_retries = 3 }\n",
        KF,
        40,
    ));
    let mut z = serde_json::to_value(&zero.schemes).unwrap();
    let l = z[0].as_object_mut().unwrap().remove("link").unwrap();
    assert_eq!(
        (l["retransmissions"].as_f64(), l["ack_frames"].as_f64()),
        (Some(0.0), Some(2.0))
    );
    // The radio pays for listening to the acknowledgements (and nothing else changes): the
    // energy figures differ by the ACK part alone.
    let mut i = serde_json::to_value(&ideal.schemes).unwrap();
    let ack = |v: &serde_json::Value| v[0]["energy_parts_per_step_uj"]["ack"].as_f64().unwrap();
    assert_eq!(ack(&i), 0.0);
    assert!(ack(&z) > 0.0);
    let tx = |v: &serde_json::Value| v[0]["energy_parts_per_step_uj"]["tx"].as_f64().unwrap();
    assert_eq!(tx(&i), tx(&z));
    for key in [
        "energy_per_step_uj",
        "energy_per_sensor_step_uj",
        "energy_parts_per_step_uj",
        "lifetime_days",
    ] {
        i[0].as_object_mut().unwrap().remove(key);
        z[0].as_object_mut().unwrap().remove(key);
    }
    assert_eq!(i, z);
}

/// The Kalman filter meets the ARQ link's arrivals: its variance is the data-free recursion of
/// the arrivals of the fate table with retries (Sinopoli et al. 2004), to 1e-9.
#[test]
fn the_kalman_variance_follows_the_arrivals_after_retries() {
    let channel = "[channel]\nkind = \"bernoulli\"\nloss = 0.6\narq = { max_retries = 1 }\n";
    let text = scalar(1.2, 1, channel, KF, 50);
    let exp = build::load(&text, "scalar.toml").unwrap();
    let s = summary(&text);
    let specs = exp.channel.as_deref().unwrap();
    let mut mean_post = vec![0.0; exp.steps];
    let mut lost = 0usize;
    for trial in 0..exp.trials {
        let fates = FateTable::draw(specs, exp.steps, exp.seed, trial as u64, false);
        let arrivals: Vec<bool> = (1..=exp.steps).map(|k| !fates.get(0, k).lost).collect();
        lost += arrivals.iter().filter(|a| !**a).count();
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
    // 3000 slots lost at 0.36: SE = sqrt(0.36 * 0.64 / 3000) = 0.0088; 4 SE.
    let rate = lost as f64 / 3000.0;
    assert!((rate - 0.36).abs() < 4.0 * 0.0088, "{rate}");
    assert!((link(&s).loss_fraction.unwrap() - rate).abs() < 1e-12);
}

/// Gilbert–Elliott with loss_bad = 1 and loss_good = 0: the retries of a step see its state, so
/// a packet sent in the bad state is lost after all its retries and one sent in the good state
/// arrives at once. ARQ loses exactly the packets the plain link loses, at the cost of n
/// retries each.
#[test]
fn bursts_defeat_retries() {
    let ge = "[channel]\nkind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.3\nloss_good = 0.0\nloss_bad = 1.0\n";
    let plain = summary(&scalar(0.95, 1, ge, KF, 100));
    let arq = summary(&scalar(
        0.95,
        1,
        &format!("{ge}arq = {{ max_retries = 3 }}\n"),
        KF,
        100,
    ));
    let (lp, la) = (link(&plain), link(&arq));
    assert!(
        lp.lost > 0.1,
        "the chain spends time in the bad state: {}",
        lp.lost
    );
    assert_eq!(la.lost_per_step, lp.lost_per_step);
    for (r, l) in la.retransmissions_per_step.iter().zip(&la.lost_per_step) {
        assert!((r - 3.0 * l).abs() < 1e-12, "{r} retries for {l} lost");
    }
    assert_eq!(la.duplicates, 0.0);
    assert_eq!(arq.schemes[0].mse, plain.schemes[0].mse);
}

/// Zheng et al.'s CFwMD behind a lossy downlink: each sensor decides with the last fed-back
/// prediction that reached it (the first, made from the prior, counts as received). The engine's
/// decisions and estimates are those of a loop written here by hand with that rule, bit for bit;
/// and the feedback matters: an ideal downlink gives other decisions.
#[test]
fn a_censoring_sensor_keeps_the_last_feedback_it_received() {
    let pf = "[[schemes]]\nkind = \"censored-pf\"\nl = 1.0\nparticles = 100\nfeedback = \"prediction\"\n";
    let ideal_text = scalar(0.95, 2, "", pf, 1);
    let ideal = build::load(&ideal_text, "scalar.toml").unwrap();
    let mut differ = [0usize; 2];
    for (d, loss) in [0.5f64, 1.0].into_iter().enumerate() {
        let channel = format!(
            "[channel]\nkind = \"ideal\"\ndownlink = {{ kind = \"bernoulli\", loss = {loss:?} }}\n"
        );
        let exp = build::load(&scalar(0.95, 2, &channel, pf, 1), "scalar.toml").unwrap();
        let specs = exp.channel.as_deref().unwrap();
        for trial in 0..4 {
            let engine = trace::trace(&exp, trial, false).unwrap();
            let fed = trace::trace(&ideal, trial, false).unwrap();
            let data = runner::draw_trial(&exp, trial);
            let down = FateTable::draw(specs, exp.steps, exp.seed, trial as u64, true);
            // The loop by hand: variant 0's coins and center seed, as the engine seeds them.
            let ns = exp.system.n_sensors();
            let (mut coins, center_seed) =
                seeding::coins(exp.seed, trial, seeding::coin_stream(0), ns);
            let mut inst = exp.variants[0].scheme.build_with_seed(center_seed).unwrap();
            // Feedback as the sensors receive it (singles), as the engine sends it.
            let fb = |c: &dyn hushfuse::scheme::FusionCenter| c.feedback().map(|f| f.as_sent());
            let mut held = vec![fb(inst.center.as_ref()); 2];
            assert!(held[0].is_some(), "the scheme feeds back");
            for k in 1..=exp.steps {
                let fresh = fb(inst.center.as_ref());
                for (i, h) in held.iter_mut().enumerate() {
                    if k > 1 && !down.get(i, k).lost {
                        h.clone_from(&fresh);
                    }
                }
                let mut inbox = Vec::new();
                for (i, node) in inst.sensors.iter_mut().enumerate() {
                    let t = node
                        .step(
                            k,
                            &data.measurements[k - 1][i],
                            held[i].as_ref(),
                            &mut coins[i],
                        )
                        .unwrap();
                    inbox.push(Received::from(t));
                }
                inst.center.step(k, &inbox).unwrap();
                for (i, r) in inbox.iter().enumerate() {
                    let sent = !matches!(r, Received::Silent);
                    let got = engine.variants[0].links[k - 1][i];
                    assert_eq!(
                        got == Link::Sent,
                        sent,
                        "loss {loss}, trial {trial}, step {k}, sensor {i}: engine {got:?}"
                    );
                    differ[d] += usize::from(fed.variants[0].links[k - 1][i] != got);
                }
                let (a, b) = (&engine.variants[0].estimates[k - 1], inst.center.estimate());
                assert_eq!(a.mean, b.mean, "loss {loss}, trial {trial}, step {k}");
                assert_eq!(a.cov, b.cov, "loss {loss}, trial {trial}, step {k}");
            }
        }
    }
    // Stale feedback changes decisions: the held rule is seen, not an ideal downlink in disguise.
    assert!(differ[0] > 0 && differ[1] > 0, "{differ:?}");
}
