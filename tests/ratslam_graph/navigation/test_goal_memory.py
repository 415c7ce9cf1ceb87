"""Goal memory (the experience-map paper's baseline) against brute-force references."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ratslam_graph.errors import InputError
from ratslam_graph.navigation.goal_memory import GoalMemory, collisions


def brute_fastest(links: dict[tuple[int, int], float], n: int, start: int) -> np.ndarray:
    """Bellman-Ford by repeated relaxation over every link (no heap)."""
    t = np.full(n, np.inf)
    t[start] = 0.0
    for _ in range(n):
        for (a, b), w in links.items():
            t[b] = min(t[b], t[a] + w)
    return t


def test_links_are_learnt_between_neighbouring_cells_with_the_mean_stay():
    rng = np.random.default_rng(0)
    nx, ny = 7, 5
    gm = GoalMemory((nx, ny))
    # a random walk of the packet, with wraps in both axes and a few jumps
    pos = np.array([3.2, 2.6])
    stays: dict[tuple[int, int], list[float]] = {}
    prev_cell, entered, jumps = None, 0.0, 0
    for k in range(3000):
        if k % 500 == 499:
            pos = pos + np.array([3.0, 2.0])  # a jump: not a neighbour
        else:
            pos = pos + rng.normal(0, 0.3, 2)
        t = 0.1 * k
        gm.observe(pos, t)
        cell = (int(np.floor(pos[0])) % nx, int(np.floor(pos[1])) % ny)
        if cell != prev_cell:
            if prev_cell is not None:
                dx = (cell[0] - prev_cell[0] + nx // 2) % nx - nx // 2
                dy = (cell[1] - prev_cell[1] + ny // 2) % ny - ny // 2
                if abs(dx) <= 1 and abs(dy) <= 1:
                    a = prev_cell[0] + nx * prev_cell[1]
                    b = cell[0] + nx * cell[1]
                    stays.setdefault((a, b), []).append(t - entered)
                else:
                    jumps += 1
            prev_cell, entered = cell, t
    assert gm.jumps == jumps > 0
    assert gm.num_links == len(stays)
    learnt = dict(zip(zip(gm._src, gm._dst, strict=True), gm._time, strict=True))
    for key, values in stays.items():
        assert learnt[key] == pytest.approx(np.mean(values))
    links = {k: max(v, 1e-6) for k, v in learnt.items()}
    for start in (0, 12, 34):
        np.testing.assert_allclose(
            gm.temporal_map(start).times, brute_fastest(links, nx * ny, start), rtol=1e-12
        )
        # every route is a chain of learnt links, as fast as the brute-force time
        for goal in range(nx * ny):
            route = gm.route(start, goal)
            want = brute_fastest(links, nx * ny, start)[goal]
            if route is None:
                assert not np.isfinite(want)
                continue
            assert route[0] == start and route[-1] == goal
            assert sum(links[(a, b)] for a, b in itertools.pairwise(route)) == pytest.approx(want)


def test_positions_unwrap_a_route_across_the_wrap():
    gm = GoalMemory((5, 4))
    cells = [4 + 5 * 3, 0 + 5 * 3, 0 + 5 * 0, 1 + 5 * 0]  # (4,3) -> (0,3) -> (0,0) -> (1,0)
    xy = gm.positions(cells, (4.5, 3.5))
    assert xy.tolist() == [[4.5, 3.5], [5.5, 3.5], [5.5, 4.5], [6.5, 4.5]]
    with pytest.raises(InputError):
        GoalMemory((0, 3))


def test_collisions_count_cells_whose_places_spread():
    pc = np.array([[0.5, 0.5], [0.6, 0.4], [1.5, 0.5], [1.2, 0.9], [0.2, 0.3]])
    truth = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [9.0, 5.0], [6.0, 0.0]])
    # cell (0, 0): places 0, 0.1 and 6 m apart -> a collision; cell (1, 0): 4 m -> one too
    assert collisions(pc, truth, 2.0) == (2, 2)
    assert collisions(pc, truth, 5.0) == (1, 2)
    assert collisions(pc, truth, 10.0) == (0, 2)
