"""Transition monitoring: Eq. 9 confidence, deletion below the threshold, relearning."""

import numpy as np
import pytest

from ratslam_graph.errors import InputError
from ratslam_graph.navigation.monitoring import LinkTable, record_transition


def _eq9(n_ij, n_i_beta):
    """c_ij = n_ij / (n_i beta_ij), written out."""
    return n_ij / n_i_beta


def test_confidence_follows_eq9_over_a_sequence():
    t = LinkTable.empty()
    t, r = record_transition(t, 0, 1, behaviour=0, dt=2.0, threshold=0.0)
    assert r.learnt and not r.relearnt and r.predicted == () and not r.as_predicted
    # a second behaviour's link from the same experience
    t, _ = record_transition(t, 0, 2, behaviour=1, dt=3.0, threshold=0.0)
    seq = [1, 1, 3, 1, 3, 3]  # arrivals leaving 0 with behaviour 0
    n01, n0b = 1, 1
    n03, n03b = 0, 0
    for k, dst in enumerate(seq):
        t, r = record_transition(t, 0, dst, behaviour=0, dt=1.0 + k, threshold=0.0)
        n0b += 1
        n01 += dst == 1
        if n03b or dst == 3:  # the link 0 -> 3 exists once first made
            n03b += 1
            n03 += dst == 3
        conf = dict(zip(zip(t.src.tolist(), t.dst.tolist()), t.confidence.tolist()))
        assert conf[(0, 1)] == pytest.approx(_eq9(n01, n0b))
        if n03b:
            assert conf[(0, 3)] == pytest.approx(_eq9(n03, n03b))
        assert conf[(0, 2)] == 1.0  # another behaviour: no trials
        assert r.as_predicted == (dst in r.predicted)
    assert r.predicted == (1, 3)


def test_links_below_the_threshold_are_deleted_and_relearnt():
    t = LinkTable.empty()
    t, _ = record_transition(t, 4, 5, behaviour=2, dt=1.0, threshold=0.4)  # 1/1
    t, _ = record_transition(t, 4, 5, behaviour=2, dt=1.0, threshold=0.4)  # 2/2
    # an obstacle: leaving 4 with behaviour 2 now ends at 9 (failures for 4 -> 5)
    t, r = record_transition(t, 4, 9, behaviour=2, dt=4.0, threshold=0.4)  # 2/3
    assert r.deleted == () and not r.as_predicted and r.learnt
    t, r = record_transition(t, 4, 9, behaviour=2, dt=4.0, threshold=0.4)  # 4->5: 2/4
    assert r.deleted == () and r.as_predicted
    t, r = record_transition(t, 4, 9, behaviour=2, dt=4.0, threshold=0.4)  # 2/5 = 0.4
    assert r.deleted == ()
    t, r = record_transition(t, 4, 9, behaviour=2, dt=4.0, threshold=0.4)  # 2/6 < 0.4
    assert r.deleted == ((4, 5),)
    assert (4, 5) not in set(zip(t.src.tolist(), t.dst.tolist()))
    assert t.deleted.tolist() == [[4, 5]]
    # the obstacle is gone: the path is traversed again and the link relearnt afresh
    t, r = record_transition(t, 4, 5, behaviour=2, dt=1.0, threshold=0.4)
    assert r.learnt and r.relearnt and r.predicted == (9,)
    k = np.nonzero((t.src == 4) & (t.dst == 5))[0][0]
    assert (t.successes[k], t.trials[k], t.confidence[k]) == (1, 1, 1.0)
    assert t.deleted.shape == (0, 2)
    j = np.nonzero((t.src == 4) & (t.dst == 9))[0][0]
    assert t.confidence[j] == pytest.approx(_eq9(4, 5))


def test_a_link_traversed_backwards_is_not_learnt_twice():
    t, _ = record_transition(LinkTable.empty(), 0, 1, behaviour=0, dt=1.0, threshold=0.5)
    t, r = record_transition(t, 1, 0, behaviour=3, dt=1.0, threshold=0.5)
    assert not r.learnt and len(t) == 1


def test_from_links_reads_the_maps_arrays():
    links = {
        "src": [0, 1], "dst": [1, 2], "behaviour": [0, 0], "dt": [1.0, 2.0],
        "successes": [3, 1], "trials": [4, 1],
    }  # fmt: skip
    t = LinkTable.from_links(links)
    assert t.confidence.tolist() == [0.75, 1.0]
    with pytest.raises(InputError):
        record_transition(t, 1, 1, behaviour=0, dt=1.0, threshold=0.5)
    with pytest.raises(InputError):
        record_transition(t, 0, 1, behaviour=0, dt=1.0, threshold=1.5)
