"""Visual odometry: the vectorised search equals a brute-force loop; known shifts give
known rotations; speed is the scaled, capped profile difference."""

import math

import numpy as np
import pytest

from torchratslam.config import VisualOdometryParams
from torchratslam.errors import InputError
from torchratslam.messages import Frame
from torchratslam.readers.visual_odometry import (
    GivenOdometry,
    VisualOdometry,
    best_shift,
    intensity_profile,
)


def _brute_force(data, old, slen=40):
    """The reference search written out: left shifts 0..slen-1, then right shifts."""
    w = len(data)
    mindiff, minoffset = 1e6, 0
    for offset in range(min(slen, w)):
        c = sum(abs(data[k] - old[k + offset]) for k in range(w - offset)) / (w - offset)
        if c < mindiff:
            mindiff, minoffset = c, -offset
    for offset in range(min(slen, w)):
        c = sum(abs(data[k + offset] - old[k]) for k in range(w - offset)) / (w - offset)
        if c < mindiff:
            mindiff, minoffset = c, offset
    return minoffset, mindiff


@pytest.mark.parametrize("seed", range(6))
def test_best_shift_equals_the_brute_force_search(seed):
    rng = np.random.default_rng(seed)
    w = int(rng.integers(20, 90))
    old = rng.random(w)
    new = np.roll(old, int(rng.integers(-10, 10))) + rng.normal(scale=0.05, size=w)
    shift, diff = best_shift(new, old)
    ref_shift, ref_diff = _brute_force(new, old)
    assert shift == ref_shift
    assert diff == pytest.approx(ref_diff, rel=1e-12)


def test_intensity_profile_is_column_mean_of_the_crop():
    img = np.arange(5 * 7, dtype=np.uint8).reshape(5, 7) * 3
    p = intensity_profile(img, 1, 5, 2, -1)
    assert np.allclose(p, img[2:, 1:5].mean(0) / 255.0)
    colour = np.repeat(img[:, :, None], 3, axis=2)
    assert np.allclose(intensity_profile(colour, 0, -1, 0, -1), img.mean(0) / 255.0)
    with pytest.raises(InputError, match="does not fit"):
        intensity_profile(img, 0, 20, 0, -1)


@pytest.mark.parametrize("shift", [-7, -1, 0, 3, 12])
def test_a_known_panoramic_rotation_gives_the_known_turn_rate(shift):
    # 360 columns over 360 degrees at 2 Hz: each column is one degree per half second
    p = VisualOdometryParams(camera_fov_deg=360.0, camera_hz=2.0, vtrans_scaling=10.0)
    vo = VisualOdometry(p)
    rng = np.random.default_rng(0)
    base = rng.random(360)
    img = (np.tile(base, (16, 1)) * 255).astype(np.uint8)
    assert vo.on_image(img) == (0.0, 0.0)
    vtrans, vrot = vo.on_image(np.roll(img, shift, axis=1))
    assert vrot == pytest.approx(shift * math.radians(1.0) * 2.0)
    # a pure rotation leaves (almost) nothing for the speed: only the wrapped columns differ
    assert vtrans < 10.0 * np.abs(np.diff(base)).mean()


def test_speed_is_scaled_min_difference_and_capped():
    p = VisualOdometryParams(vtrans_scaling=100.0, vtrans_max=5.0)
    vo = VisualOdometry(p)
    img = np.full((10, 60), 100, dtype=np.uint8)
    vo.on_image(img)
    v, w = vo.on_image(img + 2)  # uniform brightening: difference 2/255 at every shift
    assert w == 0.0 and v == pytest.approx(2 / 255 * 100.0)
    v, _ = vo.on_image(img + 40)  # 38/255*100 = 14.9 > cap
    assert v == 5.0


def test_limits_count_the_frames_clamped_at_vtrans_max_and_at_the_shift_limit():
    p = VisualOdometryParams(vtrans_scaling=100.0, vtrans_max=5.0, camera_fov_deg=360.0)
    vo = VisualOdometry(p, max_shift=10)
    rng = np.random.default_rng(1)
    img = (np.tile(rng.random(60), (8, 1)) * 200).astype(np.uint8)
    assert vo.limits() == {"frames": 0, "vtrans_max": 0.0, "vrot_limit": 0.0}
    vo.on_image(img)  # primes only
    vo.on_image(img + 2)  # 0.78 m/s: free
    vo.on_image(img + 42)  # 16 m/s: clamped
    vo.on_image(np.roll(img + 42, 3, axis=1))  # a 3-column turn: inside the search
    vo.on_image(np.roll(img + 42, 3 + 9, axis=1))  # 9 columns: the largest searched
    lim = vo.limits()
    assert lim["frames"] == 4 and lim["vtrans_max"] == 0.25 and lim["vrot_limit"] == 0.25
    vo.reset()
    assert vo.limits()["frames"] == 0


def test_odometry_sources_return_vtrans_vrot_dt():
    p = VisualOdometryParams(camera_hz=4.0)
    vo = VisualOdometry(p)
    img = np.zeros((4, 50), dtype=np.uint8)
    assert vo(Frame(0, 0.0, img)) == (0.0, 0.0, 0.0)
    assert vo(Frame(1, 0.25, img))[2] == pytest.approx(0.25)  # no reader dt: 1/camera_hz
    assert vo(Frame(2, 0.75, img, dt=0.5))[2] == pytest.approx(0.5)
    given = GivenOdometry()
    assert given(Frame(3, 1.0, None, vtrans=0.5, vrot=-0.1, dt=0.2)) == (0.5, -0.1, 0.2)
    with pytest.raises(InputError, match="not finite"):
        given(Frame(4, 1.0, None, vtrans=float("nan"), dt=0.1))
    with pytest.raises(InputError, match="needs an image"):
        vo(Frame(5, 1.0, None))


def test_rotation_sign_on_the_simulators_mirrored_panoramas():
    # the simulator's panoramas turn counter-clockwise with the column index (the
    # mirror of a real camera): with mirrored=True the estimate follows the true turn
    from torchratslam.sim import get_tour

    session = get_tour("loop", laps=1, frames=300).full()
    p = VisualOdometryParams(camera_fov_deg=360.0, camera_hz=5.0)
    vo = VisualOdometry(p, mirrored=True)
    est, true = [], []
    for f in session.frames(0, 60):
        est.append(vo.on_image(f.image)[1])
        true.append(f.vrot)
    est, true = np.array(est[1:]), np.array(true[1:])
    turning = np.abs(true) > 0.3
    assert turning.sum() > 5
    assert np.mean(np.sign(est[turning]) == np.sign(true[turning])) > 0.9
