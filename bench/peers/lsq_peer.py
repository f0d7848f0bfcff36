#!/usr/bin/env python3
"""Peer for needle-lsq: SciPy's least_squares on the problems of
crates/lsq/examples/peer_problems.rs, printing final cost (1/2 sum r^2),
evaluations and wall time.

Install and run:
    python3 -m pip install scipy numpy
    python3 bench/peers/lsq_peer.py

Our side:
    cargo run --release -p needle-lsq --example peer_problems

Both use forward finite differences ('2-point'), ftol = xtol = gtol = 1e-10,
and the same starts. "all calls" counts every residual evaluation,
finite differences included (SciPy's own nfev convention differs between
'lm' and 'trf'); compare it with our "nfev + fd".
"""
import time

import numpy as np
from scipy.optimize import least_squares

MEYER_Y = np.array([34780.0, 28610.0, 23650.0, 19630.0, 16370.0, 13720.0, 11540.0, 9744.0,
                    8261.0, 7030.0, 6005.0, 5147.0, 4427.0, 3820.0, 3307.0, 2872.0])
MEYER_T = 45.0 + 5.0 * np.arange(1, 17)


def meyer(x):
    return x[0] * np.exp(x[1] / (MEYER_T + x[2])) - MEYER_Y


def exponential_problem(m):
    i = np.arange(m)
    t = 5.0 * i / (m - 1)
    y = 2.0 * np.exp(-1.3 * t) + 0.01 * (((7919 * i) % 1000) / 1000.0 - 0.5)
    return lambda p: p[0] * np.exp(-p[1] * t) - y


def run(name, fun, x0, method, repeats=5):
    calls = [0]

    def counted(x):
        calls[0] += 1
        return fun(x)

    start = time.perf_counter()
    for _ in range(repeats):
        calls[0] = 0
        result = least_squares(counted, x0, method=method, jac="2-point",
                               ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=20000)
    seconds = (time.perf_counter() - start) / repeats
    njev = result.njev if result.njev is not None else 0
    print(f"{name:<14} scipy-{method:<4} cost {result.cost:.10e}  nfev {result.nfev:>4}  "
          f"njev {njev:>4}  all calls {calls[0]:>4}  time {seconds:.3e} s  "
          f"status {result.status}  x = {[float(v) for v in result.x]}")


def main():
    for method in ("lm", "trf"):
        run("meyer", meyer, np.array([0.02, 4000.0, 250.0]), method)
        run("exp-1e5", exponential_problem(100_000), np.array([1.0, 1.0]), method)


if __name__ == "__main__":
    main()
