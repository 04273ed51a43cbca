"""A replayed run equals the simulated run on the same measurements, bit for bit; a
notebook's own loop over Scheme's sensor nodes and fusion center equals the replay; the
Python replay equals the command line's."""
import numpy as np
import pandas as pd
import pytest

import hushfuse
from conftest import CENSORED_PF, EXAMPLE, cli, plain, read_json

SCENARIOS = {"example": str(EXAMPLE / "scenario.toml"), "censored-pf": CENSORED_PF}


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_replay_of_simulated_data_equals_the_run(name):
    scenario = SCENARIOS[name]
    run = hushfuse.run(scenario, trials=1)
    data = hushfuse.simulate(scenario)
    r = hushfuse.replay(scenario, data["measurements"], data["truth"])
    assert r["available"].all()
    assert plain(r["summary"]) == plain(run)
    # Through a DataFrame in the command line's long form: the same again.
    frame = hushfuse.measurements_frame(data["measurements"])
    assert list(frame.columns[:2]) == ["step", "sensor"]
    r2 = hushfuse.replay(scenario, frame, data["truth"])
    assert plain(r2["summary"]) == plain(run)
    # Other coins (another seed) change the result: the equality is not vacuous.
    if name == "censored-pf":
        r3 = hushfuse.replay(scenario, data["measurements"], data["truth"], seed=99)
        assert plain(r3["summary"]["schemes"][0]["mse"]) != plain(run["schemes"][0]["mse"])


def test_notebook_loop_equals_replay():
    """Drive the scheme step by step as the simulator does: the same estimates, bit for bit."""
    scenario = CENSORED_PF
    data = hushfuse.simulate(scenario)
    r = hushfuse.replay(scenario, data["measurements"], data["truth"])
    for v in range(len(hushfuse.variants(scenario))):
        s = hushfuse.Scheme(scenario, variant=v)
        fb = s.center.feedback()
        for k in range(1, s.steps + 1):
            inbox = []
            for i, node in enumerate(s.sensors):
                if s.allows(k, i):
                    inbox.append(node.step(k, data["measurements"][i][k - 1], fb))
                else:
                    inbox.append(None)
            s.center.step(k, inbox)
            fb = s.center.feedback()
            mean, cov = s.center.estimate()
            assert np.array_equal(mean, r["schemes"][v]["mean"][k - 1]), (v, k)
            assert np.array_equal(cov, r["schemes"][v]["cov"][k - 1]), (v, k)
            sent = [t is not None and t.sent for t in inbox]
            assert sent == [l == "sent" for l in r["schemes"][v]["links"][k - 1]]


def test_censored_pf_python_equals_cli(tmp_path, monkeypatch):
    """A censored particle-filter run through Python equals the same run through the CLI."""
    (tmp_path / "pf.toml").write_text(CENSORED_PF)
    out = cli("run", "pf.toml", "--out", "o", "--threads", "2", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    expected = read_json(tmp_path / "o" / "summary.json")
    expected.pop("paper", None)
    monkeypatch.chdir(tmp_path)  # the same source name, "pf.toml", in both summaries
    got = hushfuse.run("pf.toml", threads=1)
    assert got["schemes"][0]["kind"] == "censored-pf" and got["trials"] == 6
    assert plain(got) == expected
    # The particle filter reported its effective sample size, as per-step arrays.
    assert got["schemes"][0]["ess"]["mean_per_step"].shape == (15,)


def test_example_replay_python_equals_cli(tmp_path):
    out = cli(
        "replay",
        str(EXAMPLE / "scenario.toml"),
        "--measurements",
        str(EXAMPLE / "measurements.csv"),
        "--truth",
        str(EXAMPLE / "truth.csv"),
        "--out",
        "o",
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    meas = pd.read_csv(EXAMPLE / "measurements.csv", float_precision="round_trip")
    truth = pd.read_csv(EXAMPLE / "truth.csv", float_precision="round_trip")
    r = hushfuse.replay(str(EXAMPLE / "scenario.toml"), meas, truth)
    assert plain(r["summary"]) == read_json(tmp_path / "o" / "summary.json")
    est = pd.read_csv(tmp_path / "o" / "estimates.csv", float_precision="round_trip")
    assert len(est) == 5 * 40
    for v, s in enumerate(r["schemes"]):
        rows = est[est["variant"] == v]
        assert np.array_equal(rows[["mean_0", "mean_1"]].to_numpy(), s["mean"])
        assert np.array_equal(rows[["var_0", "var_1"]].to_numpy(), np.diagonal(s["cov"], axis1=1, axis2=2))
        assert (rows[[f"sensor_{i}" for i in range(4)]].to_numpy() == s["links"]).all()
    # The example's deleted rows are missing readings.
    assert not r["available"][9, 3] and not r["available"][19, 1] and r["available"].sum() == 154


def test_three_d_array_and_list_agree():
    """Sensors of equal dimension: a (T, N, m) array is the same data as the list of (T, m)."""
    data = hushfuse.simulate(CENSORED_PF)
    cube = np.stack(data["measurements"], axis=1)
    assert cube.shape == (15, 2, 1)
    cube[3, 1, :] = np.nan  # sensor 1 has no reading at step 4
    a = hushfuse.replay(CENSORED_PF, cube, data["truth"])
    lst = [cube[:, i, :] for i in range(2)]
    b = hushfuse.replay(CENSORED_PF, lst, data["truth"])
    assert plain(a["summary"]) == plain(b["summary"])
    assert a["available"].sum() == 29 and not a["available"][3, 1]
    assert all(s["links"][3, 1] == "missing" for s in a["schemes"])
    assert [v["kind"] for v in hushfuse.variants(CENSORED_PF)] == ["censored-pf", "centralized-kf"]
    assert "default" in [name for name, _ in hushfuse.builtins()]
