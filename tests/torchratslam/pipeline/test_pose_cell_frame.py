"""The pipeline's pose-cell stage in one compiled call (``PoseCells.on_frame``) against
the two calls it stands for (a subclass of ``PoseCells`` takes them), frame by frame."""

import numpy as np
import pytest

from torchratslam.config import load_config
from torchratslam.pipeline import RatSLAM
from torchratslam.pose_cells.stage import PoseCells


class TwoCalls(PoseCells):
    """``PoseCells`` that the pipeline drives by ``on_view_template`` + ``on_odometry``."""

    def on_frame(self, *args, **kwargs):  # pragma: no cover - the pipeline must not call it
        raise AssertionError("the pipeline took the compiled frame for a subclass")


@pytest.mark.parametrize("action_angle", ["injection", "view"])
def test_the_pipeline_with_on_frame_is_the_pipeline_with_the_two_calls(
    loop_frames, loop_params, action_angle
):
    frames = loop_frames[:240]
    runs = []
    for pose_cells in (None, TwoCalls):
        cfg = load_config(None, **loop_params, action_angle=action_angle)
        slam = RatSLAM(cfg, pose_cells=pose_cells)
        results = [slam.step_frame(f) for f in frames]
        runs.append((slam, results))
    (fused, got), (apart, want) = runs
    assert type(apart.pose_cells) is TwoCalls and type(fused.pose_cells) is PoseCells
    assert [(r.action, r.pc, r.experience_id) for r in got] == [
        (r.action, r.pc, r.experience_id) for r in want
    ]
    assert {r.action.kind for r in got} >= {1, 2}  # creations and links
    assert fused.counts() == apart.counts()
    assert np.array_equal(fused.trajectory(), apart.trajectory(), equal_nan=True)
    assert np.array_equal(fused.pc_log(), apart.pc_log())
