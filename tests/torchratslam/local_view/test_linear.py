"""``LinearScanView``: OpenRatSLAM's ``LocalViewMatch::compare`` (a linear scan with the
mean rule and row-wise early exits) against the loop written out in the test."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchratslam.config import LocalViewParams
from torchratslam.local_view.linear import LinearScanView
from torchratslam.local_view.view import LocalView
from torchratslam.pipeline.defaults import DEFAULTS
from torchratslam.registry import LOCAL_VIEWS


def compare(templates, view, *, panoramic, shift, step, threshold):
    """OpenRatSLAM's compare(), pair by pair: templates in id order, the mean rule
    (``threshold + 0.005``), every offset; a strictly smaller error wins."""
    x = view.shape[1]
    best = (np.inf, -1, 0)
    for t, tmpl in enumerate(templates):
        if abs(view.mean() - tmpl.mean()) > threshold + 0.005:
            continue
        if panoramic:
            for o in range(0, x, step):
                err = np.abs(np.roll(tmpl, -o, axis=1) - view).mean()
                best = min(best, (err, t, o), key=lambda b: b[0])
        else:
            w = x - 2 * shift
            for o in range(0, 2 * shift + 1, step):
                err = np.abs(tmpl[:, o : o + w] - view[:, shift : shift + w]).mean()
                best = min(best, (err, t, o), key=lambda b: b[0])
    return best


@pytest.mark.parametrize("panoramic", [False, True])
def test_linear_scan_is_openratslams_compare(panoramic):
    rng = np.random.default_rng(3)
    params = LocalViewParams(
        template_x_size=20,
        template_y_size=5,
        vt_shift_match=3,
        vt_step_match=1 if panoramic else 2,
        vt_match_threshold=0.1,
        vt_panoramic=panoramic,
    )
    base = rng.uniform(0.3, 0.7, (5, 20))
    views = [base + rng.normal(0, 0.05, base.shape) for _ in range(6)]
    views += [rng.uniform(0, 1, (5, 20)) * rng.uniform(0.2, 1.5) for _ in range(30)]
    lv = LinearScanView(params, dtype=torch.float64)
    for v in views:
        lv.add_templates(torch.as_tensor(v)[None])
    templates = lv.templates.numpy()
    probes = [base, np.roll(base, 2, axis=1), views[9] + 0.01, base + 0.3, views[20]]
    for probe in probes:
        err, tid, off = compare(
            templates,
            probe,
            panoramic=panoramic,
            shift=3,
            step=params.vt_step_match,
            threshold=0.1,
        )
        got = lv.match(torch.as_tensor(probe))
        assert got[:2] == (tid, off)
        if tid >= 0:
            assert got[2] == pytest.approx(err, rel=1e-12)
    # a probe far from every template's mean skips them all, as OpenRatSLAM does
    assert lv.match(torch.as_tensor(np.full((5, 20), 5.0)))[0] == -1


def test_linear_scan_decides_as_the_exact_search_in_panoramic_mode():
    rng = np.random.default_rng(4)
    params = LocalViewParams(
        template_x_size=16,
        template_y_size=4,
        vt_shift_match=2,
        vt_match_threshold=0.06,
        vt_panoramic=True,
    )
    places = [rng.integers(0, 255, (4, 16)).astype(np.uint8) for _ in range(12)]
    seq = [np.roll(places[i % 12], int(rng.integers(0, 16)), axis=1) for i in range(60)]
    lin, exact = LinearScanView(params), LocalView(params)
    for img in seq:
        a, b = lin.process(img), exact.process(img)
        assert (a.template_id, a.is_new, a.offset) == (b.template_id, b.is_new, b.offset)
    assert len(lin) == len(exact) < 50  # places seen again were matched


def test_registered_as_linear():
    assert any(name == "linear" for _, name, _ in DEFAULTS)
    lv = LOCAL_VIEWS.build(
        "linear", LocalViewParams(template_x_size=16, template_y_size=4, vt_shift_match=2)
    )
    assert isinstance(lv, LinearScanView) and lv.kind == "linear"
