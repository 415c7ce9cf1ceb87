"""Eq. 9 through the pipeline: a link whose transition keeps failing is deleted, and
learnt again when the transition is made again (RatSLAM fed the executed behaviour)."""

from typing import Any

import numpy as np

from torchratslam.navigation.params import office_config
from torchratslam.navigation.robot import LinkEvents, count_link_events, pair_keys
from torchratslam.pipeline.ratslam import RatSLAM

FOLLOW, LEFT = 0, 1


def _places(n):
    """One distinct 12 x 8 view per place."""
    rng = np.random.default_rng(7)
    return [rng.integers(0, 256, (8, 12)).astype(np.uint8) for _ in range(n)]


class _Drive:
    """The pipeline standing still between views (no odometry), so every view is one
    experience and a return to a view is a transition to its experience."""

    def __init__(self):
        self.slam = RatSLAM(office_config(12, confidence_threshold=0.5))
        self.events = LinkEvents()
        self.keys = np.zeros(0, np.int64)
        self.views = _places(4)

    @property
    def em(self) -> Any:
        """The pipeline's experience map."""
        return self.slam.experience_map

    def visit(self, place, behaviour):
        r = self.slam.step(self.views[place], (0.0, 0.0, 1 / 7), behaviour=behaviour)
        store = self.em.store
        keys = pair_keys(store.src[: store.e], store.dst[: store.e])
        count_link_events(self.events, self.keys, keys)
        self.keys = keys
        return r.experience_id

    def linked(self, a, b):
        links = self.em.links()
        s, d = links["src"], links["dst"]
        return bool((((s == a) & (d == b)) | ((s == b) & (d == a))).any())


def test_a_blocked_link_is_deleted_and_relearnt_through_the_pipeline():
    drive = _Drive()
    a = drive.visit(0, FOLLOW)
    b = drive.visit(1, FOLLOW)
    assert drive.linked(a, b)
    for _ in range(2):  # a -> b works twice more with FOLLOW
        assert drive.visit(0, LEFT) == a
        assert drive.visit(1, FOLLOW) == b
    links = drive.em.links()
    k = int(np.flatnonzero((links["src"] == a) & (links["dst"] == b))[0])
    assert links["behaviour"][k] == FOLLOW
    # now FOLLOW from a ends up at c (the way to b is blocked): Eq. 9 counts failures
    fails = 0
    while drive.linked(a, b):
        drive.visit(0, LEFT)
        c = drive.visit(2, FOLLOW)
        fails += 1
        assert fails < 10
    # three successes in 3 + f trials: deleted once 3 / (3 + f) < 0.5, i.e. f = 4
    assert fails == 4
    assert drive.events.deleted >= 1 and not drive.linked(a, b)
    assert drive.linked(a, c)
    # the way is open again: a -> b is learnt anew
    drive.visit(0, LEFT)
    assert drive.visit(1, FOLLOW) == b
    assert drive.linked(a, b)
    assert drive.events.relearnt >= 1
