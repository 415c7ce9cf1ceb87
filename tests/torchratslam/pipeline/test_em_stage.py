"""The pipeline's experience-map stage against the map's own calls, one by one."""

from __future__ import annotations

import numpy as np
import pytest

from ratslam_graph.errors import GraphError
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams
from torchratslam.pipeline.em_stage import experience_map_step


def frames(seed: int, steps: int):
    """Random frames: odometry (None on some), an action (none on about half), the
    pose-cell centre and a behaviour label (None on some)."""
    rng = np.random.default_rng(seed)
    n = 0
    for step in range(steps):
        odo = None if rng.uniform() < 0.05 else tuple(rng.uniform([0, -0.8, 0.02], [2, 0.8, 0.3]))
        u = rng.uniform()
        rel = float(rng.uniform(-0.4, 0.4))
        if n == 0 or u < 0.2:
            act, n = Action(ActionKind.CREATE, dest_id=n), n + 1
        elif u < 0.4:
            act = Action(ActionKind.LINK, dest_id=int(rng.integers(n)), relative_rad=rel)
        elif u < 0.5:
            act = Action(ActionKind.SET, dest_id=int(rng.integers(n)), relative_rad=rel)
        else:
            act = Action.none()
        pc = tuple(float(v) for v in rng.uniform(0, 30, 3))
        beh = None if rng.uniform() < 0.3 else int(rng.integers(3))
        yield step, odo, act, pc, beh


def one_by_one(em: ExperienceMap, step, odo, act, pc, beh) -> int:
    """What the stage means: odometry, the action, and a relaxation when the settings
    relax every frame or the frame has an action."""
    if odo is not None:
        em.on_odometry(*odo)
    em.apply(act, frame=step, t=0.1 * step, pc=pc, template_id=step % 7, behaviour=beh or 0)
    if em.params.exp_relax == "every_frame" or act.kind != ActionKind.NONE:
        em.iterate()
    return em.current_id


def stage(em: ExperienceMap, step, odo, act, pc, beh) -> int:
    return experience_map_step(
        em,
        odo,
        act,
        frame=step,
        t=0.1 * step,
        pc=pc,
        template_id=step % 7,
        pc_dims=(30.0, 30.0, 36.0),
        behaviour=beh,
    )


def same_map(a: ExperienceMap, b: ExperienceMap) -> bool:
    sa, sb = a.get_state(), b.get_state()
    return sa.keys() == sb.keys() and all(
        np.asarray(v).tobytes() == np.asarray(sb[k]).tobytes() for k, v in sa.items()
    )


@pytest.mark.parametrize("relax", ["on_action", "every_frame"])
@pytest.mark.parametrize("seed", [1, 2])
def test_the_stage_is_the_maps_calls_one_by_one(relax, seed):
    params = ExperienceMapParams(exp_relax=relax)
    fast, slow = ExperienceMap(params), ExperienceMap(params)
    for f in frames(seed, 200):
        assert stage(fast, *f) == one_by_one(slow, *f)
    assert len(fast) > 30 and fast.num_links > 30
    assert same_map(fast, slow)


class Recording(ExperienceMap):
    """A map that sees every action, NONE included (its own ``apply``)."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[int] = []

    def apply(self, action: Action, **kw) -> None:
        self.seen.append(int(action.kind))
        super().apply(action, **kw)


def test_a_map_with_its_own_apply_gets_every_frame():
    em, ref = Recording(), ExperienceMap()
    steps = list(frames(3, 80))
    for f in steps:
        stage(em, *f)
        one_by_one(ref, *f)
    assert em.seen == [int(f[2].kind) for f in steps]  # the frames without an action too
    assert ActionKind.NONE in em.seen
    assert same_map(em, ref)


def test_an_action_the_compiled_frame_refuses_goes_the_python_way():
    fast, slow = ExperienceMap(), ExperienceMap()
    steps = list(frames(4, 30))
    for f in steps:
        assert stage(fast, *f) == one_by_one(slow, *f)
    bad = (30, (0.5, 0.1, 0.1), Action(ActionKind.LINK, dest_id=len(fast) + 3), (1.0, 2.0, 3.0), 1)
    errors = []
    for em, run in ((fast, stage), (slow, one_by_one)):
        with pytest.raises(GraphError) as info:
            run(em, *bad)
        errors.append((type(info.value), str(info.value)))
    assert errors[0] == errors[1]
    assert same_map(fast, slow)


def test_the_stage_follows_new_settings_of_the_map():
    first = ExperienceMapParams(exp_relax="on_action")
    later = (
        ExperienceMapParams(exp_relax="every_frame", exp_loops=3),
        ExperienceMapParams(exp_relax="on_action", exp_link_averaging=True),  # not compiled
        first,
    )
    fast, slow = ExperienceMap(first), ExperienceMap(first)
    for f in frames(5, 160):
        if f[0] in (39, 79, 119):
            for em in (fast, slow):
                em.params = later[f[0] // 40]
        assert stage(fast, *f) == one_by_one(slow, *f)
    assert same_map(fast, slow)
