"""MBARAM: milliseconds per frame against the number of nodes.

Three channels as in the paper (two 682-beam lasers and a 3-D odometry pose), diagonal
covariances, float64, one thread. ``localise`` is the competition and vigilance over
all nodes (Eqs. 1-8); ``learn`` adds the update of the winner (Eqs. 9-12) and the edge.
Inputs lie near existing nodes, so learning updates a node rather than adding one.
``BENCH_QUICK=1`` uses fewer repetitions.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np
import torch

from torchratslam.mbaram.model import MBARAM
from torchratslam.mbaram.params import MBARAMParams

BEAMS = 682


def _model(n: int, rng: np.random.Generator) -> MBARAM:
    """A map of ``n`` nodes (random means, small variances) built through set_state."""
    m = MBARAM(MBARAMParams())
    state = {
        "version": 1,
        "channels": list(m.names),
        "weights": [m.weights[k] for k in m.names],
        "counts": np.full(n, 5.0),
        "prior": np.full(n, 1.0 / n),
        "prev_winner": -1,
        "edges": np.zeros((0, 2), np.int64),
        "edge_counts": np.zeros(0, np.int64),
        "mean/laser_front": rng.uniform(0.5, 10.0, (n, BEAMS)),
        "cov/laser_front": np.full((n, BEAMS), 0.01),
        "mean/laser_rear": rng.uniform(0.5, 10.0, (n, BEAMS)),
        "cov/laser_rear": np.full((n, BEAMS), 0.01),
        "mean/odometry": rng.uniform(0.0, 40.0, (n, 3)),
        "cov/odometry": np.full((n, 3), 0.01),
    }
    m.set_state(state)
    return m


def _time(fn: Any, inputs: list) -> float:
    fn(inputs[0])
    t0 = time.perf_counter()
    for x in inputs:
        fn(x)
    return 1e3 * (time.perf_counter() - t0) / len(inputs)


def main() -> None:
    torch.set_num_threads(1)
    reps = 20 if os.environ.get("BENCH_QUICK") else 100
    rng = np.random.default_rng(0)
    print("| nodes | localise ms/frame | learn ms/frame |")
    print("|---:|---:|---:|")
    for n in (10, 50, 100, 200, 500, 1000):
        m = _model(n, rng)
        # inputs near a random node, so that learning updates it (the common case)
        js = rng.integers(0, n, reps)
        inputs = [
            {k: m.means(k)[j].numpy() + rng.normal(0.0, 0.01, m.dims[k]) for k in m.names}
            for j in js
        ]
        loc = _time(m.localise, inputs)
        learn = _time(m.learn, inputs)
        print(f"| {n} | {loc:.2f} | {learn:.2f} |", flush=True)


if __name__ == "__main__":
    main()
