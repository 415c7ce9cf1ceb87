"""Link learning switches: each driven way its own link (``exp_link_directed``) and Eq. 9
not failing a link that predicted another representation of the place reached
(``exp_link_overlap_m``), against a brute-force bookkeeping written here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams


def make(**kw) -> ExperienceMap:
    # no relaxation: the map poses the overlap rule reads stay as learnt
    return ExperienceMap(ExperienceMapParams(exp_loops=0, exp_initial_em_deg=0.0, **kw))


class Bookkeeping:
    """Links with ``[traversals, successes, trials, behaviour]``, in creation order, and
    the transition rule spelt out one link at a time."""

    def __init__(self, threshold: float, directed: bool, overlap_m: float) -> None:
        self.links: dict[tuple[int, int], list[int]] = {}
        self.threshold, self.directed, self.overlap_m = threshold, directed, overlap_m

    def _pair(self, a: int, b: int) -> tuple[int, int] | None:
        if (a, b) in self.links:
            return (a, b)
        if not self.directed and (b, a) in self.links:
            return (b, a)
        return None

    def transition(self, a: int, b: int, behaviour: int, poses: np.ndarray) -> None:
        pair = self._pair(a, b)
        rows = []
        for (s, d), c in self.links.items():
            if s != a or c[3] != behaviour:
                continue
            if self.overlap_m > 0 and d != b:
                gap = math.hypot(poses[d, 0] - poses[b, 0], poses[d, 1] - poses[b, 1])
                turn = abs(math.remainder(poses[d, 2] - poses[b, 2], 2 * math.pi))
                if gap <= self.overlap_m and turn <= math.pi / 4:
                    continue  # another representation of the place reached
            rows.append((s, d))
        for s, d in rows:
            self.links[(s, d)][2] += 1
            if d == b:
                self.links[(s, d)][1] += 1
        if pair is not None:
            self.links[pair][0] += 1
        if self.threshold > 0:
            for s, d in rows:
                c = self.links[(s, d)]
                if c[1] / c[2] < self.threshold:
                    del self.links[(s, d)]

    def learn(self, a: int, b: int, behaviour: int) -> None:
        if self._pair(a, b) is None:
            self.links[(a, b)] = [1, 1, 1, behaviour]


def session(em: ExperienceMap, ref: Bookkeeping, seed: int, steps: int) -> None:
    rng = np.random.default_rng(seed)
    for step in range(steps):
        em.on_odometry(rng.uniform(0, 0.4), rng.uniform(-1.5, 1.5), 0.5)
        n, cur = len(em), em.current_id
        u, beh = rng.uniform(), int(rng.integers(2))
        dest = int(rng.integers(max(n, 1)))
        if n == 0 or u < 0.3:
            em.apply(Action(ActionKind.CREATE, dest_id=n), frame=step, behaviour=beh)
            if cur >= 0:
                ref.transition(cur, n, beh, em.poses)
                ref.learn(cur, n, beh)
        elif dest != cur and u < 0.7:
            poses = em.poses.copy()
            em.apply(Action(ActionKind.LINK, dest_id=dest), behaviour=beh)
            ref.transition(cur, dest, beh, poses)
            ref.learn(cur, dest, beh)
        elif dest != cur:
            poses = em.poses.copy()
            em.apply(Action(ActionKind.SET, dest_id=dest), behaviour=beh)
            ref.transition(cur, dest, beh, poses)


@pytest.mark.parametrize("directed", [False, True])
@pytest.mark.parametrize("overlap_m", [0.0, 0.6])
@pytest.mark.parametrize("seed", [3, 4])
def test_link_learning_matches_the_rule_link_by_link(directed, overlap_m, seed):
    em = make(
        exp_link_confidence_threshold=0.45,
        exp_link_directed=directed,
        exp_link_overlap_m=overlap_m,
    )
    ref = Bookkeeping(0.45, directed, overlap_m)
    session(em, ref, seed, 400)
    links = em.links()
    got = [
        (int(s), int(d), int(t), int(n), int(k), int(b))
        for s, d, t, n, k, b in zip(
            links["src"],
            links["dst"],
            links["traversals"],
            links["successes"],
            links["trials"],
            links["behaviour"],
        )
    ]
    assert got == [(s, d, *c) for (s, d), c in ref.links.items()]
    pairs = {(s, d) for s, d, *_ in got}
    both_ways = sum((d, s) in pairs for s, d in pairs)
    if directed:
        assert both_ways > 0  # the session drives pairs both ways: each way its own link
    else:
        assert both_ways == 0
    assert sorted(em.graph.edges) == sorted(pairs)


def test_a_way_driven_back_is_its_own_link_with_its_own_average():
    for directed in (False, True):
        em = make(exp_link_directed=directed, exp_link_averaging=True, exp_link_time="per_link")
        em.apply(Action(ActionKind.CREATE, dest_id=0))
        em.on_odometry(1.0, 0.0, 2.0)
        em.apply(Action(ActionKind.CREATE, dest_id=1))  # 0 -> 1: 2 m ahead
        em.on_odometry(0.0, math.pi, 1.0)
        em.on_odometry(1.0, 0.0, 2.5)  # back 2.5 m, facing the other way
        em.apply(Action(ActionKind.LINK, dest_id=0, relative_rad=math.pi))
        links = em.links()
        first = em.posegraph().measurements[0]
        if directed:  # 0 -> 1 keeps its own measurement
            np.testing.assert_allclose(first[:2], [2.0, 0.0], atol=1e-12)
            assert list(zip(links["src"], links["dst"])) == [(0, 1), (1, 0)]
            back = em.posegraph().measurements[1]
            assert math.hypot(back[0], back[1]) == pytest.approx(2.5)
            assert links["traversals"].tolist() == [1, 1]
        else:  # one link per pair: the way back is averaged into it (Eq. 6)
            np.testing.assert_allclose(first[:2], [2.25, 0.0], atol=1e-12)
            assert list(zip(links["src"], links["dst"])) == [(0, 1)]
            assert links["traversals"].tolist() == [2]


def test_overlap_keeps_a_link_that_predicted_the_place_reached():
    for overlap_m, kept in ((0.0, False), (0.5, True)):
        em = make(exp_link_confidence_threshold=0.5, exp_link_overlap_m=overlap_m)
        em.apply(Action(ActionKind.CREATE, dest_id=0))
        em.on_odometry(1.0, 0.0, 2.0)
        em.apply(Action(ActionKind.CREATE, dest_id=1), behaviour=1)  # 0 -> 1 at x 2
        em.on_odometry(0.05, 0.0, 1.0)
        em.apply(Action(ActionKind.CREATE, dest_id=2), behaviour=1)  # 2 learnt 5 cm on
        for _ in range(3):  # leaving 0 with behaviour 1 the robot recognises 2, not 1
            em.set_current(0)
            em.apply(Action(ActionKind.SET, dest_id=2), behaviour=1)
        assert em.graph.has_edge(0, 1) is kept
        if kept:
            assert em.graph.edges[0, 1]["trials"] == 1
