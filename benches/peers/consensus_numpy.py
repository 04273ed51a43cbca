"""The numpy peer of hushfuse's consensus on information (Battistelli & Chisci 2014) on a ring of
peers: the work of `benches/peers/consensus-ring.toml`, vectorised over trials as a numpy user
writes it.

A 1-D constant-velocity target (dt = 1, sigma2 = 0.1: Q = sigma2 [[1/3, 1/2], [1/2, 1]]),
prior N([0, 1], diag(10, 1)) of x0; N nodes on a ring, node i reads the position with noise
variance (1, 2, 4, 8)[i % 4]; Metropolis weights (1/3 on each neighbour and on itself: every
degree is 2); every step each node corrects with its reading, runs L consensus iterations on
its information pair (Omega, q) with its neighbours, and predicts. Every trial keeps its own
pairs (over lossy links they differ), as hushfuse does. Recorded per step as hushfuse's summary
does: the squared error and the NEES, each averaged over the nodes, summed over trials.

Usage: python3 consensus_numpy.py [--trials 1000] [--steps 100] [--nodes 100] [--iterations 10]
Prints the steady-state MSE (mean over nodes, steps > steps/2) and the ANEES, and the seconds.
"""
import argparse
import time

import numpy as np


def run(trials, steps, nodes, iterations, seed=9):
    rng = np.random.default_rng(seed)
    a = np.array([[1.0, 1.0], [0.0, 1.0]])
    s2 = 0.1
    q = s2 * np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]])
    r = np.array([1.0, 2.0, 4.0, 8.0])[np.arange(nodes) % 4]
    prior_mean = np.array([0.0, 1.0])
    prior_cov = np.diag([10.0, 1.0])
    # Every node starts from the prediction of the prior of x0.
    p0 = a @ prior_cov @ a.T + q
    x0 = a @ prior_mean
    omega = np.broadcast_to(np.linalg.inv(p0), (trials, nodes, 2, 2)).copy()
    info = np.broadcast_to(np.linalg.inv(p0) @ x0, (trials, nodes, 2)).copy()
    # Truth: x0 from the prior, then the model.
    lq = np.linalg.cholesky(q)
    truth = prior_mean + rng.standard_normal((trials, 2)) @ np.linalg.cholesky(prior_cov).T
    u = np.zeros((nodes, 2, 2))
    u[:, 0, 0] = 1.0 / r
    w_self, w_side = 1.0 / 3.0, 1.0 / 3.0
    se_sum = np.zeros(steps)
    nees_sum = np.zeros(steps)
    for k in range(steps):
        truth = truth @ a.T + rng.standard_normal((trials, 2)) @ lq.T
        z = truth[:, None, 0] + rng.standard_normal((trials, nodes)) * np.sqrt(r)
        # Correct: Omega += H^T R^-1 H, q += H^T R^-1 z.
        omega = omega + u
        info[:, :, 0] += z / r
        # L consensus iterations on the ring.
        for _ in range(iterations):
            omega = w_self * omega + w_side * (np.roll(omega, 1, axis=1) + np.roll(omega, -1, axis=1))
            info = w_self * info + w_side * (np.roll(info, 1, axis=1) + np.roll(info, -1, axis=1))
        cov = np.linalg.inv(omega)
        mean = np.einsum("tnij,tnj->tni", cov, info)
        err = mean - truth[:, None, :]
        se_sum[k] = (err**2).sum(axis=2).mean(axis=1).sum()
        nees_sum[k] = np.einsum("tni,tnij,tnj->tn", err, omega, err).mean(axis=1).sum()
        # Predict.
        cov_p = a @ cov @ a.T + q
        omega = np.linalg.inv(cov_p)
        info = np.einsum("tnij,tnj->tni", omega, mean @ a.T)
    steady = slice(steps // 2 + 1, steps)
    return se_sum[steady].mean() / trials, nees_sum[steady].mean() / trials / 2


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--trials", type=int, default=1000)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--nodes", type=int, default=100)
    p.add_argument("--iterations", type=int, default=10)
    args = p.parse_args()
    t0 = time.perf_counter()
    mse, anees = run(args.trials, args.steps, args.nodes, args.iterations)
    print(f"steady MSE {mse:.4f}  ANEES {anees:.3f}  ({time.perf_counter() - t0:.2f} s)")


if __name__ == "__main__":
    main()
