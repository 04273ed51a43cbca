#!/usr/bin/env python3
"""A random geometric graph scenario for whole-command measurements of a mesh (memory, time).

Usage: python3 scripts/mesh-rgg.py NODES TRIALS [--per-source] > rgg.toml

NODES − 1 scalar sensors placed uniformly in a 1 km square (Python's random, seed 7), the sink
at the centre, nodes within range linked so that the mean degree is about 20; Bernoulli 0.1
loss with one retry on every hop; the all-data KF (aggregated by the relays, or per source with
--per-source), 100 steps. The same construction as benches/mesh.rs (whose generator is Rust's,
so its graph differs in detail), as a file the command line runs:

    python3 scripts/mesh-rgg.py 1000 400 > /tmp/rgg.toml
    /usr/bin/time -f "%e s, peak RSS %M kB" hushfuse run /tmp/rgg.toml --threads 1 --out /tmp/rgg
"""
import math
import random
import sys


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if len(args) != 2:
        sys.exit(__doc__)
    nodes, trials = int(args[0]), int(args[1])
    per_source = "--per-source" in sys.argv
    n = nodes - 1
    rng = random.Random(7)
    at = [(rng.random() * 1000, rng.random() * 1000) for _ in range(n)] + [(500.0, 500.0)]
    name = lambda i: "sink" if i == n else f"s{i}"
    r = math.sqrt(20e6 / (math.pi * n))
    edges = [
        f'["{name(i)}", "{name(j)}"]'
        for i in range(len(at))
        for j in range(i + 1, len(at))
        if math.dist(at[i], at[j]) <= r
    ]
    sensors = "[[sensors]]\nH = [[1.0]]\nR = [[1.0]]\n" * n
    print(
        f'name = "mesh-rgg"\ntrials = {trials}\nsteps = 100\nseed = 1\n'
        '[model]\nkind = "matrix"\nF = [[0.95]]\nQ = [[1.0]]\n'
        "[prior]\nmean = [0.0]\ncov_diag = [1.0]\n"
        f"{sensors}\n"
        '[channel]\nkind = "bernoulli"\nloss = 0.1\narq = { max_retries = 1 }\n'
        f"[network]\naggregate = {'false' if per_source else 'true'}\n"
        f"edges = [{', '.join(edges)}]\n"
        '[[schemes]]\nkind = "centralized-kf"'
    )


if __name__ == "__main__":
    main()
