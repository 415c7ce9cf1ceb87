"""``RecodedView`` (xRatSLAM's RecodedLV): the newest template under the threshold,
against a backward scan written out in the test."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.config import LocalViewParams
from torchratslam.local_view.recoded import RecodedView
from torchratslam.local_view.view import LocalView
from torchratslam.pipeline.defaults import DEFAULTS
from torchratslam.registry import LOCAL_VIEWS


def backward_scan(templates, view, shift, step, threshold):
    """The newest template whose best windowed mean error is at most the threshold,
    by a loop from the newest template down (normal mode, OpenRatSLAM's offsets)."""
    _, x = view.shape
    w = x - 2 * shift
    block = view[:, shift : shift + w]
    for t in range(len(templates) - 1, -1, -1):
        errs = [
            np.abs(templates[t][:, o : o + w] - block).mean() for o in range(0, 2 * shift + 1, step)
        ]
        if min(errs) <= threshold:
            return t, int(np.argmin(errs)) * step, min(errs)
    return -1, 0, None


def test_recoded_view_takes_the_newest_match_as_a_backward_scan():
    rng = np.random.default_rng(0)
    params = LocalViewParams(
        template_x_size=24,
        template_y_size=6,
        vt_shift_match=3,
        vt_step_match=1,
        vt_match_threshold=0.08,
        vt_panoramic=False,
    )
    base = rng.uniform(0, 1, (6, 24))
    views = [base + rng.normal(0, 0.03, base.shape) for _ in range(5)]  # near copies
    views += [rng.uniform(0, 1, (6, 24)) for _ in range(40)]
    views += [np.roll(base, 1, axis=1) + rng.normal(0, 0.07, base.shape)]  # newest, worse
    rec = RecodedView(params, dtype=torch.float64)
    exact = LocalView(params, dtype=torch.float64)
    for v in views:
        rec.add_templates(torch.as_tensor(v)[None])
        exact.add_templates(torch.as_tensor(v)[None])
    templates = rec.templates.numpy()
    hits = 0
    for probe in [base, np.roll(base, -2, axis=1), rng.uniform(0, 1, (6, 24)), views[10]]:
        want = backward_scan(templates, probe, 3, 1, 0.08)
        got = rec.match(torch.as_tensor(probe))
        assert got[:2] == want[:2]
        if want[0] >= 0:
            hits += 1
            assert got[2] == pytest.approx(want[2], rel=1e-9)
        else:
            assert got[2] > 0.08  # a lower bound above the threshold
    assert hits == 3
    # the exact search takes the best template instead: not always the newest match
    best = exact.match(torch.as_tensor(base))
    assert best[0] != rec.match(torch.as_tensor(base))[0]


def test_registered_as_recoded_and_learns_like_a_local_view():
    assert any(name == "recoded" for _, name, _ in DEFAULTS)
    params = LocalViewParams(
        template_x_size=16,
        template_y_size=4,
        vt_shift_match=2,
        vt_step_match=1,
        vt_match_threshold=0.05,
    )
    lv = LOCAL_VIEWS.build("recoded", params)
    assert isinstance(lv, RecodedView) and lv.kind == "recoded"
    img = np.tile(np.arange(16, dtype=np.uint8) * 15, (4, 1))
    first, again = lv.process(img), lv.process(img)
    assert first.is_new and not again.is_new and again.template_id == first.template_id
