"""hushfuse: multi-sensor state estimation when sensors must save bandwidth.

Sensors decide whether and with how many bits to talk (censoring, event triggering,
quantization, scheduling); a fusion center fuses what arrives and what the silence says.

- :func:`run` runs a scenario (Monte Carlo) and returns its summary with per-step numpy arrays;
- :func:`replay` runs every scheme of a scenario on recorded measurements (numpy arrays or a
  pandas DataFrame), exactly as ``hushfuse replay`` does;
- :func:`simulate` draws one simulated trial (truth and measurements) as the simulator does;
- :class:`Scheme` gives one scheme's sensor nodes and fusion center, to drive your own loop.

Scenarios are given as a built-in name (``builtins()``), a path to a TOML file, or TOML text.
Bad input raises :class:`ScenarioError` or :class:`DataError` (both :class:`InputError`, a
``ValueError``) with the command line's messages; a scheme that fails raises :class:`RunError`.
"""
from __future__ import annotations

import io
import math
import os
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _hushfuse
from ._hushfuse import (
    DataError,
    Feedback,
    FusionCenter,
    InputError,
    RunError,
    Scheme,
    ScenarioError,
    SensorNode,
    Transmission,
    builtins,
)

__version__ = _hushfuse.__version__

__all__ = [
    "run",
    "replay",
    "simulate",
    "variants",
    "builtins",
    "measurements_frame",
    "Scheme",
    "SensorNode",
    "FusionCenter",
    "Transmission",
    "Feedback",
    "InputError",
    "ScenarioError",
    "DataError",
    "RunError",
]

# Per-step lists of a scheme's summary that become numpy arrays.
_PER_STEP = ("mse", "trace", "anees_per_step")


def _nan(v: Any) -> float:
    return math.nan if v is None else float(v)


def _arrays(summary: Dict[str, Any]) -> Dict[str, Any]:
    """Per-step lists -> float numpy arrays (null, i.e. not finite, -> NaN)."""
    for s in summary["schemes"]:
        for key in _PER_STEP:
            s[key] = np.array([_nan(v) for v in s[key]], dtype=float)
        s["rmse"] = {g: np.array([_nan(v) for v in r], dtype=float) for g, r in s["rmse"].items()}
        ess = s.get("ess")
        if ess is not None:
            for key in ("mean_per_step", "min_per_step"):
                ess[key] = np.array([_nan(v) for v in ess[key]], dtype=float)
    return summary


def _check_scenario(scenario: Any) -> str:
    if isinstance(scenario, (str,)):
        return scenario
    if hasattr(scenario, "__fspath__"):
        return os.fspath(scenario)
    raise TypeError(
        f"scenario: expected a built-in name, a path or TOML text, got {type(scenario).__name__}"
    )


def run(
    scenario: str,
    trials: Optional[int] = None,
    seed: Optional[int] = None,
    threads: int = 0,
    out: Optional[Union[str, "os.PathLike[str]"]] = None,
    resume: bool = False,
    shard: Optional[Union[str, Sequence[int]]] = None,
    report: bool = False,
    reproduce: bool = False,
    checkpoint_every: float = 10.0,
    loss: Optional[float] = None,
) -> Dict[str, Any]:
    """Runs a scenario (Monte Carlo), as ``hushfuse run`` does, and returns its summary.

    Args:
        scenario: a built-in name (see :func:`builtins`), a path to a TOML file, or TOML text.
        trials: replaces the scenario's number of trials.
        seed: replaces the scenario's seed.
        threads: worker threads (0: one per core); the result does not depend on it.
        out: an output folder: the run writes there exactly the files of ``hushfuse run
            --out`` (summary.json, per_step.csv, plots, scenario_as_run.toml, a manifest), and
            checkpoints its finished trials every ``checkpoint_every`` seconds.
        resume: continue the interrupted run whose checkpoint is in ``out`` (the same
            arguments; from the first trial when there is none).
        shard: ``"I/N"`` or ``(I, N)``: run only shard I of N (1-based) into ``out``;
            ``hushfuse merge`` turns the N shard files into the whole run's folder.
        report: also write report.html (needs ``out``).
        reproduce: a reproduction, as ``hushfuse reproduce``: also reproduction.md.
        loss: as ``--loss P``: every sensor behind a Bernoulli link losing each packet with
            probability P (the same losses for every scheme), and a "... (loss-aware)" copy of
            every scheme whose center has a loss-aware fusion, after the published ones.

    Returns:
        The summary.json of ``hushfuse run`` as Python objects: ``scenario``, ``trials``,
        ``steps``, ``seed``, ``groups``, ``schemes`` (one dict per scheme variant with
        ``name``, ``kind``, ``params``, ``rmse`` (group -> numpy array per step), ``mse``,
        ``trace``, ``anees_per_step`` (numpy arrays per step), ``mean_rmse``, ``anees``,
        ``rate``, ``bits_per_step``, ``steady_state`` and the rest) and, for a scenario that
        reproduces a paper, ``paper`` (the published numbers beside ours and the checked
        claims). With ``out``: also ``out`` and ``files``. A shard returns only ``shard`` (its
        file), ``blocks`` and ``done``.

    Raises:
        ScenarioError: the scenario cannot be read or is inconsistent, or the output folder or
            checkpoint cannot be used.
        MemoryError: the run would not fit in memory (refused before it starts).
        RunError: a scheme failed during the run.
    """
    if shard is not None and not isinstance(shard, str):
        i, n = shard
        shard = f"{int(i)}/{int(n)}"
    if out is not None:
        out = os.fspath(out)
    r = _hushfuse.run(
        _check_scenario(scenario), trials, seed, threads, out, resume, shard, report, reproduce,
        checkpoint_every, loss,
    )
    return r if "schemes" not in r else _arrays(r)


def simulate(scenario: str, trial: int = 0, seed: Optional[int] = None) -> Dict[str, Any]:
    """Draws trial ``trial`` of a scenario exactly as the simulator does.

    Returns:
        ``truth``: array (T, n); ``measurements``: one array (T, m_i) per sensor; ``steps``;
        ``seed``. ``replay(scenario, d["measurements"], d["truth"], trial=trial)`` reproduces
        ``run(scenario, trials=1)`` for trial 0, bit for bit.
    """
    return _hushfuse.simulate(_check_scenario(scenario), trial, seed)


def variants(scenario: str) -> List[Dict[str, Any]]:
    """The scheme variants of a scenario, in order: dicts with ``label``, ``kind``, ``params``."""
    return [
        {"label": label, "kind": kind, "params": params}
        for label, kind, params in _hushfuse.variants(_check_scenario(scenario))
    ]


def _is_frame(x: Any) -> bool:
    return type(x).__module__.startswith("pandas") and hasattr(x, "to_csv")


def _fmt(v: float) -> str:
    # repr of a Python float reads back to the same bits.
    return repr(float(v))


def _cell(v: Any) -> str:
    """One DataFrame cell as CSV text: floats so that they read back to the same bits (pandas'
    own to_csv drops the 17th digit), NaN as an empty field, anything else as written."""
    if isinstance(v, (float, np.floating)):
        return "" if math.isnan(v) else _fmt(v)
    if isinstance(v, (bool, np.bool_)):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return "" if v is None else str(v)


def _frame_csv(frame: Any) -> str:
    import csv

    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow([str(c) for c in frame.columns])
    for row in frame.itertuples(index=False, name=None):
        w.writerow([_cell(v) for v in row])
    return out.getvalue()


def _real(a: Any, name: str) -> np.ndarray:
    """``a`` as a float array; booleans, complex numbers, strings and objects are refused
    (numpy would turn True into 1.0 and drop an imaginary part without a word)."""
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiu":
        raise TypeError(
            f"{name}: expected real numbers (a float array), got an array of dtype {arr.dtype}"
        )
    return arr.astype(float, copy=False)


def _measurement_arrays(measurements: Any) -> List[np.ndarray]:
    """A 3-D array (T, N, m) or a sequence of N 2-D arrays (T, m_i) -> list of 2-D arrays."""
    if isinstance(measurements, np.ndarray):
        if measurements.ndim != 3:
            raise ValueError(
                "measurements: expected a 3-D array (steps, sensors, components), a list of "
                f"2-D arrays (steps, components) per sensor, or a DataFrame; got an array of shape {measurements.shape}"
            )
        arr = _real(measurements, "measurements")
        return [arr[:, i, :] for i in range(arr.shape[1])]
    if isinstance(measurements, (list, tuple)):
        out = []
        for i, a in enumerate(measurements):
            a = _real(a, f"measurements[{i}]")
            if a.ndim == 1:
                a = a[:, None]
            if a.ndim != 2:
                raise ValueError(
                    f"measurements[{i}]: expected a 2-D array (steps, components), got shape {a.shape}"
                )
            out.append(a)
        if not out:
            raise ValueError("measurements: the list is empty (expected one array per sensor)")
        steps = {a.shape[0] for a in out}
        if len(steps) != 1:
            raise ValueError(
                "measurements: every sensor's array needs the same number of steps (rows), got "
                + ", ".join(f"measurements[{i}]: {a.shape[0]}" for i, a in enumerate(out))
            )
        return out
    raise TypeError(
        "measurements: expected a pandas DataFrame, a 3-D numpy array or a list of 2-D arrays, "
        f"got {type(measurements).__name__}"
    )


def _measurements_csv(arrays: Sequence[np.ndarray]) -> str:
    """Long-form CSV of per-sensor arrays; an all-NaN row is a missing reading."""
    width = max(a.shape[1] for a in arrays)
    out = io.StringIO()
    out.write("step,sensor," + ",".join(f"z{j}" for j in range(width)) + "\n")
    steps = arrays[0].shape[0]
    for i, a in enumerate(arrays):
        nan = np.isnan(a)
        part = nan.any(axis=1) & ~nan.all(axis=1)
        if part.any():
            k = int(np.argmax(part))
            raise ValueError(
                f"measurements[{i}] row {k} (step {k + 1}): some components are NaN and others "
                "not (an all-NaN row means no reading)"
            )
        inf = np.isinf(a).any(axis=1)
        if inf.any():
            k = int(np.argmax(inf))
            raise ValueError(f"measurements[{i}] row {k} (step {k + 1}): a component is not finite")
    for k in range(steps):
        for i, a in enumerate(arrays):
            row = a[k]
            if np.isnan(row).all():
                continue
            out.write(f"{k + 1},{i}," + ",".join(_fmt(v) for v in row))
            out.write("," * (width - len(row)) + "\n")
    return out.getvalue()


def _truth_csv(truth: Any) -> str:
    if _is_frame(truth):
        return _frame_csv(truth)
    t = _real(truth, "truth")
    if t.ndim == 1:
        t = t[:, None]
    if t.ndim != 2:
        raise ValueError(f"truth: expected a 2-D array (steps, state components), got shape {t.shape}")
    out = io.StringIO()
    out.write("step," + ",".join(f"x{j}" for j in range(t.shape[1])) + "\n")
    for k, row in enumerate(t):
        out.write(f"{k + 1}," + ",".join(_fmt(v) for v in row) + "\n")
    return out.getvalue()


def _truth_array(truth: Any) -> np.ndarray:
    t = _real(truth, "truth")
    if t.ndim == 1:
        t = t[:, None]
    if t.ndim != 2:
        raise ValueError(f"truth: expected a 2-D array (steps, state components), got shape {t.shape}")
    return np.ascontiguousarray(t, dtype=float)


def measurements_frame(measurements: Any) -> "Any":
    """Per-sensor arrays (or a 3-D array) as the long-form pandas DataFrame ``replay`` and the
    command line read: columns ``step``, ``sensor``, ``z0``, ``z1``, ...; all-NaN rows left out."""
    import pandas as pd

    text = io.StringIO(_measurements_csv(_measurement_arrays(measurements)))
    if int(pd.__version__.split(".")[0]) >= 3:
        return pd.read_csv(text)  # round-trip precision is the default from pandas 3 on
    return pd.read_csv(text, float_precision="round_trip")


def replay(
    scenario: str,
    measurements: Any,
    truth: Any = None,
    seed: Optional[int] = None,
    trial: int = 0,
) -> Dict[str, Any]:
    """Runs every scheme (variant) of a scenario on recorded measurements, as
    ``hushfuse replay`` does: each sensor node sees its recorded z_k and decides what to send
    exactly as in a simulation; a missing reading is a sensor not scheduled at that step.

    Args:
        scenario: a built-in name, a path to a TOML file, or TOML text.
        measurements: a pandas DataFrame in the command line's long form (columns ``step``,
            ``sensor``, then the components; one row per reading, steps from 1, sensors
            0-based), or per sensor a 2-D array (T, m_i) (a list), or a 3-D array (T, N, m)
            when every sensor has m components; in arrays an all-NaN row is a missing reading.
        truth: optional, a 2-D array (T, n) or a DataFrame (``step``, ``x0``, ...), one row per
            step from 1. With truth there are metrics.
        seed: replaces the scenario's seed (the schemes' coins).
        trial: use the coins of this trial (to replay data of trial K of a simulation).

    Returns:
        ``steps``, ``available`` (bool array (T, N): which readings exist), ``schemes``: per
        variant a dict with ``name``, ``kind``, ``variant``, ``params``, ``mean`` (T, n),
        ``cov`` (T, n, n), ``links`` (str array (T, N): ``sent``, ``silent``,
        ``not_scheduled`` or ``missing``), ``bits`` (T, N: payload bits sent); and
        ``summary``: the one-trial summary (as :func:`run` returns) when truth is given,
        else None.

    Raises:
        DataError: bad data (the message names the row and the column, as the command line's).
        ScenarioError: the scenario cannot be read or is inconsistent.
        ValueError: arrays of the wrong shape; TypeError: inputs of the wrong type.
        RunError: a scheme failed on the data.
    """
    scenario = _check_scenario(scenario)
    if _is_frame(measurements) or _is_frame(truth):
        # A DataFrame is the command line's file layout: read as the command line reads it,
        # with its messages (line, row, column).
        meas_csv, meas_name = (
            (_frame_csv(measurements), "measurements (DataFrame)")
            if _is_frame(measurements)
            else (_measurements_csv(_measurement_arrays(measurements)), "measurements")
        )
        truth_name = "truth (DataFrame)" if _is_frame(truth) else "truth"
        truth_csv = None if truth is None else _truth_csv(truth)
        r = _hushfuse.replay_csv(scenario, meas_csv, meas_name, truth_csv, truth_name, seed, trial)
    else:
        # Arrays go to the library as they are (float64, row-major): no text in between.
        arrays = [np.ascontiguousarray(a, dtype=float) for a in _measurement_arrays(measurements)]
        t = None if truth is None else _truth_array(truth)
        r = _hushfuse.replay_arrays(scenario, arrays, t, seed, trial)
    for s in r["schemes"]:
        s["links"] = np.array(s["links"], dtype=str).reshape(r["available"].shape)
    if r["summary"] is not None:
        r["summary"] = _arrays(r["summary"])
    return r
