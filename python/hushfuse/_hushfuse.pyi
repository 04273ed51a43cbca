"""Type stubs of the compiled module ``hushfuse._hushfuse`` (see ``python/src/lib.rs``)."""
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class InputError(ValueError):
    """Bad input: a scenario or recorded data that cannot be used."""

class ScenarioError(InputError):
    """A scenario that cannot be read or is inconsistent (names the file and the field)."""

class DataError(InputError):
    """Recorded data that cannot be replayed (names the file, line, row and column)."""

class RunError(RuntimeError):
    """A scheme could not take a step (names the scheme and the step)."""

def run(
    scenario: str,
    trials: Optional[int] = None,
    seed: Optional[int] = None,
    threads: int = 0,
    out: Optional[str] = None,
    resume: bool = False,
    shard: Optional[str] = None,
    report: bool = False,
    reproduce: bool = False,
    checkpoint_every: float = 10.0,
    loss: Optional[float] = None,
) -> Dict[str, Any]: ...
def simulate(scenario: str, trial: int = 0, seed: Optional[int] = None) -> Dict[str, Any]: ...
def replay_csv(
    scenario: str,
    measurements_csv: str,
    measurements_name: str,
    truth_csv: Optional[str] = None,
    truth_name: str = "truth",
    seed: Optional[int] = None,
    trial: int = 0,
) -> Dict[str, Any]: ...
def replay_arrays(
    scenario: str,
    measurements: Sequence[npt.NDArray[np.float64]],
    truth: Optional[npt.NDArray[np.float64]] = None,
    seed: Optional[int] = None,
    trial: int = 0,
) -> Dict[str, Any]: ...
def variants(scenario: str) -> List[Tuple[str, str, Dict[str, Any]]]: ...
def builtins() -> List[Tuple[str, str]]: ...

class Transmission:
    """What one sensor put on the network at one step."""

    @staticmethod
    def silent() -> Transmission: ...
    @staticmethod
    def measurement(z: Any) -> Transmission: ...
    @staticmethod
    def estimate(x: Any) -> Transmission: ...
    @staticmethod
    def quantized_index(index: int, bits: int) -> Transmission: ...
    @staticmethod
    def payload(data: bytes, bits: int) -> Transmission: ...
    @property
    def sent(self) -> bool: ...
    @property
    def kind(self) -> str:
        """"silent", "measurement", "estimate" or "frame"."""
    @property
    def bits(self) -> int:
        """Payload bits (0 for a silence)."""
    @property
    def frame_bits(self) -> int:
        """Bits of the whole 802.15.4 MAC frame (0 for a silence)."""
    @property
    def value(self) -> Union[npt.NDArray[np.float64], bytes, None]:
        """The sent vector, a frame's octets, or None for a silence."""

class Feedback:
    """What the fusion center tells the sensors before the next step."""

    @property
    def kind(self) -> str: ...
    def bits(self, n_sensors: int) -> int: ...
    @staticmethod
    def prediction(mean: Any, cov: Any = None) -> "Feedback":
        """The fused prediction as feedback (downlink: 32 bits per number)."""
    @property
    def mean(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def cov(self) -> Optional[npt.NDArray[np.float64]]: ...

class Received:
    """What a Python fusion center finds from one sensor at one step."""

    @property
    def kind(self) -> str:
        """"measurement", "estimate", "payload", "silent" or "not_scheduled"."""
    @property
    def arrived(self) -> bool: ...
    @property
    def value(self) -> Union[npt.NDArray[np.float64], bytes, None]: ...
    @property
    def index(self) -> Optional[int]: ...

class System:
    """The system a scheme estimates."""

    n_sensors: int
    state_dim: int
    meas_dims: List[int]
    F: npt.NDArray[np.float64]
    Q: npt.NDArray[np.float64]
    H: List[Optional[npt.NDArray[np.float64]]]
    R: List[npt.NDArray[np.float64]]
    prior: Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]

class LinearFusion:
    """The library's Kalman arithmetic (prediction, information-form fusion)."""

    def __init__(self, system: System) -> None: ...
    def predict(self, mean: Any, cov: Any) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def start(self, mean: Any, cov: Any) -> None: ...
    def add(self, i: int, z: Any, r: Any = None) -> None: ...
    def finish(self) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...

def register_scheme(kind: str, label: str, summary: str, params: List[Tuple[str, Optional[str], str]], knob: Any, factory: Any) -> None: ...
def unregister_scheme(kind: str) -> bool: ...
def registered_schemes() -> List[str]: ...

class SensorNode:
    """The sensor side of a scheme: one node, one step per call."""

    @property
    def index(self) -> int: ...
    @property
    def dim(self) -> int: ...
    def step(
        self, k: int, z: Any, feedback: Optional[Feedback] = None
    ) -> Transmission:
        """Processes measurement z of step k (k >= 1) with the center's feedback of step k - 1."""

class FusionCenter:
    """The fusion side of a scheme."""

    def step(self, k: int, inbox: Sequence[Optional[Transmission]]) -> None:
        """Fuses step k's inbox: one Transmission per sensor, None for not scheduled / no reading."""
    def estimate(self) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(mean (n,), covariance (n, n)) after the last step."""
    def feedback(self) -> Optional[Feedback]: ...
    def ess(self) -> Optional[float]: ...

class Trial:
    """One trial of one scheme variant stepped on your readings by the simulator's own step
    (sensors, schedule, the link over any network, fusion, feedback)."""

    def __init__(
        self, scenario: str, variant: int = 0, trial: int = 0, seed: Optional[int] = None
    ) -> None: ...
    def step(self, k: int, readings: List[Any]) -> Dict[str, Any]:
        """Step k (1, 2, ... in order) on one reading per sensor: mean, cov, links, bits,
        traffic and, over a multi-hop network, nodes."""
    @property
    def label(self) -> str: ...
    @property
    def steps(self) -> int: ...
    @property
    def n_sensors(self) -> int: ...

class Scheme:
    """One variant of a scenario built as the simulator builds it for one trial."""

    def __init__(
        self,
        scenario: str,
        variant: int = 0,
        trial: int = 0,
        seed: Optional[int] = None,
        steps: Optional[int] = None,
    ) -> None: ...
    @property
    def sensors(self) -> List[SensorNode]: ...
    @property
    def center(self) -> FusionCenter: ...
    @property
    def label(self) -> str: ...
    @property
    def kind(self) -> str: ...
    @property
    def variant(self) -> int: ...
    @property
    def steps(self) -> int: ...
    @property
    def state_dim(self) -> int: ...
    def allows(self, k: int, i: int) -> bool:
        """Whether the network lets sensor i send at step k."""
