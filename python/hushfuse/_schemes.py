"""Your own scheme in Python: base classes, the declaration, messages, registration.

A scheme is a sensor node (:class:`SensorNode`), a fusion center (:class:`FusionCenter`) and a
declaration (:class:`SchemeSpec`: its kind name, parameters, bandwidth knob, what its messages
carry) registered with :func:`register`. Once registered, its kind runs wherever a built-in
kind does (scenario files, ``run(..., schemes=[...])``, ``replay``, the arena's ``budget=``),
with the same truth, noise, schedule and link, its messages priced by the same rules.

Threads: trials run on the engine's worker threads; each call into your objects holds the GIL
for that call. Each trial gets fresh objects, and each object its own ``numpy.random.Generator``
(``self.rng``) seeded from the trial's seed: results are the same for any ``threads=``, as long
as your code keeps no state outside its objects (no module globals, no ``numpy.random`` global
state).
"""
from __future__ import annotations

import abc as _abc
import json as _json
import math as _math
from typing import Any as _Any, Dict as _Dict, Optional as _Optional

import numpy as _np

from . import _hushfuse

_Transmission = _hushfuse.Transmission


def Measurement(z: _Any) -> "_hushfuse.Transmission":
    """A measurement message: z (a number, a list or an array), 32 bits per component."""
    return _Transmission.measurement(z)


def Estimate(x: _Any) -> "_hushfuse.Transmission":
    """A state-estimate message: x, 32 bits per component."""
    return _Transmission.estimate(x)


def QuantizedIndex(index: int, bits: int) -> "_hushfuse.Transmission":
    """A quantization index 0 <= index < 2**bits in ``bits`` payload bits (an 802.15.4 frame
    of 11 + ceil(bits / 8) octets); the center reads it back as ``received.index``."""
    return _Transmission.quantized_index(int(index), int(bits))


def Payload(data: bytes, bits: int) -> "_hushfuse.Transmission":
    """A raw payload of ``bits`` bits in ``data`` (ceil(bits / 8) octets); the center reads it
    back as ``received.value`` (bytes)."""
    return _Transmission.payload(bytes(data), int(bits))


def Silence() -> "_hushfuse.Transmission":
    """The sensor stays silent (returning None means the same)."""
    return _Transmission.silent()


class Context:
    """What a node is built with: ``params`` (the scheme's parameters, defaults filled in),
    ``system`` (:class:`System`: F, Q, H, R, prior), ``trial`` (None outside a run),
    ``index`` (the sensor's index; None for the center), ``rng`` (its own generator) and
    ``kind``."""

    __slots__ = ("params", "system", "trial", "index", "rng", "kind")

    def __init__(self, kind, params, system, trial, index, rng):
        self.kind = kind
        self.params = params
        self.system = system
        self.trial = trial
        self.index = index
        self.rng = rng


class SensorNode(_abc.ABC):
    """Base class of the sensor node of your scheme. Override :meth:`step`; the constructor
    receives a :class:`Context` (call ``super().__init__(ctx)``, which sets ``self.params``,
    ``self.system``, ``self.index``, ``self.trial`` and ``self.rng``). The sensor nodes of the
    built-in schemes (``Scheme(...).sensors``) are SensorNodes too."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.params = ctx.params
        self.system = ctx.system
        self.index = ctx.index
        self.trial = ctx.trial
        self.rng = ctx.rng

    @_abc.abstractmethod
    def step(self, k: int, z: _np.ndarray, feedback: _Optional[_Any]) -> _Any:
        """Step k (from 1): measurement z (float array), the center's feedback of step k - 1
        (None without). Return a message (:func:`Measurement`, :func:`Estimate`,
        :func:`QuantizedIndex`, :func:`Payload`) or :func:`Silence` / None."""


class FusionCenter(_abc.ABC):
    """Base class of the fusion center of your scheme. Override :meth:`step` and
    :meth:`estimate` (and :meth:`feedback` for a scheme with feedback). The constructor
    receives a :class:`Context` (``index`` None)."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.params = ctx.params
        self.system = ctx.system
        self.trial = ctx.trial
        self.rng = ctx.rng

    @_abc.abstractmethod
    def step(self, k: int, inbox: list) -> None:
        """Fuses step k: ``inbox`` has one :class:`Received` per sensor, in sensor order
        (``kind``: "measurement", "estimate", "payload", "silent" — chose not to send, or the
        packet was lost — or "not_scheduled"; ``value``; ``index`` of a quantized index)."""

    @_abc.abstractmethod
    def estimate(self) -> tuple:
        """(mean (n,), cov (n, n)) after the last step; the prior before the first."""

    def feedback(self) -> _Any:
        """Feedback for the sensors' next step (:meth:`Feedback.prediction`), or None."""
        return None


SensorNode.register(_hushfuse.SensorNode)
FusionCenter.register(_hushfuse.FusionCenter)


class Knob:
    """A scheme's bandwidth knob: the parameter ``name`` that sets how much it talks, its range
    [lo, hi] (hi None: open, found by the calibrator by quadrupling), its ``scale`` ("linear"
    or "log"), ``integer`` values only, and which way bits move as it grows (``grows``:
    "more_bits" or "fewer_bits", a threshold's)."""

    def __init__(self, name: str, lo: float = 0.0, hi: _Optional[float] = None,
                 scale: str = "linear", integer: bool = False, grows: str = "fewer_bits"):
        self.name, self.lo, self.hi = str(name), float(lo), None if hi is None else float(hi)
        self.scale, self.integer, self.grows = str(scale), bool(integer), str(grows)

    def __repr__(self) -> str:
        return (f"Knob({self.name!r}, lo={self.lo}, hi={self.hi}, scale={self.scale!r}, "
                f"integer={self.integer}, grows={self.grows!r})")


class SchemeSpec:
    """The declaration of a scheme: subclass it, set the class attributes, :func:`register`.

    - ``kind``: its name in scenarios (``[[schemes]] kind = "..."``, ``schemes=[...]``);
    - ``label``: the default curve label (default: ``kind``); ``summary``: one line;
    - ``params``: parameter name -> default (None: required); numbers, strings or flags;
    - ``knob``: its :class:`Knob` (one of ``params``) or None;
    - ``carries``: what its messages carry, in words (e.g. "measurement");
    - ``sensor`` / ``center``: its :class:`SensorNode` and :class:`FusionCenter` classes.
    """

    kind: str = ""
    label: _Optional[str] = None
    summary: str = ""
    params: _Dict[str, _Any] = {}
    knob: _Optional[Knob] = None
    carries: str = "measurement"
    sensor: type = SensorNode
    center: type = FusionCenter


def _toml_value(name: str, v: _Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not _math.isfinite(v):
            raise ValueError(f"params[{name!r}]: expected a finite number, got {v}")
        return repr(v)
    if isinstance(v, str):
        return _json.dumps(v)
    raise TypeError(f"params[{name!r}]: expected a number, a string or a flag, got {type(v).__name__}")


def _factory(spec: type):
    kind = spec.kind
    defaults = dict(spec.params)
    sensor, center = spec.sensor, spec.center

    def make(params, system, trial, seed):
        full = dict(defaults)
        full.update(params)
        gens = [_np.random.default_rng(s) for s in _np.random.SeedSequence(seed).spawn(system.n_sensors + 1)]
        nodes = [sensor(Context(kind, full, system, trial, i, gens[i + 1])) for i in range(system.n_sensors)]
        return nodes, center(Context(kind, full, system, trial, None, gens[0]))

    return make


def register(spec: type) -> type:
    """Registers a :class:`SchemeSpec` subclass (usable as a class decorator; registering a
    kind again replaces it). Its kind then runs wherever a built-in kind does."""
    if not (isinstance(spec, type) and issubclass(spec, SchemeSpec)):
        raise TypeError("register: expected a subclass of hushfuse.SchemeSpec")
    if not spec.kind or not isinstance(spec.kind, str):
        raise ValueError(f"{spec.__name__}.kind: expected the scheme's name (a non-empty string)")
    for role, base in (("sensor", SensorNode), ("center", FusionCenter)):
        cls = getattr(spec, role)
        if not (isinstance(cls, type) and issubclass(cls, base)) or cls is base:
            raise TypeError(f"{spec.__name__}.{role}: expected a subclass of hushfuse.{base.__name__}")
        if getattr(cls, "__abstractmethods__", None):
            missing = ", ".join(sorted(cls.__abstractmethods__))
            raise TypeError(f"{spec.__name__}.{role} ({cls.__name__}) does not define {missing}")
    params = [(n, None if d is None else _toml_value(n, d), "") for n, d in spec.params.items()]
    knob = spec.knob
    if knob is not None and knob.name not in spec.params:
        raise ValueError(f"{spec.__name__}.knob: {knob.name!r} is not one of its params ({', '.join(spec.params)})")
    knob_args = None if knob is None else (knob.name, knob.lo, knob.hi, knob.scale, knob.integer, knob.grows)
    summary = spec.summary or (spec.__doc__ or "").strip().split("\n")[0]
    summary = f"{summary} (Python; messages carry: {spec.carries})".strip()
    _hushfuse.register_scheme(spec.kind, spec.label or spec.kind, summary, params, knob_args, _factory(spec))
    return spec


def unregister(kind: _Any) -> bool:
    """Removes a registered Python scheme kind (a name or its :class:`SchemeSpec`)."""
    return _hushfuse.unregister_scheme(getattr(kind, "kind", kind))


def registered() -> list:
    """The registered Python scheme kinds."""
    return list(_hushfuse.registered_schemes())


def scheme_tables(schemes: _Any) -> _Optional[str]:
    """``schemes=`` of run/replay (kind names, SchemeSpec classes or dicts with ``kind``) as
    the JSON the library reads; None for None."""
    if schemes is None:
        return None
    if isinstance(schemes, (str, dict)) or isinstance(schemes, type):
        schemes = [schemes]
    out = []
    for i, s in enumerate(schemes):
        if isinstance(s, type) and issubclass(s, SchemeSpec):
            s = {"kind": s.kind}
        elif isinstance(s, str):
            s = {"kind": s}
        if not isinstance(s, dict) or "kind" not in s:
            raise TypeError(f"schemes[{i}]: expected a kind name, a SchemeSpec subclass or a dict with 'kind'")
        out.append({str(k): (float(v) if isinstance(v, _np.floating) else int(v) if isinstance(v, _np.integer) else v)
                    for k, v in s.items()})
    return _json.dumps(out)
