"""RatSLAM.step(..., behaviour=...) labels transitions for Eq. 9; the default is unchanged."""

import numpy as np

from torchratslam.navigation.params import office_config
from torchratslam.pipeline.ratslam import RatSLAM


def _run(behaviour, **keys):
    rng = np.random.default_rng(0)
    r = RatSLAM(office_config(12, **keys))
    for k in range(60):
        img = (
            rng.integers(0, 255, (8, 12)).astype(np.uint8)
            if k % 20 < 10
            else np.full((8, 12), 100 + k % 10, np.uint8)
        )
        r.step(img, (0.3, 0.05, 1 / 7), behaviour=behaviour)
    return r


def test_behaviour_labels_links_and_changes_nothing_else():
    plain = _run(None, exp_link_confidence_threshold=0.0)
    labelled = _run(2, exp_link_confidence_threshold=0.0)
    assert set(plain.experience_map.links()["behaviour"].tolist()) == {0}
    assert set(labelled.experience_map.links()["behaviour"].tolist()) == {2}
    np.testing.assert_array_equal(plain.trajectory(), labelled.trajectory())


def test_activity_rule_creates_experiences_from_experience_activity():
    r = _run(None, exp_create_rule="activity")
    em = r.experience_map
    assert len(em) >= 2
    pc = em.store.pc[: len(em)]
    assert np.all(np.isfinite(pc))
