"""Schemes written in Python: registered, run beside the built-in ones on the same data,
charged the same bits, calibrated to budgets; their errors name the trial and the step."""
import json
import re

import numpy as np
import pytest

import hushfuse as hf

# arena-1d's system (1-D constant velocity, 3 position sensors and 1 velocity sensor), short.
SYSTEM = """
name = "py-small"
trials = {trials}
steps = {steps}
seed = 1101

[model]
kind = "constant-velocity-1d"
dt = 1.0
sigma2 = 0.1
[prior]
mean = [0.0, 1.0]
cov_diag = [10.0, 1.0]
[groups]
position = [0]
velocity = [1]
[[sensors]]
H = [[1.0, 0.0]]
R = [[1.0]]
[[sensors]]
H = [[1.0, 0.0]]
R = [[2.0]]
[[sensors]]
H = [[1.0, 0.0]]
R = [[4.0]]
[[sensors]]
H = [[0.0, 1.0]]
R = [[0.5]]
"""


def scenario(trials=20, steps=40, schemes=""):
    return SYSTEM.format(trials=trials, steps=steps) + schemes


class SodSensor(hf.SensorNode):
    """Send-on-delta's sensor: send z when it left the band z_last +- delta."""

    def __init__(self, ctx):
        super().__init__(ctx)
        self.delta = float(self.params["delta"])
        self.last = None

    def step(self, k, z, feedback):
        if self.last is None or np.max(np.abs(z - self.last)) > self.delta:
            self.last = z.copy()
            return hf.Measurement(z)
        return None


class SodCenter(hf.FusionCenter):
    """Send-on-delta's center, uniform silences: the library's fusion, called as the built-in
    center calls it."""

    def __init__(self, ctx):
        super().__init__(ctx)
        d = float(self.params["delta"])
        self.fusion = hf.LinearFusion(self.system)
        self.mean, self.cov = self.system.prior
        self.last = [None] * self.system.n_sensors
        self.r_silent = [R + np.eye(R.shape[0]) * (d * d / 3.0) for R in self.system.R]

    def step(self, k, inbox):
        self.fusion.start(*self.fusion.predict(self.mean, self.cov))
        for i, r in enumerate(inbox):
            if r.kind == "measurement":
                self.last[i] = r.value
                self.fusion.add(i, r.value)
            elif r.kind == "silent" and self.last[i] is not None:
                self.fusion.add(i, self.last[i], self.r_silent[i])
        self.mean, self.cov = self.fusion.finish()

    def estimate(self):
        return self.mean, self.cov


@hf.register
class PySod(hf.SchemeSpec):
    kind = "py-send-on-delta"
    params = {"delta": None}
    knob = hf.Knob("delta", lo=0.0, hi=None, grows="fewer_bits")
    sensor, center = SodSensor, SodCenter


class Failing(SodSensor):
    def step(self, k, z, feedback):
        if self.trial == 3 and k == 17 and self.index == 1:
            raise ZeroDivisionError("the sensor's own bug")
        return super().step(k, z, feedback)


@hf.register
class PyFailing(hf.SchemeSpec):
    kind = "py-failing"
    params = {"delta": 1.0}
    sensor, center = Failing, SodCenter


class CoinSensor(hf.SensorNode):
    """Sends with probability p, drawing from its own generator."""

    def step(self, k, z, feedback):
        return hf.Measurement(z) if self.rng.random() < self.params["p"] else hf.Silence()


class IgnoreCenter(SodCenter):
    def step(self, k, inbox):
        self.fusion.start(*self.fusion.predict(self.mean, self.cov))
        for i, r in enumerate(inbox):
            if r.kind == "measurement":
                self.fusion.add(i, r.value)
        self.mean, self.cov = self.fusion.finish()


@hf.register
class PyCoin(hf.SchemeSpec):
    kind = "py-coin"
    params = {"p": 0.5, "delta": 0.0}
    knob = hf.Knob("p", lo=0.01, hi=1.0, grows="more_bits")
    sensor, center = CoinSensor, IgnoreCenter


BOTH = """
[[schemes]]
kind = "send-on-delta"
delta = {d}
[[schemes]]
kind = "py-send-on-delta"
delta = {d}
"""


@pytest.mark.parametrize("delta", [0.0, 0.7, 2.5])
def test_python_send_on_delta_equals_the_built_in_bit_for_bit(delta):
    r = hf.run(scenario(schemes=BOTH.format(d=delta)))
    a, b = r["schemes"]
    assert (a["kind"], b["kind"]) == ("send-on-delta", "py-send-on-delta")
    for key in ("bits_per_step", "frame_bits_per_step", "downlink_bits_per_step", "mean_rmse", "anees"):
        assert a[key] == b[key], key
    for key in ("mse", "trace", "anees_per_step"):
        assert np.array_equal(a[key], b[key]), key
    # Per step and sensor, estimates and bits, on one trial's data.
    d = hf.simulate(scenario(schemes=BOTH.format(d=delta)), trial=2)
    rp = hf.replay(scenario(schemes=BOTH.format(d=delta)), d["measurements"], d["truth"], trial=2)
    a, b = rp["schemes"]
    for key in ("mean", "cov", "bits", "links"):
        assert np.array_equal(a[key], b[key]), key
    assert a["bits"].sum() > 0


def test_python_schemes_join_an_arena_beside_the_built_ins():
    r = hf.run("arena-1d", trials=3, schemes=[{"kind": "py-send-on-delta", "delta": 1.0}])
    names = [s["name"] for s in r["schemes"]]
    assert names[-1] == "py-send-on-delta" and "Send-on-delta" in names
    by = {s["name"]: s for s in r["schemes"]}
    assert by["Send-on-delta"]["mean_rmse"] == by["py-send-on-delta"]["mean_rmse"]


def test_calibration_of_a_python_scheme_reaches_the_budget():
    only = '[[schemes]]\nkind = "py-send-on-delta"\ndelta = 1.0\n'
    r = hf.run(scenario(trials=10, schemes=only), budget=40.0, budget_axis="payload")
    (row,) = r["calibration"]
    assert row["kind"] == "py-send-on-delta" and row["knob"] == "delta"
    assert row["status"] == "calibrated", row
    assert abs(row["achieved"] - 40.0) <= 0.02 * 40.0
    assert abs(r["schemes"][0]["bits_per_step"] - 40.0) <= 0.02 * 40.0
    # The knob moved: at delta = 1 the scheme spends another rate.
    plain = hf.run(scenario(trials=10, schemes=only))
    assert abs(plain["schemes"][0]["bits_per_step"] - 40.0) > 0.02 * 40.0


def test_budget_works_for_built_in_schemes_and_budgets_gives_every_budget():
    sod = '[[schemes]]\nkind = "send-on-delta"\ndelta = 1.0\n'
    r = hf.run(scenario(trials=5, schemes=sod), budget=30, budget_axis="payload")
    assert r["budget"] == 30.0 and r["axis"] == "payload"
    assert abs(r["calibration"][0]["achieved"] - 30.0) <= 0.02 * 30.0
    many = hf.run(scenario(trials=5, schemes=sod), budgets=[20, 60], budget_axis="frame")
    assert many["budgets"] == [20.0, 60.0] and len(many["runs"]) == 2 and many["axis"] == "frame"
    with pytest.raises(ValueError, match="budget"):
        hf.run(scenario(schemes=sod), budget=-1)
    with pytest.raises(TypeError, match="budget"):
        hf.run(scenario(schemes=sod), budget="64")


MIXED = """
[[schemes]]
kind = "py-send-on-delta"
delta = 1.0
[[schemes]]
kind = "send-on-delta"
delta = 1.0
[[schemes]]
kind = "centralized-kf-random"
rate = 0.5
"""


def test_an_arena_with_a_python_scheme_writes_its_files_and_report(tmp_path):
    out = tmp_path / "arena"
    budgets = [30.0, 60.0]
    r = hf.run(scenario(trials=6, schemes=MIXED), budgets=budgets, budget_axis="payload",
               out=out, report=True)
    assert r["out"] == str(out)
    for name in ("calibration.json", "best_per_budget.md", "report.html",
                 "rmse_position_vs_bits.svg", "anees_vs_bits.svg"):
        assert name in r["files"], name
    for b in ("30", "60"):
        for name in ("scenario.toml", "summary.json", "per_step.csv"):
            assert f"budget-{b}/{name}" in r["files"]
    for name in r["files"]:
        assert (out / name).is_file(), name
    manifest = json.loads((out / "hushfuse-manifest.json").read_text())
    assert manifest["kind"] == "arena" and manifest["files"] == r["files"]
    assert manifest["scenario"] == "py-small" and manifest["trials"] == 6

    cal = json.loads((out / "calibration.json").read_text())
    assert cal["budgets"] == budgets and cal["axis"] == "payload"
    for b, row in zip(budgets, cal["rows"]):
        by = {c["kind"]: c for c in row}
        assert set(by) == {"py-send-on-delta", "send-on-delta", "centralized-kf-random"}
        py = by["py-send-on-delta"]
        assert py["status"] == "calibrated", py
        assert abs(py["achieved"] - b) <= cal["tolerance"] * b
    # The file holds what the call returned.
    assert [[c["achieved"] for c in row] for row in cal["rows"]] == [
        [c["achieved"] for c in row] for row in r["calibration"]]
    summary = json.loads((out / "budget-30" / "summary.json").read_text())
    assert "py-send-on-delta" in [s["kind"] for s in summary["schemes"]]
    html = (out / "report.html").read_text()
    assert html.startswith("<!DOCTYPE html>") and "py-send-on-delta" in html
    assert "Best scheme per budget" in html

    # budget= (one budget) writes its folder too, and says where.
    one = hf.run(scenario(trials=6, schemes=MIXED), budget=30, budget_axis="payload",
                 out=tmp_path / "one")
    assert one["out"] == str(tmp_path / "one") and "budget-30/summary.json" in one["files"]
    assert "report.html" not in one["files"] and one["budget"] == 30.0


def test_an_arena_refuses_what_a_calibration_cannot_do():
    s = scenario(trials=4, schemes=MIXED)
    for kw in ({"resume": True, "out": "x"}, {"shard": "1/2", "out": "x"}, {"reproduce": True}):
        with pytest.raises(ValueError, match="not checkpointed") as e:
            hf.run(s, budgets=[30], budget_axis="payload", **kw)
        assert "Rust" not in str(e.value) and "::" not in str(e.value)
    with pytest.raises(ValueError, match="report= needs out="):
        hf.run(s, budgets=[30], budget_axis="payload", report=True)


def test_an_exception_in_user_code_names_the_scheme_trial_step_and_traceback():
    s = scenario(trials=6, steps=30, schemes='[[schemes]]\nkind = "py-failing"\n')
    with pytest.raises(hf.RunError) as e:
        hf.run(s, threads=2)
    msg = str(e.value)
    assert "py-failing" in msg
    assert re.search(r"\btrial 3\b", msg) and re.search(r"\bstep 17\b", msg), msg
    assert "Traceback (most recent call last)" in msg
    assert "ZeroDivisionError: the sensor's own bug" in msg
    assert "raise ZeroDivisionError" in msg  # the line of user code


def test_python_schemes_are_reproducible_for_any_thread_count():
    s = scenario(trials=12, schemes='[[schemes]]\nkind = "py-coin"\np = 0.4\n')
    one = hf.run(s, threads=1)["schemes"][0]
    four = hf.run(s, threads=4)["schemes"][0]
    assert np.array_equal(one["mse"], four["mse"])
    assert one["bits_per_step"] == four["bits_per_step"]
    other = hf.run(s, threads=1, seed=7)["schemes"][0]
    assert not np.array_equal(one["mse"], other["mse"])


def test_messages_are_priced_as_the_library_prices_them():
    assert hf.Measurement([1.0, 2.0]).bits == 64
    assert hf.Measurement(1.5).bits == 32
    assert hf.Estimate(np.zeros(3)).frame_bits == 8 * (11 + 12)
    q = hf.QuantizedIndex(5, 3)
    assert (q.kind, q.bits, q.frame_bits) == ("frame", 3, 8 * (11 + 1))
    p = hf.Payload(b"\x01\x02", 12)
    assert (p.bits, p.frame_bits) == (12, 8 * (11 + 2))
    assert hf.Silence().bits == 0
    with pytest.raises(ValueError, match="2\\^bits"):
        hf.QuantizedIndex(8, 3)
    with pytest.raises(ValueError, match="octets"):
        hf.Payload(b"\x01", 12)


def test_quantized_indices_reach_the_center():
    seen = []

    class QSensor(hf.SensorNode):
        def step(self, k, z, feedback):
            return hf.QuantizedIndex(k % 8, 3)

    class QCenter(IgnoreCenter):
        def step(self, k, inbox):
            seen.append([(r.kind, r.index) for r in inbox])
            super().step(k, inbox)

    @hf.register
    class PyQ(hf.SchemeSpec):
        kind = "py-q"
        params = {"delta": 0.0}
        sensor, center = QSensor, QCenter

    try:
        r = hf.run(scenario(trials=1, steps=5, schemes='[[schemes]]\nkind = "py-q"\n'))
        assert r["schemes"][0]["bits_per_step"] == 4 * 3
        assert r["schemes"][0]["frame_bits_per_step"] == 4 * 8 * 12
        assert seen[0] == [("payload", 1)] * 4 and seen[4] == [("payload", 5)] * 4
    finally:
        hf.unregister("py-q")
    assert "py-q" not in hf.registered()


def test_declarations_are_checked():
    class NoStep(hf.SensorNode):
        pass

    class Bad(hf.SchemeSpec):
        kind = "py-bad"
        sensor, center = NoStep, SodCenter

    with pytest.raises(TypeError, match="step"):
        hf.register(Bad)

    class BuiltIn(hf.SchemeSpec):
        kind = "send-on-delta"
        sensor, center = SodSensor, SodCenter

    with pytest.raises(ValueError, match="built-in"):
        hf.register(BuiltIn)
    with pytest.raises(hf.ScenarioError, match="unknown parameter"):
        hf.run(scenario(schemes='[[schemes]]\nkind = "py-send-on-delta"\ndelta = 1.0\nfoo = 2\n'))
    with pytest.raises(hf.ScenarioError, match="delta"):
        hf.run(scenario(schemes='[[schemes]]\nkind = "py-send-on-delta"\n'))


def test_stepping_accepts_lists_and_scalars_and_errors_name_no_rust_type():
    s = hf.Scheme(scenario(schemes=BOTH.format(d=1.0)))
    node = s.sensors[0]
    assert isinstance(node, hf.SensorNode) and isinstance(s.center, hf.FusionCenter)
    assert node.step(1, [1.0]).sent
    assert not node.step(2, 1.1).sent
    assert node.step(3, np.array([5], dtype=np.int64)).sent
    for bad in ("x", [[1.0, 2.0], [3.0, 4.0]], None):
        with pytest.raises((ValueError, TypeError)) as e:
            s.sensors[1].step(5, bad)
        assert not re.search(r"PyArray|PyReadonly|Vec<|f64|usize|Bound<", str(e.value)), str(e.value)


def test_the_namespace_is_the_api():
    public = {n for n in dir(hf) if not n.startswith("_")}
    assert public == set(hf.__all__), public ^ set(hf.__all__)
    for helper in ("np", "json", "Dict", "io", "os", "math", "annotations"):
        assert not hasattr(hf, helper), helper


def test_feedback_of_a_python_center_reaches_the_sensors_and_is_charged(tmp_path):
    got = []

    class FbSensor(hf.SensorNode):
        def step(self, k, z, feedback):
            got.append(None if feedback is None else feedback.mean.copy())
            return hf.Silence()

    class FbCenter(IgnoreCenter):
        def feedback(self):
            return hf.Feedback.prediction(self.mean)

    @hf.register
    class PyFb(hf.SchemeSpec):
        kind = "py-fb"
        params = {"delta": 0.0}
        sensor, center = FbSensor, FbCenter

    try:
        s = scenario(trials=2, steps=6, schemes='[[schemes]]\nkind = "py-fb"\n')
        r = hf.run(s, threads=1)
        assert r["schemes"][0]["downlink_bits_per_step"] == 2 * 32
        assert r["schemes"][0]["bits_per_step"] == 0
        assert got[0] is not None and np.array_equal(got[0], [0.0, 1.0])  # the prior's mean
        # The run's folder and report, as the command line writes them.
        out = hf.run(s, out=tmp_path / "run", report=True)
        assert "report.html" in out["files"] and (tmp_path / "run" / "report.html").exists()
    finally:
        hf.unregister("py-fb")


def test_wrong_returns_of_user_code_are_named():
    class Five(hf.SensorNode):
        def step(self, k, z, feedback):
            return 5

    class Shapeless(IgnoreCenter):
        def estimate(self):
            return self.mean[:1], self.cov

    @hf.register
    class PyFive(hf.SchemeSpec):
        kind = "py-five"
        params = {"delta": 0.0}
        sensor, center = Five, SodCenter

    @hf.register
    class PyShapeless(hf.SchemeSpec):
        kind = "py-shapeless"
        params = {"delta": 0.0}
        sensor, center = SodSensor, Shapeless

    try:
        with pytest.raises(hf.RunError, match=r"sensor 0\.step\(k=1\) returned a int; expected a message"):
            hf.run(scenario(trials=1, steps=3, schemes='[[schemes]]\nkind = "py-five"\n'))
        with pytest.raises(hf.RunError, match=r"estimate\(\) after step 0 returned a mean of 1 components"):
            hf.run(scenario(trials=1, steps=3, schemes='[[schemes]]\nkind = "py-shapeless"\n'))
    finally:
        hf.unregister("py-five")
        hf.unregister("py-shapeless")


def test_budgets_below_the_sleep_energy_and_zero_pilot_trials_are_refused():
    # As the command line: no scheme spends less than the radios asleep (240 µJ for 4 sensors
    # at the CC2420 defaults), so such a budget is refused before any pilot run.
    s = scenario(trials=4, schemes=MIXED)
    with pytest.raises(ValueError, match="asleep") as e:
        hf.run(s, budget=10)
    assert "budget_axis" in str(e.value)
    with pytest.raises(ValueError, match="pilot_trials"):
        hf.run(s, budget=30, budget_axis="payload", pilot_trials=0)


def test_a_payload_larger_than_an_802154_frame_is_refused():
    # 116 payload octets fill a 127-octet MPDU; 1000 octets fit no frame.
    assert hf.Payload(bytes(116), 8 * 116).bits == 8 * 116
    with pytest.raises(ValueError, match="does not fit one IEEE 802.15.4 frame"):
        hf.Payload(bytes(1000), 8000)


SLOW = r'''
import signal, sys, time
sys.path[:0] = {path!r}
import hushfuse as hf

# Python turns SIGINT into KeyboardInterrupt only when SIGINT was not ignored at start-up, and
# a shell ignores it in the jobs it starts in the background (`.ci/run &`): without this line
# the test passed or hung depending on how the test run was launched.
signal.signal(signal.SIGINT, signal.default_int_handler)

class Slow(hf.SensorNode):
    def step(self, k, z, feedback):
        time.sleep(0.05)
        return hf.Measurement(z)

class Center(hf.FusionCenter):
    def __init__(self, ctx):
        super().__init__(ctx)
        self.mean, self.cov = self.system.prior
    def step(self, k, inbox):
        pass
    def estimate(self):
        return self.mean, self.cov

@hf.register
class PySlow(hf.SchemeSpec):
    kind = "py-slow"
    sensor, center = Slow, Center

print("started", flush=True)
try:
    hf.run({scenario!r}, threads=1)
except KeyboardInterrupt:
    print("interrupted", flush=True)
    sys.exit(7)
print("finished", flush=True)
'''


def test_ctrl_c_stops_a_run_whose_python_sensor_is_slow():
    import signal
    import subprocess
    import sys
    import time

    s = scenario(trials=50, steps=100, schemes='[[schemes]]\nkind = "py-slow"\n')
    code = SLOW.format(path=sys.path, scenario=s)
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "started"
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    try:
        out, _ = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        p.kill()
        raise AssertionError("Ctrl-C did not stop the run")
    assert p.returncode == 7, out
    assert "interrupted" in out
