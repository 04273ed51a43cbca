//! The radio energy of `summary.json` (issue 24): the `[radio]` table's defaults (CC2420) and
//! its keys priced by hand on the scalar system, acknowledgements and feedback from the run's
//! own counters, and bad `[radio]` values refused with the key named.
use hushfuse::metrics::results;
use hushfuse::scenario::build;
#[path = "common/scalar.rs"]
mod scalar;
use scalar::{scalar_system, summary};

const KF: &str = "[[schemes]]\nkind = \"centralized-kf\"\n";

/// Two scalar sensors, 10 steps, 3 trials, `extra` (a channel or a `[radio]` table) and
/// `schemes`.
fn run(extra: &str, schemes: &str) -> results::Summary {
    summary(&scalar_system(0.95, 2, 10, extra, schemes, 3))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

/// The all-data KF: each of 2 sensors sends its 32-bit measurement every step, a 4-octet
/// payload in a 15-octet MPDU, 21 octets on air (+ preamble 4, SFD 1, PHR 1) = 168 bits =
/// 672 µs at 250 kb/s. With the 192 µs turnaround, 864 µs at 3.0 V × 17.4 mA = 52.2 mW:
/// 45.1008 µJ a frame, 90.2016 µJ a step. Asleep: 2 sensors × 1 s − 2 × 864 µs = 1 998 272 µs
/// at 3.0 V × 0.02 mA = 0.06 mW: 119.89632 µJ. Total 210.09792 µJ a step, 105.04896 per sensor;
/// lifetime 2500 mAh × 3.6 × 3.0 V = 27 000 J over 105.04896 µW = 2974.8 days.
#[test]
fn cc2420_defaults_by_hand() {
    let s = run("", KF);
    let e = &s.schemes[0].energy;
    assert_eq!(s.schemes[0].frame_bits_per_step, 2.0 * 120.0);
    assert!(close(e.energy_parts_per_step_uj.tx, 90.2016), "{e:?}");
    assert!(close(e.energy_parts_per_step_uj.sleep, 119.89632), "{e:?}");
    assert_eq!(e.energy_parts_per_step_uj.ack, 0.0);
    assert_eq!(e.energy_parts_per_step_uj.downlink, 0.0);
    assert!(close(e.energy_per_step_uj, 210.09792), "{e:?}");
    assert!(close(e.energy_per_sensor_step_uj, 105.04896), "{e:?}");
    let days = 27_000.0 / 105.04896e-6 / 86_400.0;
    assert!(close(e.lifetime_days.unwrap(), days), "{e:?}");
    assert!((days - 2974.8).abs() < 0.05);
    // In summary.json, at the scheme's top level.
    let json = hushfuse::metrics::summary_json(&s).unwrap();
    assert!(close(
        json["schemes"][0]["energy_per_step_uj"].as_f64().unwrap(),
        210.09792
    ));
    assert!(json["schemes"][0]["lifetime_days"].is_number());
}

/// A `[radio]` table changes the energy as the model says: twice the TX current doubles the TX
/// part and nothing else; a 10 s step and no sleep current leave only the TX part, and the
/// lifetime follows the step.
#[test]
fn radio_table_changes_the_energy() {
    let base = run("", KF).schemes[0].energy.clone();
    let doubled = run("[radio]\ntx_ma = 34.8\n", KF).schemes[0].energy.clone();
    let (b, d) = (
        &base.energy_parts_per_step_uj,
        &doubled.energy_parts_per_step_uj,
    );
    assert!(close(d.tx, 2.0 * b.tx));
    assert_eq!((d.sleep, d.ack, d.downlink), (b.sleep, b.ack, b.downlink));
    assert!(close(
        doubled.energy_per_step_uj,
        base.energy_per_step_uj + b.tx
    ));
    let awake = run(
        "[radio]\nsleep_ma = 0.0\nstep_seconds = 10.0\nbattery_mah = 1000.0\nsupply_v = 3.3\n",
        KF,
    );
    let e = &awake.schemes[0].energy;
    // 3.3 V × 17.4 mA = 57.42 mW × 864 µs = 49.61088 µJ a frame, two a step.
    assert!(close(e.energy_per_step_uj, 2.0 * 49.61088), "{e:?}");
    // 1000 mAh × 3.6 × 3.3 V = 11 880 J over 49.61088 µJ every 10 s = 4.961088 µW.
    let days = 11_880.0 / 4.961088e-6 / 86_400.0;
    assert!(close(e.lifetime_days.unwrap(), days), "{e:?}");
}

/// With `arq` every attempt costs a frame and a wait: a heard ACK 192 + 352 µs, an unheard one
/// the whole 864 µs, at 3.0 V × 18.8 mA = 56.4 mW; the counts are the run's link section.
#[test]
fn acknowledgements_are_priced_from_the_link_counters() {
    let channel = "[channel]\nkind = \"bernoulli\"\nloss = 0.3\narq = { max_retries = 2 }\n";
    let s = run(channel, KF);
    let (e, l) = (&s.schemes[0].energy, s.schemes[0].link.as_ref().unwrap());
    assert!(l.retransmissions > 0.0);
    let attempts = l.sent + l.retransmissions;
    let heard = l.ack_frames - l.duplicates;
    let ack = 56.4 * (heard * 544.0 + (attempts - heard) * 864.0) / 1000.0;
    assert!(close(e.energy_parts_per_step_uj.ack, ack), "{e:?} vs {ack}");
    // Every attempt on air: (120 + 48 bits) / 250 kb/s + 192 µs at 52.2 mW.
    assert!(close(
        e.energy_parts_per_step_uj.tx,
        attempts * 52.2 * 864.0 / 1000.0
    ));
    // The same loss without ARQ: no waits.
    let plain = run("[channel]\nkind = \"bernoulli\"\nloss = 0.3\n", KF);
    assert_eq!(plain.schemes[0].energy.energy_parts_per_step_uj.ack, 0.0);
}

/// A scheme with feedback: both sensors listen every step for 1000 µs and receive the step's
/// feedback frame (136 bits of PHY and MAC overhead around the feedback payload).
#[test]
fn feedback_costs_every_sensor_its_listening() {
    let closed = "[[schemes]]\nkind = \"stochastic-trigger-closed\"\ntau = 1.0\n";
    let s = run("", closed);
    let sch = &s.schemes[0];
    let d = sch.downlink_bits_per_step;
    assert!(d > 0.0);
    let bits = 2.0 * 136.0 + 2.0 * d;
    let downlink = 56.4 * (2.0 * 1000.0 + bits / 0.25) / 1000.0;
    let got = sch.energy.energy_parts_per_step_uj.downlink;
    assert!(close(got, downlink), "{got} vs {downlink}");
    // A longer window costs 56.4 mW × 2 sensors × 500 µs = 56.4 µJ a step more.
    let longer = run("[radio]\nlisten_us = 1500.0\n", closed);
    let more = longer.schemes[0].energy.energy_parts_per_step_uj.downlink - got;
    assert!(close(more, 56.4), "{more}");
}

/// Bad `[radio]` values, unknown keys and wrong types are errors naming the key.
#[test]
fn bad_radio_tables_name_the_key() {
    let err = |radio: &str| {
        let text = scalar_system(0.95, 2, 10, radio, KF, 3);
        let e = build::load(&text, "scalar.toml").unwrap_err();
        (e.field.clone(), e.to_string())
    };
    let (field, msg) = err("[radio]\ntx_ma = -1.0\n");
    assert_eq!(field, "radio.tx_ma", "{msg}");
    assert!(
        msg.contains("expected a finite number > 0, got -1"),
        "{msg}"
    );
    assert_eq!(err("[radio]\nstep_seconds = 0.0\n").0, "radio.step_seconds");
    assert_eq!(err("[radio]\nlisten_us = nan\n").0, "radio.listen_us");
    assert_eq!(err("[radio]\nack_wait_us = 100.0\n").0, "radio.ack_wait_us");
    let (field, msg) = err("[radio]\ntx_current = 17.4\n");
    assert!(field.starts_with("radio.tx_current"), "{field}: {msg}");
    assert!(msg.contains("unknown field"), "{msg}");
    let (field, msg) = err("[radio]\ntx_ma = \"high\"\n");
    assert!(field.starts_with("radio.tx_ma"), "{field}: {msg}");
}
