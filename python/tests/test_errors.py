"""Errors are Python exceptions with the command line's messages, never a crash."""
import numpy as np
import pandas as pd
import pytest

import hushfuse
from conftest import EXAMPLE, cli

SCEN = str(EXAMPLE / "scenario.toml")


def test_bad_scenarios_raise_scenario_error():
    with pytest.raises(hushfuse.ScenarioError, match="neither a file nor a built-in scenario"):
        hushfuse.run("no-such-scenario")
    with pytest.raises(hushfuse.ScenarioError, match="cannot read"):
        hushfuse.run("/nonexistent/dir/x.toml")
    bad = (EXAMPLE / "scenario.toml").read_text().replace("trials = 1", "trials = 1\ntrails = 3")
    with pytest.raises(hushfuse.ScenarioError, match="trails"):
        hushfuse.run(bad)
    with pytest.raises(hushfuse.ScenarioError, match=r"field `schemes\[0\]"):
        hushfuse.replay(bad.replace("trails = 3\n", "").replace('kind = "centralized-kf"', 'kind = "no-such-kind"'), [np.zeros((3, 1))] * 4)
    # ScenarioError is a ValueError.
    with pytest.raises(ValueError):
        hushfuse.simulate("no-such-scenario")
    with pytest.raises(TypeError):
        hushfuse.run(42)


def test_wrong_array_shapes_raise():
    with pytest.raises(ValueError, match="3-D array"):
        hushfuse.replay(SCEN, np.zeros((40, 4)))
    with pytest.raises(ValueError, match="same number of steps"):
        hushfuse.replay(SCEN, [np.zeros((40, 1)), np.zeros((39, 1)), np.zeros((40, 2)), np.zeros((40, 2))])
    # A sensor array of the wrong width: the replay's own error, naming the array.
    with pytest.raises(hushfuse.DataError, match=r"measurements\[0\]: sensor 0 measures 1 component, the array has 2 columns"):
        hushfuse.replay(SCEN, [np.zeros((40, 2)), np.zeros((40, 1)), np.zeros((40, 2)), np.zeros((40, 2))])
    # One array per sensor: too many or too few is an error naming the counts.
    with pytest.raises(hushfuse.DataError, match="5 sensor arrays given, but .* has 4 sensors"):
        hushfuse.replay(SCEN, [np.zeros((40, 1))] * 2 + [np.zeros((40, 2))] * 2 + [np.zeros((40, 1))])
    with pytest.raises(ValueError, match="some components are NaN"):
        hushfuse.replay(SCEN, [np.zeros((40, 1)), np.zeros((40, 1)), np.array([[np.nan, 1.0]] * 40), np.zeros((40, 2))])
    with pytest.raises(ValueError, match="not finite"):
        hushfuse.replay(SCEN, [np.full((40, 1), np.inf)])
    # Truth of the wrong dimension.
    with pytest.raises(hushfuse.DataError, match=r"truth: the state has 2 components, the array has 1 columns"):
        hushfuse.replay(SCEN, FOUR, np.zeros((40, 1)))
    with pytest.raises(ValueError, match="2-D array"):
        hushfuse.replay(SCEN, FOUR, np.zeros((40, 2, 1)))


# One array per sensor of the example scenario: two scalar sensors, two 2-D ones.
FOUR = [np.zeros((40, 1))] * 2 + [np.zeros((40, 2))] * 2


def test_python_inputs_are_strict():
    with pytest.raises(hushfuse.DataError, match="3 sensor arrays given, but .* has 4 sensors"):
        hushfuse.replay(SCEN, FOUR[:3])
    for bad in (FOUR[:3] + [np.zeros((40, 2), dtype=complex)], FOUR[:3] + [np.zeros((40, 2), dtype=bool)]):
        with pytest.raises(TypeError, match=r"measurements\[3\]: expected real numbers"):
            hushfuse.replay(SCEN, bad)
    with pytest.raises(TypeError, match="truth: expected real numbers"):
        hushfuse.replay(SCEN, FOUR, np.zeros((40, 2), dtype=complex))
    # The fusion center takes k = 1, 2, 3, ... in order; a sensor's steps increase.
    s = hushfuse.Scheme(SCEN, variant=0)
    s.center.step(1, [None] * 4)
    for k in (1, 3):
        with pytest.raises(ValueError, match="the center takes every step in order"):
            s.center.step(k, [None] * 4)
    s.center.step(2, [None] * 4)
    s.sensors[0].step(2, np.array([0.5]))
    with pytest.raises(ValueError, match="a sensor's steps must increase"):
        s.sensors[0].step(2, np.array([0.5]))
    s.sensors[0].step(5, np.array([0.5]))
    # Far more threads than cores: capped, the same numbers.
    assert hushfuse.run(SCEN, threads=100000)["schemes"][0]["mse"].tolist() == hushfuse.run(SCEN, threads=1)["schemes"][0]["mse"].tolist()


def test_dataframe_errors_carry_the_cli_message(tmp_path):
    meas = pd.read_csv(EXAMPLE / "measurements.csv").astype({"z0": object})
    meas.loc[2, "z0"] = "oops"
    meas.to_csv(tmp_path / "m.csv", index=False)
    out = cli("replay", SCEN, "--measurements", "m.csv", cwd=tmp_path)
    assert out.returncode == 2
    cli_msg = out.stderr.strip().removeprefix("error: m.csv")
    with pytest.raises(hushfuse.DataError) as e:
        hushfuse.replay(SCEN, meas)
    assert str(e.value) == "measurements (DataFrame)" + cli_msg
    assert "line 4 (data row 3), column 3 (z0): expected a number" in cli_msg
    # Steps out of order.
    swapped = pd.read_csv(EXAMPLE / "measurements.csv").iloc[[4, 0, 1]]
    with pytest.raises(hushfuse.DataError, match="steps out of order"):
        hushfuse.replay(SCEN, swapped)


def test_step_level_errors_raise():
    s = hushfuse.Scheme(SCEN, variant=0)
    with pytest.raises(ValueError, match="z has 2 components, the sensor measures 1"):
        s.sensors[0].step(1, np.zeros(2))
    with pytest.raises(ValueError, match="not finite"):
        s.sensors[0].step(1, np.array([np.nan]))
    with pytest.raises(ValueError, match="inbox has 1 entries, the scheme has 4 sensors"):
        s.center.step(1, [None])
    with pytest.raises(ValueError, match="variant 9 does not exist"):
        hushfuse.Scheme(SCEN, variant=9)
    with pytest.raises(TypeError):
        s.center.step(1, ["not a transmission"] * 4)
    # After errors the objects still work.
    t = s.sensors[0].step(1, np.array([0.5]))
    assert t.sent and t.bits == 32 and t.kind == "measurement"
    s.center.step(1, [t, None, None, None])
    mean, cov = s.center.estimate()
    assert mean.shape == (2,) and cov.shape == (2, 2)


def test_a_request_larger_than_the_machine_is_a_memory_error_before_any_allocation():
    # Seed-free, machine-free: the estimate (tens of GiB) is above the 16 GiB ceiling anywhere.
    with pytest.raises(MemoryError, match="in memory, more than the limit") as e:
        hushfuse.Scheme("dormann-fig1", variant=1, steps=2_000_000)
    assert "--allow-large" not in str(e.value) and "--trials" not in str(e.value)


def test_a_replay_larger_than_the_memory_limit_is_a_memory_error(monkeypatch):
    data = hushfuse.simulate(SCEN)
    monkeypatch.setenv("HUSHFUSE_MAX_MEMORY_BYTES", "1000")
    with pytest.raises(MemoryError, match="in memory, more than the limit") as e:
        hushfuse.replay(SCEN, data["measurements"], data["truth"])
    assert "--allow-large" not in str(e.value)


def test_readings_that_overflow_the_filters_are_a_run_error_naming_the_scheme():
    # The example's model with the centralized KF only (a filter that takes any finite reading).
    text = (EXAMPLE / "scenario.toml").read_text()
    kf = text.split("[[schemes]]")[0] + '[[schemes]]\nkind = "centralized-kf"\n'
    data = hushfuse.simulate(kf)
    # Readings near the largest double, alternating in sign. They cross the network as IEEE
    # singles (issue 26), so they arrive as infinities and the center rejects step 1.
    def huge_like(m):
        m = np.asarray(m, dtype=float)
        sign = np.where(np.arange(m.shape[0]) % 2 == 0, 1.0, -1.0).reshape(-1, *[1] * (m.ndim - 1))
        return np.ones_like(m) * sign * 1.7e308

    huge = [huge_like(m) for m in data["measurements"]]
    with pytest.raises(hushfuse.RunError, match="not finite") as e:
        hushfuse.replay(kf, huge)
    assert "Centralized KF" in str(e.value) and "step 1:" in str(e.value), str(e.value)


def test_a_multi_hop_network_runs_whole_and_is_refused_step_by_step():
    r = hushfuse.run("mesh-line", trials=2)
    net = r["schemes"][0]["network"]
    battery = [n for n in net["nodes"] if not n["mains"]]
    first = min(battery, key=lambda n: n["lifetime_days"])
    assert net["first_to_die"]["node"] == first["name"]
    assert [n["hops"] for n in net["nodes"]] == [5, 4, 3, 2, 1, 0]
    with pytest.raises(ValueError, match=r"multi-hop \[network\]"):
        hushfuse.Scheme("mesh-line")


def test_a_trial_steps_over_the_mesh_as_the_run_does():
    # hushfuse.Trial is the simulator's own step: trial 0 stepped by hand spends every bit and
    # frame that run(trials=1) reports, per scheme and per node (aggregated and per source).
    data = hushfuse.simulate("mesh-line", trial=0)
    r = hushfuse.run("mesh-line", trials=1)
    for v in (0, 1):
        t = hushfuse.Trial("mesh-line", variant=v, trial=0)
        assert t.n_sensors == len(data["measurements"])
        bits, sent = 0, {}
        for k in range(1, t.steps + 1):
            s = t.step(k, [m[k - 1] for m in data["measurements"]])
            assert s["mean"].shape == (2,) and s["cov"].shape == (2, 2)
            bits += s["traffic"]["bits"]
            for name, c in s["nodes"].items():
                sent[name] = sent.get(name, 0) + c["frames_sent"]
        scheme = r["schemes"][v]
        assert bits / t.steps == pytest.approx(scheme["bits_per_step"], rel=1e-12)
        for n in scheme["network"]["nodes"]:
            assert sent[n["name"]] / t.steps == pytest.approx(n["frames_sent_per_step"], rel=1e-12)
    with pytest.raises(hushfuse.InputError, match="in order"):
        t.step(1, [m[0] for m in data["measurements"]])
    fresh = hushfuse.Trial("mesh-line")
    with pytest.raises(hushfuse.InputError, match="readings"):
        fresh.step(1, [data["measurements"][0][0]])
