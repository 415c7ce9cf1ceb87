"""Does a ground truth describe a map? Checks before an ATE is computed.

Ground truth is matched to a map by time: the pose at each experience's creation time.
A ground truth of another dataset still yields a number (``np.interp`` clamps outside
its time range), so :func:`check_groundtruth_covers` compares the two first:

* time range: the share of the map's times inside the ground truth's; under half is
  an error (another time base or another dataset), less than all a warning;
* samples: fewer than two ground-truth poses over the map's time range is a warning
  (the ATE then measures a straight line);
* extent: the path through the experiences in creation order against the ground
  truth's path through the same times. Beyond :data:`REFUSE_RATIO` (either way) the
  ground truth is of another route: an error; beyond :data:`WARN_RATIO` a warning.

Example:
    >>> import numpy as np
    >>> from torchratslam.eval.groundtruth import groundtruth_coverage
    >>> gt = np.array([[0, 0, 0, 0], [10, 10, 0, 0]], float)
    >>> c = groundtruth_coverage(np.array([1.0, 5.0]), np.array([[1, 0], [5, 0.0]]), gt)
    >>> round(c.in_time, 2), round(c.path_ratio, 2)
    (1.0, 1.0)
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from torchratslam.errors import InputError

__all__ = [
    "REFUSE_RATIO",
    "WARN_RATIO",
    "GroundTruthCoverage",
    "check_groundtruth_covers",
    "groundtruth_coverage",
]

log = logging.getLogger(__name__)

WARN_RATIO = 1.5
"""Path lengths of map and ground truth further apart than this factor: a warning."""
REFUSE_RATIO = 3.0
"""Path lengths further apart than this factor: not this map's ground truth (an error)."""
_EPS_T = 1e-9


@dataclass(frozen=True)
class GroundTruthCoverage:
    """How well a ground truth covers a map.

    Attributes:
        in_time: share of the map's times inside the ground truth's time range (0..1).
        samples: ground-truth poses inside the map's time range.
        map_path_m: path through the map's positions in time order (m).
        groundtruth_path_m: path through the ground truth at the same times (m).
        path_ratio: the larger path over the smaller (1: alike; inf: one is zero).
        map_times: the map's time range ``(first, last)`` (s).
        groundtruth_times: the ground truth's time range ``(first, last)`` (s).
    """

    in_time: float
    samples: int
    map_path_m: float
    groundtruth_path_m: float
    path_ratio: float
    map_times: tuple[float, float]
    groundtruth_times: tuple[float, float]


def _path(xy: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) > 1 else 0.0


def groundtruth_coverage(t: np.ndarray, xy: np.ndarray, gt: np.ndarray) -> GroundTruthCoverage:
    """Measure how ``gt`` covers a map's positions ``xy`` made at times ``t``.

    Args:
        t: the map's times (s), e.g. the experiences' creation times. Shape: ``(N,)``.
        xy: the map's positions at those times (m). Shape: ``(N, 2)`` (or ``(N, 3)``).
        gt: the ground truth, rows ``[t, x, y, theta]`` in increasing t. Shape: ``(T, 4)``.

    Returns:
        :class:`GroundTruthCoverage`.

    Raises:
        InputError: the arrays have the wrong shapes.
    """
    t = np.asarray(t, np.float64).reshape(-1)
    pos = np.asarray(xy, np.float64)
    g = np.asarray(gt, np.float64)
    if pos.ndim != 2 or pos.shape[0] != t.size or pos.shape[1] < 2:
        raise InputError(f"map positions of shape {pos.shape} do not match {t.size} times")
    if g.ndim != 2 or g.shape[1] < 3 or g.shape[0] == 0:
        raise InputError(f"ground truth must be a (T, 4) array [t, x, y, theta], got {g.shape}")
    order = np.argsort(t, kind="stable")
    t, pos = t[order], pos[order, :2]
    lo, hi = float(g[0, 0]), float(g[-1, 0])
    inside = (t >= lo - _EPS_T) & (t <= hi + _EPS_T)
    t0, t1 = (float(t[0]), float(t[-1])) if t.size else (0.0, 0.0)
    samples = int(((g[:, 0] >= t0 - _EPS_T) & (g[:, 0] <= t1 + _EPS_T)).sum())
    truth = np.stack([np.interp(t, g[:, 0], g[:, 1]), np.interp(t, g[:, 0], g[:, 2])], axis=1)
    a, b = _path(pos), _path(truth)
    ratio = max(a, b) / min(a, b) if min(a, b) > 0 else (1.0 if a == b else math.inf)
    return GroundTruthCoverage(
        in_time=float(inside.mean()) if t.size else 1.0,
        samples=samples,
        map_path_m=a,
        groundtruth_path_m=b,
        path_ratio=ratio,
        map_times=(t0, t1),
        groundtruth_times=(lo, hi),
    )


def check_groundtruth_covers(
    t: np.ndarray, xy: np.ndarray, gt: np.ndarray, *, source: str, what: str = "the map"
) -> GroundTruthCoverage:
    """Refuse a ground truth that does not describe the map; warn when it only partly
    does (see the module docstring for the rules).

    Args:
        t, xy, gt: as for :func:`groundtruth_coverage`.
        source: the ground truth's name in messages (a file or a dataset spec).
        what: the map's name in messages.

    Returns:
        The coverage (after any warnings were logged).

    Raises:
        InputError: under half of the map's times inside the ground truth's range, or
            path lengths more than :data:`REFUSE_RATIO` apart (one line naming both).
    """
    c = groundtruth_coverage(t, xy, gt)
    (m0, m1), (g0, g1) = c.map_times, c.groundtruth_times
    times = f"ground truth [{g0:.6g}, {g1:.6g}] s, {what} [{m0:.6g}, {m1:.6g}] s"
    if c.in_time < 0.5:
        raise InputError(
            f"{source}: the ground truth's times cover {c.in_time:.0%} of {what}'s ({times}); "
            "it is the ground truth of another dataset or time base; give the one the map "
            "was made from"
        )
    paths = (
        f"{what} runs {c.map_path_m:.3g} m, the ground truth {c.groundtruth_path_m:.3g} m "
        f"over the same times"
    )
    if c.path_ratio > REFUSE_RATIO:
        raise InputError(
            f"{source}: {paths} ({c.path_ratio:.3g}x apart): it is not the ground truth of "
            f"{what}; give the dataset or ground-truth CSV the map was made from"
        )
    if c.in_time < 1.0:
        log.warning(
            "%s: the ground truth covers %.0f%% of %s's times (%s); the ATE is taken over "
            "the poses inside it only",
            source,
            100 * c.in_time,
            what,
            times,
        )
    if c.samples < 2 and m1 > m0:
        log.warning(
            "%s: only %d ground-truth pose(s) within %s's times (%s); the ATE compares "
            "with a straight line",
            source,
            c.samples,
            what,
            times,
        )
    if c.path_ratio > WARN_RATIO:
        log.warning(
            "%s: %s (%.3gx apart); check that it is the ground truth of %s",
            source,
            paths,
            c.path_ratio,
            what,
        )
    return c
