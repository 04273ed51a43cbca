"""hushfuse: multi-sensor state estimation when sensors must save bandwidth.

Sensors decide whether and with how many bits to talk (censoring, event triggering,
quantization, scheduling); a fusion center fuses what arrives and what the silence says.

- :func:`run` runs a scenario (Monte Carlo) and returns its summary with per-step numpy arrays;
- :func:`replay` runs every scheme of a scenario on recorded measurements (numpy arrays or a
  pandas DataFrame), exactly as ``hushfuse replay`` does;
- :func:`simulate` draws one simulated trial (truth and measurements) as the simulator does;
- :class:`Scheme` gives one scheme's sensor nodes and fusion center, to drive your own loop;
- :class:`Trial` steps one trial on your readings by the simulator's own step (any network);
- :class:`SchemeSpec`, :class:`SensorNode`, :class:`FusionCenter` and :func:`register` let you
  write a scheme of your own in Python that runs beside the built-in ones (``run``, ``replay``,
  the arena's ``budget=``), charged the same bits (see ``hushfuse._schemes``).

Scenarios are given as a built-in name (``builtins()``), a path to a TOML file, or TOML text.
Bad input raises :class:`ScenarioError` or :class:`DataError` (both :class:`InputError`, a
``ValueError``) with the command line's messages; a scheme that fails raises :class:`RunError`.
"""
from __future__ import annotations

import io as _io
import math as _math
import os as _os
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as _np

from . import _hushfuse
from ._hushfuse import (
    DataError,
    Feedback,
    InputError,
    LinearFusion,
    Received,
    RunError,
    Scheme,
    ScenarioError,
    System,
    Transmission,
    Trial,
    builtins,
)
from ._schemes import (
    Context,
    Estimate,
    FusionCenter,
    Knob,
    Measurement,
    Payload,
    QuantizedIndex,
    SchemeSpec,
    SensorNode,
    Silence,
    register,
    registered,
    scheme_tables as _scheme_tables,
    unregister,
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
    "Trial",
    "SensorNode",
    "FusionCenter",
    "Transmission",
    "Feedback",
    "InputError",
    "ScenarioError",
    "DataError",
    "RunError",
    "SchemeSpec",
    "Knob",
    "Context",
    "register",
    "unregister",
    "registered",
    "Measurement",
    "Estimate",
    "QuantizedIndex",
    "Payload",
    "Silence",
    "Received",
    "System",
    "LinearFusion",
]

# Per-step lists of a scheme's summary that become numpy arrays.
_PER_STEP = ("mse", "trace", "anees_per_step")


def _nan(v: Any) -> float:
    return _math.nan if v is None else float(v)


def _arrays(summary: Dict[str, Any]) -> Dict[str, Any]:
    """Per-step lists -> float numpy arrays (null, i.e. not finite, -> NaN)."""
    for s in summary["schemes"]:
        for key in _PER_STEP:
            s[key] = _np.array([_nan(v) for v in s[key]], dtype=float)
        s["rmse"] = {g: _np.array([_nan(v) for v in r], dtype=float) for g, r in s["rmse"].items()}
        ess = s.get("ess")
        if ess is not None:
            for key in ("mean_per_step", "min_per_step"):
                ess[key] = _np.array([_nan(v) for v in ess[key]], dtype=float)
    return summary


def _check_scenario(scenario: Any) -> str:
    if isinstance(scenario, (str,)):
        return scenario
    if hasattr(scenario, "__fspath__"):
        return _os.fspath(scenario)
    raise TypeError(
        f"scenario: expected a built-in name, a path or TOML text, got {type(scenario).__name__}"
    )


def run(
    scenario: str,
    trials: Optional[int] = None,
    seed: Optional[int] = None,
    threads: int = 0,
    out: Optional[Union[str, "_os.PathLike[str]"]] = None,
    resume: bool = False,
    shard: Optional[Union[str, Sequence[int]]] = None,
    report: bool = False,
    reproduce: bool = False,
    checkpoint_every: float = 10.0,
    loss: Optional[float] = None,
    schemes: Any = None,
    budget: Optional[float] = None,
    budgets: Optional[Sequence[float]] = None,
    budget_axis: str = "energy",
    tolerance: float = 0.02,
    pilot_trials: Optional[int] = None,
) -> Dict[str, Any]:
    """Runs a scenario (Monte Carlo), as ``hushfuse run`` does, and returns its summary.

    Args:
        scenario: a built-in name (see :func:`builtins`), a path to a TOML file, or TOML text.
        trials: replaces the scenario's number of trials.
        seed: replaces the scenario's seed.
        threads: worker threads (0: one per core); the result does not depend on it.
        out: an output folder: the run writes there exactly the files of ``hushfuse run
            --out`` (summary.json, per_step.csv, plots, scenario_as_run.toml, a manifest), and
            checkpoints its finished trials every ``checkpoint_every`` seconds. With ``budget``
            or ``budgets``: the files of ``hushfuse run --budgets ... --out`` (calibration.json,
            best_per_budget.md, one ``budget-X/`` folder per budget, the plots, a manifest),
            written by the same code; a calibration is not checkpointed.
        resume: continue the interrupted run whose checkpoint is in ``out`` (the same
            arguments; from the first trial when there is none). Not with ``budget(s)``: a
            calibration keeps no checkpoint to continue from (nor shards, nor reproductions).
        shard: ``"I/N"`` or ``(I, N)``: run only shard I of N (1-based) into ``out``;
            ``hushfuse merge`` turns the N shard files into the whole run's folder.
        report: also write report.html (needs ``out``); with ``budget(s)``, the arena's page
            (the first budget's run with the calibration and best-per-budget tables).
        reproduce: a reproduction, as ``hushfuse reproduce``: also reproduction.md.
        loss: as ``--loss P``: every sensor behind a Bernoulli link losing each packet with
            probability P (the same losses for every scheme), and a "... (loss-aware)" copy of
            every scheme whose center has a loss-aware fusion, after the published ones.
        schemes: scheme entries added to the scenario's: kind names, registered
            :class:`SchemeSpec` subclasses, or dicts (``{"kind": ..., "label": ..., params}``).
        budget: the arena, as ``--budget B``: every scheme's knob calibrated so that it spends
            B per step on ``budget_axis`` (``energy``, the default: µJ of the sensors'
            radios, what a battery-powered deployment pays; or ``payload``, ``frame``,
            ``total`` bits) within ``tolerance`` (relative), on pilot runs of
            ``pilot_trials`` trials (default: the scenario's). Returns the summary at that
            budget with ``budget``, ``axis`` and ``calibration`` (per scheme: ``label``,
            ``kind``, ``knob``, ``value``, ``target``, ``achieved``, ``status``); with
            ``out``, also ``out`` and ``files``.
        budgets: several budgets, as ``--budgets``: returns ``budgets``, ``axis``,
            ``calibration`` (per budget, per scheme) and ``runs`` (per budget, its summary);
            with ``out``, also ``out`` and ``files``.

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
        out = _os.fspath(out)
    if budget is not None and budgets is not None:
        raise ValueError("give budget= or budgets=, not both")
    many = None
    if budget is not None:
        many = [_number(budget, "budget")]
    elif budgets is not None:
        many = [_number(b, "budgets") for b in _np.atleast_1d(_np.asarray(budgets, dtype=object))]
    r = _hushfuse.run(
        _check_scenario(scenario), trials, seed, threads, out, resume, shard, report, reproduce,
        checkpoint_every, loss, _scheme_tables(schemes), many, budget_axis, tolerance,
        pilot_trials,
    )
    if many is None:
        return r if "schemes" not in r else _arrays(r)
    runs = [_arrays(x) for x in r["runs"]]
    if budget is None:
        r["runs"] = runs
        return r
    out_r = runs[0]
    out_r.update(budget=many[0], axis=r["axis"], calibration=r["calibration"][0],
                 evaluations=r["evaluations"])
    out_r.update({k: r[k] for k in ("out", "files") if k in r})
    return out_r


def _number(v: Any, name: str) -> float:
    if isinstance(v, (bool, _np.bool_)) or not isinstance(v, (int, float, _np.integer, _np.floating)):
        raise TypeError(f"{name}: expected a number of bits (or µJ) per step, got {type(v).__name__}")
    v = float(v)
    if not (_math.isfinite(v) and v > 0):
        raise ValueError(f"{name}: expected a positive finite number, got {v}")
    return v


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
    if isinstance(v, (float, _np.floating)):
        return "" if _math.isnan(v) else _fmt(v)
    if isinstance(v, (bool, _np.bool_)):
        return str(v)
    if isinstance(v, (int, _np.integer)):
        return str(int(v))
    return "" if v is None else str(v)


def _frame_csv(frame: Any) -> str:
    import csv

    out = _io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow([str(c) for c in frame.columns])
    for row in frame.itertuples(index=False, name=None):
        w.writerow([_cell(v) for v in row])
    return out.getvalue()


def _real(a: Any, name: str) -> _np.ndarray:
    """``a`` as a float array; booleans, complex numbers, strings and objects are refused
    (numpy would turn True into 1.0 and drop an imaginary part without a word)."""
    arr = _np.asarray(a)
    if arr.dtype.kind not in "fiu":
        raise TypeError(
            f"{name}: expected real numbers (a float array), got an array of dtype {arr.dtype}"
        )
    return arr.astype(float, copy=False)


def _measurement_arrays(measurements: Any) -> List[_np.ndarray]:
    """A 3-D array (T, N, m) or a sequence of N 2-D arrays (T, m_i) -> list of 2-D arrays."""
    if isinstance(measurements, _np.ndarray):
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


def _measurements_csv(arrays: Sequence[_np.ndarray]) -> str:
    """Long-form CSV of per-sensor arrays; an all-NaN row is a missing reading."""
    width = max(a.shape[1] for a in arrays)
    out = _io.StringIO()
    out.write("step,sensor," + ",".join(f"z{j}" for j in range(width)) + "\n")
    steps = arrays[0].shape[0]
    for i, a in enumerate(arrays):
        nan = _np.isnan(a)
        part = nan.any(axis=1) & ~nan.all(axis=1)
        if part.any():
            k = int(_np.argmax(part))
            raise ValueError(
                f"measurements[{i}] row {k} (step {k + 1}): some components are NaN and others "
                "not (an all-NaN row means no reading)"
            )
        inf = _np.isinf(a).any(axis=1)
        if inf.any():
            k = int(_np.argmax(inf))
            raise ValueError(f"measurements[{i}] row {k} (step {k + 1}): a component is not finite")
    for k in range(steps):
        for i, a in enumerate(arrays):
            row = a[k]
            if _np.isnan(row).all():
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
    out = _io.StringIO()
    out.write("step," + ",".join(f"x{j}" for j in range(t.shape[1])) + "\n")
    for k, row in enumerate(t):
        out.write(f"{k + 1}," + ",".join(_fmt(v) for v in row) + "\n")
    return out.getvalue()


def _truth_array(truth: Any) -> _np.ndarray:
    t = _real(truth, "truth")
    if t.ndim == 1:
        t = t[:, None]
    if t.ndim != 2:
        raise ValueError(f"truth: expected a 2-D array (steps, state components), got shape {t.shape}")
    return _np.ascontiguousarray(t, dtype=float)


def measurements_frame(measurements: Any) -> "Any":
    """Per-sensor arrays (or a 3-D array) as the long-form pandas DataFrame ``replay`` and the
    command line read: columns ``step``, ``sensor``, ``z0``, ``z1``, ...; all-NaN rows left out."""
    import pandas as pd

    text = _io.StringIO(_measurements_csv(_measurement_arrays(measurements)))
    if int(pd.__version__.split(".")[0]) >= 3:
        return pd.read_csv(text)  # round-trip precision is the default from pandas 3 on
    return pd.read_csv(text, float_precision="round_trip")


def replay(
    scenario: str,
    measurements: Any,
    truth: Any = None,
    seed: Optional[int] = None,
    trial: int = 0,
    schemes: Any = None,
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
        schemes: scheme entries added to the scenario's (as :func:`run`'s).

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
        r = _hushfuse.replay_csv(
            scenario, meas_csv, meas_name, truth_csv, truth_name, seed, trial, _scheme_tables(schemes)
        )
    else:
        # Arrays go to the library as they are (float64, row-major): no text in between.
        arrays = [_np.ascontiguousarray(a, dtype=float) for a in _measurement_arrays(measurements)]
        t = None if truth is None else _truth_array(truth)
        r = _hushfuse.replay_arrays(scenario, arrays, t, seed, trial, _scheme_tables(schemes))
    for s in r["schemes"]:
        s["links"] = _np.array(s["links"], dtype=str).reshape(r["available"].shape)
    if r["summary"] is not None:
        r["summary"] = _arrays(r["summary"])
    return r


# The namespace is the API: the helpers' names are not part of it.
del annotations, Any, Dict, List, Optional, Sequence, Union
