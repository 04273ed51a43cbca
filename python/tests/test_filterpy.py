"""hushfuse's centralized Kalman filter against FilterPy's KalmanFilter on the same model and
the same data: every step's mean and covariance to 1e-10, with all readings and with some
missing (a missing reading is no update for that sensor)."""
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

import hushfuse

F = np.array([[1.0, 0.5], [0.0, 1.0]])
Q = np.array([[0.02, 0.05], [0.05, 0.2]])
X0 = np.array([1.0, -0.5])
P0 = np.array([[2.0, 0.3], [0.3, 1.0]])
H0 = np.array([[1.0, 0.0]])
R0 = np.array([[0.8]])
H1 = np.array([[1.0, 0.5], [0.0, 1.0]])
R1 = np.array([[2.0, 0.3], [0.3, 1.0]])

SCENARIO = f"""
name = "kf-vs-filterpy"
trials = 1
steps = 30
seed = 5

[model]
kind = "matrix"
F = {F.tolist()}
Q = {Q.tolist()}

[prior]
mean = {X0.tolist()}
cov = {P0.tolist()}

[groups]
position = [0]
velocity = [1]

[[sensors]]
H = {H0.tolist()}
R = {R0.tolist()}

[[sensors]]
H = {H1.tolist()}
R = {R1.tolist()}

[[schemes]]
kind = "centralized-kf"
"""

SENSORS = [(H0, R0), (H1, R1)]


def filterpy_run(measurements, available):
    kf = KalmanFilter(dim_x=2, dim_z=3)
    kf.x = X0.copy()
    kf.P = P0.copy()
    kf.F = F
    kf.Q = Q
    means, covs = [], []
    for k in range(len(available)):
        kf.predict()
        rows = [i for i in range(len(SENSORS)) if available[k, i]]
        if rows:
            z = np.concatenate([measurements[i][k] for i in rows])
            H = np.vstack([SENSORS[i][0] for i in rows])
            R = np.zeros((len(z), len(z)))
            o = 0
            for i in rows:
                m = SENSORS[i][1].shape[0]
                R[o : o + m, o : o + m] = SENSORS[i][1]
                o += m
            kf.dim_z = len(z)  # FilterPy reshapes z to dim_z; fewer readings, a smaller z
            kf.update(z, R=R, H=H)
        means.append(kf.x.copy())
        covs.append(kf.P.copy())
    return np.array(means), np.array(covs)


@pytest.mark.parametrize("missing", [False, True])
def test_centralized_kf_matches_filterpy(missing):
    data = hushfuse.simulate(SCENARIO)
    meas = [m.copy() for m in data["measurements"]]
    if missing:
        meas[1][5:9] = np.nan  # sensor 1 has no reading at steps 6..9
        meas[0][7] = np.nan  # nor sensor 0 at step 8: no update at all there
    r = hushfuse.replay(SCENARIO, meas, data["truth"])
    kf = r["schemes"][0]
    assert kf["kind"] == "centralized-kf"
    available = r["available"]
    assert available.sum() == (2 * 30 - (5 if missing else 0))
    # hushfuse delivers each reading as the IEEE single it is priced as (issue 26): FilterPy
    # gets the same singles (NaN stays NaN).
    sent = [m.astype(np.float32).astype(np.float64) for m in meas]
    mean, cov = filterpy_run(sent, available)
    assert kf["mean"].shape == (30, 2) and kf["cov"].shape == (30, 2, 2)
    np.testing.assert_allclose(kf["mean"], mean, rtol=0, atol=1e-10)
    np.testing.assert_allclose(kf["cov"], cov, rtol=0, atol=1e-10)
    # The filter did something: its covariance shrank well below the prior's.
    assert cov[-1].trace() < 0.5 * P0.trace()
    # Missing readings: nothing sent, marked missing.
    if missing:
        assert kf["links"][5, 1] == "missing" and kf["bits"][5, 1] == 0
        assert kf["links"][4, 1] == "sent" and kf["bits"][4, 1] == 64
