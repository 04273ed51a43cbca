"""Type stubs of the ``hushfuse`` package (docstrings in ``__init__.py``)."""
from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

from ._hushfuse import (
    DataError as DataError,
    Feedback as Feedback,
    InputError as InputError,
    LinearFusion as LinearFusion,
    Received as Received,
    RunError as RunError,
    Scheme as Scheme,
    ScenarioError as ScenarioError,
    System as System,
    Transmission as Transmission,
    builtins as builtins,
)
from ._schemes import (
    Context as Context,
    Estimate as Estimate,
    FusionCenter as FusionCenter,
    Knob as Knob,
    Measurement as Measurement,
    Payload as Payload,
    QuantizedIndex as QuantizedIndex,
    SchemeSpec as SchemeSpec,
    SensorNode as SensorNode,
    Silence as Silence,
    register as register,
    registered as registered,
    unregister as unregister,
)

__version__: str

ScenarioLike = Union[str, "PathLike[str]"]
Measurements = Union[Any, npt.NDArray[np.float64], Sequence[npt.NDArray[np.float64]]]

def run(
    scenario: ScenarioLike,
    trials: Optional[int] = None,
    seed: Optional[int] = None,
    threads: int = 0,
    out: Optional[Union[str, "PathLike[str]"]] = None,
    resume: bool = False,
    shard: Union[None, str, Sequence[int]] = None,
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
) -> Dict[str, Any]: ...
def simulate(scenario: ScenarioLike, trial: int = 0, seed: Optional[int] = None) -> Dict[str, Any]: ...
def variants(scenario: ScenarioLike) -> List[Dict[str, Any]]: ...
def measurements_frame(measurements: Measurements) -> Any: ...
def replay(
    scenario: ScenarioLike,
    measurements: Measurements,
    truth: Union[None, Any, npt.NDArray[np.float64]] = None,
    seed: Optional[int] = None,
    trial: int = 0,
    schemes: Any = None,
) -> Dict[str, Any]: ...
