"""Visual odometry from image intensity profiles, as OpenRatSLAM estimates it.

For each image, two column-intensity profiles are taken: one from the ``vtrans_image_*``
crop (for speed) and one from the ``vrot_image_*`` crop (for rotation). Each profile
(one value per column: the mean grey level of the crop's rows, in [0, 1]) is compared
with the previous image's profile at every column shift of up to ``max_shift`` (40,
as in OpenRatSLAM) columns either way, by mean absolute difference over the
overlapping columns.

* rotation: the best shift of the rotation profile, in columns, converted with the
  camera's field of view and rate:
  ``vrot = shift * camera_fov_deg / image_width * camera_hz * pi / 180`` (rad/s);
  content moving towards higher columns (a left turn of a camera whose column 0 is on
  the left) is a positive, counter-clockwise rotation;
* speed: the smallest mean difference of the translation profile, scaled:
  ``vtrans = min(min_difference * vtrans_scaling, vtrans_max)`` (m/s).

The first image only primes the previous profiles and gives zero motion. The search
over shifts is vectorised (no Python loop over offsets or columns). Ties between shifts
go to the first of the reference's search order (left shifts 0..39, then right shifts
0..39).

Example:
    >>> import numpy as np
    >>> from torchratslam.config import VisualOdometryParams
    >>> from torchratslam.readers.visual_odometry import VisualOdometry
    >>> vo = VisualOdometry(VisualOdometryParams(camera_fov_deg=360.0, camera_hz=1.0))
    >>> img = (np.random.default_rng(0).random((8, 360)) * 255).astype(np.uint8)
    >>> vo.on_image(img)
    (0.0, 0.0)
    >>> round(vo.on_image(np.roll(img, 3, axis=1))[1], 4)  # 3 columns = 3 degrees
    0.0524
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import nn

from torchratslam.config import VisualOdometryParams
from torchratslam.errors import InputError, MapFormatError
from torchratslam.messages import Frame

__all__ = ["GivenOdometry", "VisualOdometry", "best_shift", "intensity_profile"]


def _grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    scale = 255.0 if np.issubdtype(img.dtype, np.integer) else 1.0
    img = img.astype(np.float64)
    if img.ndim == 3:
        img = img.mean(axis=2)
    if img.ndim != 2:
        raise InputError(f"expected an (H, W) or (H, W, 3) image, got shape {np.shape(image)}")
    return img / scale


def intensity_profile(
    image: np.ndarray, x_min: int, x_max: int, y_min: int, y_max: int
) -> np.ndarray:
    """Mean grey level of each column of the crop ``[y_min:y_max, x_min:x_max]``.

    Args:
        image: uint8 (0..255) or float (0..1) image. Shape: ``(H, W)`` or ``(H, W, 3)``.
        x_min, x_max, y_min, y_max: the crop; ``-1`` as a maximum means the image edge.

    Returns:
        ``(x_max - x_min,)`` float64 profile in [0, 1].

    Raises:
        InputError: the crop is empty or outside the image.
    """
    g = _grey(image)
    h, w = g.shape
    x1 = w if x_max < 0 else x_max
    y1 = h if y_max < 0 else y_max
    if not (0 <= x_min < x1 <= w and 0 <= y_min < y1 <= h):
        raise InputError(
            f"visual odometry crop x {x_min}..{x_max}, y {y_min}..{y_max} does not fit a "
            f"{w}x{h} image; fix the vtrans_image_*/vrot_image_* keys of the config"
        )
    return g[y_min:y1, x_min:x1].mean(axis=0)


def best_shift(profile: np.ndarray, previous: np.ndarray, max_shift: int = 40) -> tuple[int, float]:
    """Best column shift between two profiles and its mean absolute difference.

    A shift ``+s`` means ``profile[k + s] ~ previous[k]`` (content moved to higher
    columns); ``-s`` means ``profile[k] ~ previous[k + s]``. Each shift's difference is
    the mean over the ``W - s`` overlapping columns.

    Shape:
        profile, previous: ``(W,)``.

    Returns:
        ``(shift, mean_abs_difference)``.
    """
    w = profile.shape[0]
    n = max(1, min(max_shift, w))
    s = np.arange(n)
    k = np.arange(w)
    valid = k[None, :] < (w - s)[:, None]  # (n, W)
    shifted = np.minimum(k[None, :] + s[:, None], w - 1)
    # left: profile[k] vs previous[k + s]; right: profile[k + s] vs previous[k]
    left = np.where(valid, np.abs(profile[None, :] - previous[shifted]), 0.0).sum(1) / (w - s)
    right = np.where(valid, np.abs(profile[shifted] - previous[None, :]), 0.0).sum(1) / (w - s)
    diffs = np.concatenate([left, right])
    i = int(np.argmin(diffs))
    shift = -int(s[i]) if i < n else int(s[i - n])
    return shift, float(diffs[i])


class VisualOdometry(nn.Module):
    """OpenRatSLAM's intensity-profile visual odometry (an odometry source).

    A ``torch.nn.Module`` without parameters: the profiles are computed in numpy
    float64 whatever ``.to()`` / ``.double()`` / ``.float()`` ask (as for any module
    without floating tensors, they change nothing); ``state_dict()`` holds the previous
    image's profiles (the whole state) as CPU tensors under ``_extra_state`` and
    ``load_state_dict`` restores them, so the next frame gives the same odometry.

    Args:
        params: the ``vtrans_*``, ``vrot_*``, ``camera_fov_deg``, ``camera_hz``,
            ``vtrans_scaling`` and ``vtrans_max`` keys.
        max_shift: columns searched either way (OpenRatSLAM: 40).
        mirrored: the image's columns turn counter-clockwise from left to right (the
            built-in simulator's panoramas do; real cameras turn clockwise), so the
            rotation's sign is flipped.
    """

    def __init__(
        self,
        params: VisualOdometryParams | None = None,
        *,
        max_shift: int = 40,
        mirrored: bool = False,
    ) -> None:
        super().__init__()
        self.params = params if params is not None else VisualOdometryParams()
        self.max_shift = int(max_shift)
        self.mirrored = bool(mirrored)
        self.reset()

    def reset(self) -> None:
        """Forget the previous image (the next one gives zero motion) and the counts of
        :meth:`limits`."""
        self._prev_trans: np.ndarray | None = None
        self._prev_rot: np.ndarray | None = None
        self._counts = [0, 0, 0]  # frames compared, at vtrans_max, at the shift limit

    def limits(self) -> dict[str, float | int]:
        """How often the estimate sat on a limit since :meth:`reset`: ``frames`` (images
        compared with a previous one), ``vtrans_max`` (the fraction whose speed was
        clamped at ``vtrans_max``) and ``vrot_limit`` (the fraction whose best rotation
        shift was the largest searched, ``max_shift - 1`` columns either way: the turn
        may have been larger)."""
        n, at_v, at_r = self._counts
        return {
            "frames": n,
            "vtrans_max": at_v / n if n else 0.0,
            "vrot_limit": at_r / n if n else 0.0,
        }

    def on_image(self, image: np.ndarray | None) -> tuple[float, float]:
        """Speed and turn rate since the previous image.

        Args:
            image: the camera image. Shape: ``(H, W)`` or ``(H, W, 3)``.

        Returns:
            ``(vtrans m/s, vrot rad/s)``; ``(0.0, 0.0)`` for the first image.
        """
        p = self.params
        if image is None:
            raise InputError("visual odometry needs an image in every frame")
        width = np.shape(image)[1]
        trans = intensity_profile(
            image,
            p.vtrans_image_x_min,
            p.vtrans_image_x_max,
            p.vtrans_image_y_min,
            p.vtrans_image_y_max,
        )
        rot = intensity_profile(
            image, p.vrot_image_x_min, p.vrot_image_x_max, p.vrot_image_y_min, p.vrot_image_y_max
        )
        if (
            self._prev_trans is None
            or self._prev_rot is None
            or self._prev_trans.shape != trans.shape
        ):
            self._prev_trans, self._prev_rot = trans, rot
            return 0.0, 0.0
        _, trans_diff = best_shift(trans, self._prev_trans, self.max_shift)
        shift, _ = best_shift(rot, self._prev_rot, self.max_shift)
        self._prev_trans, self._prev_rot = trans, rot
        vrot = shift * p.camera_fov_deg / width * p.camera_hz * math.pi / 180.0
        if self.mirrored:
            vrot = -vrot
        vtrans = min(trans_diff * p.vtrans_scaling, p.vtrans_max)
        self._counts[0] += 1
        self._counts[1] += int(trans_diff * p.vtrans_scaling >= p.vtrans_max)
        self._counts[2] += int(abs(shift) >= min(self.max_shift, rot.shape[0]) - 1)
        return float(vtrans), float(vrot)

    def forward(self, frame: Frame) -> tuple[float, float, float]:
        """Odometry-source interface (``module(frame)``): ``(vtrans, vrot, dt)`` for one frame.

        ``dt`` is the frame's own interval when the reader knows it, else
        ``1 / camera_hz``; it is 0 for the first frame.
        """
        first = self._prev_trans is None
        vtrans, vrot = self.on_image(frame.image)
        if first:
            return 0.0, 0.0, 0.0
        dt = frame.dt if frame.dt > 0 else 1.0 / self.params.camera_hz
        return vtrans, vrot, float(dt)

    def get_state(self) -> dict:
        """The previous profiles (numpy arrays, or None before the first image)."""
        return {"prev_trans": self._prev_trans, "prev_rot": self._prev_rot}

    def set_state(self, state: dict) -> None:
        """Restore :meth:`get_state`'s output."""
        self._prev_trans = state.get("prev_trans")
        self._prev_rot = state.get("prev_rot")

    def get_extra_state(self) -> dict:
        """:meth:`get_state` with the profiles as CPU float64 tensors (for ``state_dict()``)."""
        return {k: None if v is None else torch.from_numpy(v) for k, v in self.get_state().items()}

    def set_extra_state(self, state: Any) -> None:
        """Restore :meth:`get_extra_state`'s output (``load_state_dict()``)."""
        if not isinstance(state, dict):
            raise MapFormatError(f"visual odometry state_dict entry is a {type(state).__name__}")
        self.set_state(
            {k: None if v is None else np.asarray(v.numpy(), np.float64) for k, v in state.items()}
        )


class GivenOdometry:
    """Odometry source that passes the reader's wheel odometry through.

    Args:
        params: unused (accepted so every odometry factory has one signature).
    """

    def __init__(self, params: VisualOdometryParams | None = None) -> None:
        self.params = params

    def reset(self) -> None:
        """Nothing to forget."""

    def __call__(self, frame: Frame) -> tuple[float, float, float]:
        """``(frame.vtrans, frame.vrot, frame.dt)``, checked to be finite, dt >= 0."""
        v, w, dt = float(frame.vtrans), float(frame.vrot), float(frame.dt)
        if not (math.isfinite(v) and math.isfinite(w) and math.isfinite(dt)) or dt < 0:
            raise InputError(
                f"frame {frame.index}: odometry (vtrans={v}, vrot={w}, dt={dt}) is not finite "
                "or dt is negative; fix the odometry file"
            )
        return v, w, dt

    def get_state(self) -> dict:
        return {}

    def set_state(self, state: dict) -> None:
        pass
