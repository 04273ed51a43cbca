"""Shared pieces of the Python tests: the repository, the command-line binary, scenarios."""
import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "replay"

# A censoring particle filter (Zheng et al.'s (2014) CFwMD with feedback) and its all-send bound, small.
CENSORED_PF = """
name = "pf-small"
trials = 6
steps = 15
seed = 2014
steady_state_from = 1

[model]
kind = "constant-velocity-1d"
dt = 1.0
sigma2 = 4.0
noise = "discrete"

[initial_truth]
mean = [0.0, 10.0]
cov_diag = [0.0, 0.0]

[prior]
mean = [0.0, 10.0]
cov_diag = [1.0, 1.0]

[groups]
position = [0]
velocity = [1]

[[sensors]]
observe = [0]
R_diag = [1.0]
[[sensors]]
observe = [0]
R_diag = [1.0]

[[schemes]]
kind = "censored-pf"
label = "CFwMD"
policy = "nis"
l = 1.0
fusion = "full"
feedback = "prediction"
particles = 300

[[schemes]]
kind = "centralized-kf"
"""


def binary() -> Path:
    """The command line, built by scripts/test-python.sh (HUSHFUSE_BIN) or cargo."""
    env = os.environ.get("HUSHFUSE_BIN")
    path = Path(env) if env else ROOT / "target" / "release" / "hushfuse"
    if not path.exists():
        pytest.fail(f"the hushfuse binary is missing at {path}: run `cargo build --release` first")
    return path


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(binary()), *args], cwd=cwd, capture_output=True, text=True, check=False
    )


def plain(x):
    """numpy arrays -> lists, NaN -> None: the JSON form, to compare with summary.json."""
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def read_json(path: Path):
    with open(path) as f:
        return json.load(f)
