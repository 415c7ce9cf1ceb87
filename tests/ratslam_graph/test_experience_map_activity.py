"""Experience creation by experience activity (Eqs. 1-4): ExperienceMap.activity_action."""

import math

import numpy as np

from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.messages import ActionKind
from ratslam_graph.params import ExperienceMapParams


def _brute(pcs, vts, cur, vt, ra, ta, dims):
    out = []
    for (x, y, th), v in zip(pcs, vts):
        dx = min(abs(cur[0] - x), dims[0] - abs(cur[0] - x))
        dy = min(abs(cur[1] - y), dims[0] - abs(cur[1] - y))
        dt = min(abs(cur[2] - th), dims[1] - abs(cur[2] - th))
        r = math.sqrt(dx * dx + dy * dy) / ra
        t = dt / ta
        e = 0.0 if (r > 1 or t > 1) else 2 - r - t
        out.append(e if v == vt else 0.0)
    return out


def test_activity_action_follows_eqs_1_to_4_and_the_threshold():
    rng = np.random.default_rng(3)
    p = ExperienceMapParams(exp_create_rule="activity", exp_activity_threshold=0.7)
    em = ExperienceMap(p)
    dims = (20.0, 36.0)
    pcs = rng.uniform(0, 20, (40, 3)) * np.array([1, 1, 1.8])
    vts = rng.integers(0, 3, 40)
    for k in range(40):
        em.create_experience(pc=pcs[k], template_id=int(vts[k]))
    for _ in range(200):
        cur = rng.uniform(0, 20, 3) * np.array([1, 1, 1.8])
        vt = int(rng.integers(0, 3))
        want = _brute(pcs, vts, cur, vt, p.exp_activity_zone_xy, p.exp_activity_zone_th, dims)
        a = em.activity_action(cur, vt, dims=dims)
        best = int(np.argmax(want))
        if want[best] < 0.7:
            assert a.kind == ActionKind.CREATE and a.dest_id == len(em)
        elif want[em.current_id] >= want[best]:
            assert a.kind == ActionKind.NONE
        else:
            assert a.kind == ActionKind.LINK and a.dest_id == best


def test_default_rule_is_the_pose_cells_distance_rule():
    assert ExperienceMapParams().exp_create_rule == "pc_distance"
