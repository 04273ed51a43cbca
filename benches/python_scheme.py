"""The cost of a scheme written in Python: the bridge alone (a scheme that does nothing), and send-on-delta on arena-1d's system (200 trials x 100
steps x 4 sensors), built-in against the Python re-implementation of
python/tests/test_python_schemes.py (same numbers, bit for bit), per trial step and overall.
Run with the package installed: python benches/python_scheme.py [THREADS ...]"""
import importlib.util
import pathlib
import sys
import time

import hushfuse as hf

ROOT = pathlib.Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("t", ROOT / "python/tests/test_python_schemes.py")
t = importlib.util.module_from_spec(spec)
spec.loader.exec_module(t)  # registers py-send-on-delta



class NopSensor(hf.SensorNode):
    def step(self, k, z, feedback):
        return None


class NopCenter(hf.FusionCenter):
    def __init__(self, ctx):
        super().__init__(ctx)
        self.e = self.system.prior

    def step(self, k, inbox):
        pass

    def estimate(self):
        return self.e


@hf.register
class Nop(hf.SchemeSpec):
    """A scheme whose Python does nothing: the cost of the bridge alone."""

    kind = "py-nop"
    params = {"delta": 1.0}
    sensor, center = NopSensor, NopCenter


TRIALS, STEPS = 200, 100
ONLY = '[[schemes]]\nkind = "{}"\ndelta = 1.0\n'


def timed(kind, threads):
    text = t.scenario(trials=TRIALS, steps=STEPS, schemes=ONLY.format(kind))
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        r = hf.run(text, threads=threads)
        best = min(best, time.perf_counter() - t0)
    return best, r["schemes"][0]


for threads in [int(a) for a in sys.argv[1:]] or [1, 0]:
    (tb, b), (tp, p) = timed("send-on-delta", threads), timed("py-send-on-delta", threads)
    assert b["mean_rmse"] == p["mean_rmse"] and b["bits_per_step"] == p["bits_per_step"]
    steps = TRIALS * STEPS
    tn, _ = timed("py-nop", threads)
    print(f"threads={threads}: a do-nothing Python scheme {tn:.3f} s: the bridge costs {1e6 * tn / steps:.1f} µs"
          f" per step ({1e6 * tn / (steps * 5):.1f} µs per step() call, estimate() read included)")
    print(f"threads={threads}: built-in {tb:.3f} s, Python {tp:.3f} s for {TRIALS} trials x {STEPS} steps"
          f" x 4 sensors; Python overhead {1e6 * (tp - tb) / steps:.1f} µs per step"
          f" ({1e6 * (tp - tb) / (steps * 5):.1f} µs per Python call: 4 sensors + 1 center)")
