"""The local views and visual odometry behave as torch modules: ``.to`` / ``.double`` /
``.float`` convert everything they hold, and ``state_dict`` round-trips the whole state.

Each check runs a module over frames, converts (or saves and loads) it, steps on, and
compares with the unconverted original stepping over the same frames.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
import torch

from torchratslam.config import LocalViewParams, VisualOdometryParams
from torchratslam.errors import ConfigError
from torchratslam.local_view.view import FeatureView, LocalView
from torchratslam.messages import Frame
from torchratslam.readers.visual_odometry import VisualOdometry

PARAMS = LocalViewParams(
    template_x_size=24,
    template_y_size=6,
    vt_panoramic=True,
    vt_step_match=1,
    vt_match_threshold=0.06,
)


def _scenes(n_frames: int = 60, seed: int = 5) -> list[np.ndarray]:
    """Eight smooth panoramas seen again and again, rolled and with a little noise."""
    rng = np.random.default_rng(seed)
    base = [
        np.clip(np.cumsum(rng.normal(0, 12, (24, 96)), 1) * 0.2 + rng.uniform(60, 190), 0, 255)
        for _ in range(8)
    ]
    out = []
    for _ in range(n_frames):
        img = np.roll(base[rng.integers(8)], int(rng.integers(96)), axis=1)
        out.append(np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8))
    return out


def _run(view, frames, start: int):
    return [view.process(f, frame_index=start + i) for i, f in enumerate(frames)]


def _same(a, b, *, exact: bool):
    assert [(m.template_id, m.offset, m.is_new) for m in a] == [
        (m.template_id, m.offset, m.is_new) for m in b
    ]
    ea, eb = np.array([m.error for m in a]), np.array([m.error for m in b])
    if exact:
        np.testing.assert_array_equal(ea, eb)
    else:
        np.testing.assert_allclose(ea, eb, rtol=1e-5, atol=1e-6)


def _views():
    rng = np.random.default_rng(9)
    scans = [np.abs(rng.normal(3.0, 1.0, 72)) for _ in range(6)]
    feats = [np.roll(scans[rng.integers(6)], int(rng.integers(72))) for _ in range(60)]
    return [
        (lambda dtype=torch.float32: LocalView(PARAMS, dtype=dtype), _scenes()),
        (lambda dtype=torch.float32: FeatureView(PARAMS, dtype=dtype), feats),
    ]


@pytest.mark.parametrize("case", [0, 1], ids=["LocalView", "FeatureView"])
def test_converting_a_local_view_then_stepping_matches_the_original(case):
    make, frames = _views()[case]
    a, ref = make(), make()
    _run(a, frames[:30], 0)
    _run(ref, frames[:30], 0)
    assert len(a) > 3 and len(a) < 30  # both novel views and matches happened
    assert a.double() is a
    assert a.dtype == torch.float64 and a.templates.dtype == torch.float64
    assert a.bank.data.dtype == torch.float64 and torch.equal(a.templates, ref.templates.double())
    _same(_run(a, frames[30:45], 30), _run(ref, frames[30:45], 30), exact=False)
    a.float()
    assert a.templates.dtype == torch.float32
    _same(_run(a, frames[45:], 45), _run(ref, frames[45:], 45), exact=True)
    a.to(torch.device("cpu"), torch.float64)
    assert a.templates.dtype == torch.float64
    with pytest.raises(ConfigError, match="dtype"):
        a.half()


@pytest.mark.parametrize("case", [0, 1], ids=["LocalView", "FeatureView"])
def test_local_view_state_dict_round_trips_the_whole_state(case):
    make, frames = _views()[case]
    a = make()
    _run(a, frames[:30], 0)
    buf = io.BytesIO()
    torch.save(a.state_dict(), buf)
    buf.seek(0)
    b = make()
    b.load_state_dict(torch.load(buf, weights_only=True))
    assert torch.equal(a.templates, b.templates)
    assert torch.equal(a.bank.frames, b.bank.frames)
    assert (a.current_id, a.previous_id, a.frame_counter) == (
        b.current_id,
        b.previous_id,
        b.frame_counter,
    )
    # the next frames: the same decisions and errors, bit for bit
    _same([a.process(f) for f in frames[30:]], [b.process(f) for f in frames[30:]], exact=True)
    assert torch.equal(a.templates, b.templates)
    # a float64 module loads a float32 state (load_state_dict keeps the module's dtype)
    c = make(torch.float64)
    c.load_state_dict(a.state_dict())
    assert c.templates.dtype == torch.float64 and torch.equal(c.templates, a.templates.double())


def test_visual_odometry_state_dict_and_dtype_calls():
    p = VisualOdometryParams(camera_fov_deg=360.0, camera_hz=10.0)
    frames = [Frame(i, 0.1 * i, img, dt=0.1) for i, img in enumerate(_scenes(20, seed=2))]
    a = VisualOdometry(p)
    for f in frames[:10]:
        a(f)
    sd = a.state_dict()
    buf = io.BytesIO()
    torch.save(sd, buf)
    buf.seek(0)
    b = VisualOdometry(p)
    b.load_state_dict(torch.load(buf, weights_only=True))
    a.double()  # no floating tensors: nothing to convert, the numbers do not change
    b.float()
    assert [a(f) for f in frames[10:]] == [b(f) for f in frames[10:]]
    fresh = VisualOdometry(p)
    fresh.load_state_dict(VisualOdometry(p).state_dict())  # the empty state loads too
    assert fresh(frames[0]) == (0.0, 0.0, 0.0)
