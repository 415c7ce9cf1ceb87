"""Readers: datasets as a stream of :class:`~torchratslam.messages.Frame`.

Every reader has ``frames()`` (also ``iter(reader)``), ``len(reader)``,
``groundtruth()`` (``(T, 4)`` rows ``[t, x, y, theta]`` or None), ``name`` and
``has_odometry`` (False when the data carries no odometry, so the pipeline must use
visual odometry). Frames are read lazily, one at a time.

* :class:`DirectoryReader` -- ``frames/`` (images in natural order of their file
  names: ``frame_2`` before ``frame_10``; names that differ only in leading zeros are
  refused as ambiguous; the order is logged; gaps and repeats in the frame numbers
  are warnings, kept in ``input_warnings``),
  ``odometry.csv`` (header with ``t``, ``vtrans`` m/s, ``vrot`` rad/s; row k is the
  velocity over the interval that ends at row k's ``t``; other columns are ignored),
  optional ``groundtruth.csv`` (``t, x, y, theta``), optional ``meta.json`` (its
  ``camera.columns`` saying "counter-clockwise" sets ``mirrored``). This is what
  ``torchratslam.sim.write_dataset`` writes.
* :class:`VideoReader` -- a video file plus an optional odometry CSV (same format,
  one row per video frame); without it, timestamps come from the video's frame rate
  and the pipeline uses visual odometry.
* :class:`~torchratslam.readers.bags.BagReader` -- a ROS 1 or ROS 2 (sqlite3, MCAP)
  bag, in :mod:`torchratslam.readers.bags`.
* :func:`open_data` -- dispatch on a spec: a directory, a video, a ROS bag, or
  ``sim:NAME`` / ``sim:NAME/sessionK`` (the simulator).

Errors (missing files, unreadable images, mismatched counts, non-monotonic or NaN
timestamps and values, odometry faster than ``max_speed`` / ``max_turn_rate``, ground
truth whose times do not overlap the frames' times: a different time base) raise
:class:`~ratslam_graph.errors.InputError` naming the file and the row.
"""

from __future__ import annotations

import csv
import itertools
import json
import logging
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ratslam_graph.geometry import wrap_angle
from torchratslam.errors import InputError, option
from torchratslam.messages import Frame
from torchratslam.readers.limits import MAX_SPEED, MAX_TURN_RATE

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_EXTENSIONS",
    "DirectoryReader",
    "Reader",
    "VideoReader",
    "check_odometry",
    "check_time_bases",
    "frame_numbering",
    "natural_key",
    "open_data",
    "read_groundtruth_csv",
    "read_odometry_csv",
]

log = logging.getLogger(__name__)

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff")
VIDEO_EXTENSIONS = (".mp4", ".avi", ".mkv", ".mov", ".mpg", ".mpeg", ".webm", ".m4v")
IRAT_IMAGE_TOPIC = "/irat_red/camera/image/compressed"
IRAT_ODOM_TOPIC = "/irat_red/odom"
IRAT_GROUNDTRUTH_TOPIC = "/overhead/pose"
_CSV_MAX_BYTES = 1 << 31


# ----------------------------------------------------------------------------- CSV files
def _read_csv_columns(path: Path, required: tuple[str, ...]) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    if path.stat().st_size > _CSV_MAX_BYTES:
        raise InputError(f"{path}: {path.stat().st_size} bytes is too large for a CSV table")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:  # a spreadsheet's BOM
            rows = list(
                csv.reader(line for line in fh if line.strip() and not line.startswith("#"))
            )
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: cannot be read as CSV ({exc})") from None
    if not rows:
        raise InputError(f"{path}: empty file; expected a header with {', '.join(required)}")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(
            f"{path}: header {header} lacks column(s) {', '.join(missing)}; "
            f"the first line must name the columns, e.g. '{','.join(required)}'"
        )
    cols = [header.index(c) for c in required]
    out = np.empty((len(rows) - 1, len(required)), dtype=np.float64)
    for i, row in enumerate(rows[1:]):
        try:
            out[i] = [float(row[c]) for c in cols]
        except (ValueError, IndexError):
            raise InputError(
                f"{path}, line {i + 2}: expected numbers in {', '.join(required)}, got {row}"
            ) from None
    bad = ~np.isfinite(out).all(axis=1)
    if bad.any():
        line = int(np.flatnonzero(bad)[0]) + 2
        raise InputError(f"{path}, line {line}: NaN or infinite value; remove or fix that row")
    t = out[:, 0]
    if t.size > 1 and not np.all(np.diff(t) > 0):
        line = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 3
        raise InputError(
            f"{path}, line {line}: timestamps must increase strictly (t={t[line - 2]} after "
            f"{t[line - 3]}); sort the file or remove duplicates"
        )
    return {c: out[:, j] for j, c in enumerate(required)}


def check_odometry(
    vtrans: np.ndarray,
    vrot: np.ndarray,
    source: str,
    *,
    max_speed: float = MAX_SPEED,
    max_turn_rate: float = MAX_TURN_RATE,
    first_line: int = 2,
) -> None:
    """Refuse NaN/inf and implausible odometry, naming the first bad row.

    Args:
        vtrans, vrot: velocities (m/s, rad/s). Shape: ``(N,)``.
        source: the file (or topic) named in the message.
        max_speed, max_turn_rate: the limits (m/s, rad/s).
        first_line: the line number of row 0 (2 for a CSV with a header).

    Raises:
        InputError: naming the line, the value and the limit.
    """
    for arg, limit in (("max_speed", max_speed), ("max_turn_rate", max_turn_rate)):
        if not (np.isfinite(limit) and limit > 0):
            raise InputError(f"{arg} = {limit!r}: a limit must be a finite number above 0")
    for name, v, limit, unit, flag in (
        ("vtrans", vtrans, max_speed, "m/s", option("--max-speed", "max_speed")),
        ("vrot", vrot, max_turn_rate, "rad/s", option("--max-turn-rate", "max_turn_rate")),
    ):
        v = np.asarray(v, dtype=np.float64)
        bad = ~np.isfinite(v) | (np.abs(v) > limit)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            what = "is not finite" if not np.isfinite(v[i]) else f"exceeds {limit:g} {unit}"
            raise InputError(
                f"{source}, line {i + first_line}: {name} = {v[i]:g} {unit} {what}; fix that "
                f"row, or raise the limit ({flag}) if the platform really moves that fast"
            )


def read_odometry_csv(
    path: str | Path, *, max_speed: float = MAX_SPEED, max_turn_rate: float = MAX_TURN_RATE
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read an odometry CSV: ``(t, vtrans, vrot)``, each ``(N,)`` float64.

    Args:
        path: the file.
        max_speed, max_turn_rate: rows faster than these (m/s, rad/s) are refused.

    Raises:
        InputError: missing file or columns, non-numeric/NaN values, non-increasing t,
            implausible speeds (naming the line).
    """
    c = _read_csv_columns(Path(path), ("t", "vtrans", "vrot"))
    check_odometry(
        c["vtrans"], c["vrot"], str(path), max_speed=max_speed, max_turn_rate=max_turn_rate
    )
    return c["t"], c["vtrans"], c["vrot"]


def check_time_bases(t: np.ndarray, gt: np.ndarray | None, frames: str, gt_source: str) -> None:
    """Check that the ground truth's times cover the frames' times (same time base).

    Ground truth is matched to frames by time (interpolated at each frame's ``t``). When
    the two time ranges do not overlap, or the ground truth covers fewer than half of
    the frames, the files use different time bases (e.g. a video's frame times from 0
    s against Unix times): an error. A partial cover is logged as a warning.

    Raises:
        InputError: naming both ranges.
    """
    if gt is None or gt.shape[0] == 0 or t.size == 0:
        return
    lo, hi = float(gt[0, 0]), float(gt[-1, 0])
    span, gt_span = float(t[-1] - t[0]), hi - lo
    if t.size >= 3 and 0 < span < 1e-6 * gt_span:
        raise InputError(
            f"{gt_source}: the {t.size} frame times of {frames} span {span:.3g} s against "
            f"the ground truth's {gt_span:.6g} s: the files use different time units (e.g. "
            "nanoseconds against seconds); give both in seconds"
        )
    inside = (t >= lo - 1e-9) & (t <= hi + 1e-9)
    frac = float(inside.mean())
    if frac < 0.5:
        raise InputError(
            f"{gt_source}: ground-truth times [{lo:.6g}, {hi:.6g}] s cover "
            f"{int(inside.sum())} of {t.size} frame times [{t[0]:.6g}, {t[-1]:.6g}] s of "
            f"{frames}: the files use different time bases (give the odometry CSV's times, "
            "or shift one file's t column)"
        )
    if frac < 1.0:
        log.warning(
            "%s: ground truth covers %d of %d frames (times [%.6g, %.6g] s vs frames "
            "[%.6g, %.6g] s); frames outside it have no ground-truth pose",
            gt_source,
            int(inside.sum()),
            t.size,
            lo,
            hi,
            t[0],
            t[-1],
        )


_DIGITS = re.compile(r"(\d+)")


def natural_key(name: str) -> tuple:
    """Sort key of a file name with its digit runs compared as numbers
    (``frame_2`` < ``frame_10``)."""
    return tuple(int(p) if i % 2 else p for i, p in enumerate(_DIGITS.split(name)))


def natural_sort(files: list[Path], where: str) -> list[Path]:
    """``files`` in natural order of their names (logged).

    Raises:
        InputError: two names differ only in leading zeros (``frame_1``, ``frame_01``),
            so no order is certain.
    """
    keyed = sorted(((natural_key(f.name), f.name, f) for f in files), key=lambda x: (x[0], x[1]))
    for (ka, na, _), (kb, nb, _) in itertools.pairwise(keyed):
        if ka == kb:
            raise InputError(
                f"{where}: {na!r} and {nb!r} differ only in leading zeros, so their order is "
                "ambiguous; rename the images with one numbering"
            )
    out = [f for _, _, f in keyed]
    names = [f.name for f in out]
    shown = ", ".join(names[:3]) + (f", ..., {names[-1]}" if len(names) > 3 else "")
    if names != sorted(names):
        log.warning("%s: %d images in natural order (not as strings): %s", where, len(out), shown)
    else:
        log.info("%s: %d images in order: %s", where, len(out), shown)
    return out


def _span(a: int, b: int) -> str:
    return str(a) if a == b else f"{a}..{b}"


def frame_numbering(names: list[str], where: str) -> tuple[str, ...]:
    """Gaps and repeats in the frame numbers of image names in reading order.

    The frame number of a name is its last run of digits that is not the same in every
    name (``cam2_000031.png``: 31). The usual step between two
    names is the most common difference; a larger one is a gap (frames missing, or
    renamed to later numbers, so every later image meets another row of the odometry),
    a zero or negative one a repeat. Names without digits are not checked.

    Args:
        names: the file names, in the order they are read.
        where: the folder named in the messages.

    Returns:
        One message per kind of problem (empty when the numbering is regular).
    """
    runs = [_DIGITS.findall(Path(n).stem) for n in names]
    width = len(runs[0]) if runs else 0
    if len(names) < 2 or not width or any(len(r) != width for r in runs):
        return ()
    table = np.array([[int(v) for v in r] for r in runs], dtype=np.int64)
    varying = np.flatnonzero((table != table[0]).any(axis=0))
    nums = table[:, varying[-1] if varying.size else width - 1]
    diff = np.diff(nums)
    positive = diff[diff > 0]
    if not positive.size:
        step = 1
    else:
        values, counts = np.unique(positive, return_counts=True)
        step = int(values[np.argmax(counts)])
    out = []
    gaps = np.flatnonzero(diff > step)
    if gaps.size:
        shown = ", ".join(
            f"{_span(int(nums[i]) + step, int(nums[i + 1]) - step)} "
            f"({names[i]}, then {names[i + 1]})"
            for i in gaps[:3]
        )
        more = f" and {gaps.size - 3} more" if gaps.size > 3 else ""
        out.append(
            f"{where}: the frame numbers skip {shown}{more}; the images are read in name "
            "order, one odometry row each, so a missing or renamed image shifts every later "
            "frame against its odometry; check the numbering"
        )
    repeats = np.flatnonzero(diff <= 0)
    if repeats.size:
        shown = ", ".join(f"{names[i]} and {names[i + 1]}" for i in repeats[:3])
        more = f" and {repeats.size - 3} more" if repeats.size > 3 else ""
        out.append(
            f"{where}: frame numbers repeat or go back ({shown}{more}); the images are read "
            "in name order, one odometry row each; check that every image is one frame"
        )
    for message in out:
        log.warning("%s", message)
    return tuple(out)


def read_groundtruth_csv(path: str | Path) -> np.ndarray:
    """Read a ground-truth CSV with columns ``t, x, y, theta`` into ``(T, 4)`` float64."""
    c = _read_csv_columns(Path(path), ("t", "x", "y", "theta"))
    return np.stack([c["t"], c["x"], c["y"], c["theta"]], axis=1)


def _pose_at(gt: np.ndarray | None, t: float) -> tuple[float, float, float] | None:
    if gt is None or gt.shape[0] == 0 or t < gt[0, 0] - 1e-9 or t > gt[-1, 0] + 1e-9:
        return None
    x = float(np.interp(t, gt[:, 0], gt[:, 1]))
    y = float(np.interp(t, gt[:, 0], gt[:, 2]))
    th = float(np.interp(t, gt[:, 0], np.unwrap(gt[:, 3])))
    return x, y, wrap_angle(th, include_pi=True)


def _frames_from_arrays(
    images: Iterator[np.ndarray],
    t: np.ndarray,
    vtrans: np.ndarray,
    vrot: np.ndarray,
    gt: np.ndarray | None,
    source: str,
) -> Iterator[Frame]:
    n = t.shape[0]
    k = -1
    for k, image in enumerate(images):
        if k >= n:
            raise InputError(
                f"{source}: more images than odometry rows ({n}); the counts must match"
            )
        dt = 0.0 if k == 0 else float(t[k] - t[k - 1])
        yield Frame(
            index=k,
            t=float(t[k]),
            image=image,
            vtrans=float(vtrans[k]),
            vrot=float(vrot[k]),
            dt=dt,
            pose=_pose_at(gt, float(t[k])),
        )
    if k + 1 != n:
        raise InputError(f"{source}: {k + 1} images but {n} odometry rows; the counts must match")


class Reader:
    """Base of the readers: iteration, length, ground truth."""

    name: str = "data"
    has_odometry: bool = True
    mirrored: bool = False
    """True when image columns turn counter-clockwise (the simulator's panoramas)."""
    input_warnings: tuple[str, ...] = ()
    """What looked wrong in the input but did not stop it (e.g. gaps in the frame
    numbers), one message each; a run records them in its metrics."""

    def frames(self) -> Iterator[Frame]:  # pragma: no cover - abstract
        raise NotImplementedError

    def __iter__(self) -> Iterator[Frame]:
        return self.frames()

    def __len__(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def groundtruth(self) -> np.ndarray | None:
        """``(T, 4)`` rows ``[t, x, y, theta]``, or None when there is none."""
        return None


# ----------------------------------------------------------------------------- directory
def _read_meta(path: Path) -> dict[str, Any]:
    """The optional ``meta.json`` of a dataset directory (``{}`` when absent)."""
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not valid JSON ({exc}); fix or delete it") from None
    return data if isinstance(data, dict) else {}


class DirectoryReader(Reader):
    """A dataset directory: ``frames/``, ``odometry.csv``, optional ``groundtruth.csv``.

    Args:
        path: the directory.
        odometry: another odometry CSV to use instead of ``path/odometry.csv``.
        color: load images as BGR (default: grey, which is all the local view uses).
        rate: frames per second used for timestamps when there is no odometry CSV
            (then ``has_odometry`` is False and the pipeline needs visual odometry).
        groundtruth: another ground-truth CSV to use instead of ``path/groundtruth.csv``.
        max_speed, max_turn_rate: odometry rows faster than these are refused.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        odometry: str | Path | None = None,
        color: bool = False,
        rate: float = 10.0,
        groundtruth: str | Path | None = None,
        max_speed: float = MAX_SPEED,
        max_turn_rate: float = MAX_TURN_RATE,
    ) -> None:
        self.path = Path(path)
        self.name = self.path.name
        if not self.path.is_dir():
            raise InputError(f"{self.path}: not a directory")
        fdir = self.path / "frames"
        if not fdir.is_dir():
            raise InputError(f"{self.path}: no frames/ folder; put the images in {fdir}")
        entries = sorted(fdir.iterdir())
        files = [p for p in entries if p.suffix.lower() in IMAGE_EXTENSIONS]
        if len(files) < len(entries):
            other = [p.name for p in entries if p.suffix.lower() not in IMAGE_EXTENSIONS]
            log.info(
                "%s: skipped %d entries that are not images (%s)",
                fdir,
                len(other),
                ", ".join(other[:3]) + (", ..." if len(other) > 3 else ""),
            )
        if not files:
            raise InputError(f"{fdir}: no images ({', '.join(IMAGE_EXTENSIONS)})")
        self.files = natural_sort(files, str(fdir))
        self.input_warnings = frame_numbering([f.name for f in self.files], str(fdir))
        self.color = color
        odo = Path(odometry) if odometry is not None else self.path / "odometry.csv"
        if odo.is_file() or odometry is not None:
            self.t, self.vtrans, self.vrot = read_odometry_csv(
                odo, max_speed=max_speed, max_turn_rate=max_turn_rate
            )
            self.has_odometry = True
            if self.t.shape[0] != len(self.files):
                raise InputError(
                    f"{self.path}: {len(self.files)} images in frames/ but {self.t.shape[0]} rows "
                    f"in {odo.name}; the counts must match (one odometry row per image)"
                )
        else:
            if rate <= 0:
                raise InputError(f"frame rate must be positive, got {rate}")
            self.t = np.arange(len(self.files), dtype=np.float64) / rate
            self.vtrans = np.zeros(len(self.files))
            self.vrot = np.zeros(len(self.files))
            self.has_odometry = False
            log.info("%s: no odometry.csv; timestamps at %g frames/s, no odometry", self.path, rate)
        gt = Path(groundtruth) if groundtruth is not None else self.path / "groundtruth.csv"
        self._gt = read_groundtruth_csv(gt) if gt.is_file() or groundtruth is not None else None
        check_time_bases(self.t, self._gt, str(fdir), str(gt))
        self.meta = _read_meta(self.path / "meta.json")
        camera: dict[str, Any] = (
            self.meta.get("camera") if isinstance(self.meta.get("camera"), dict) else {}  # type: ignore[assignment]
        )
        self.mirrored = "counter-clockwise" in str(camera.get("columns", ""))

    def __len__(self) -> int:
        return len(self.files)

    def groundtruth(self) -> np.ndarray | None:
        return None if self._gt is None else self._gt.copy()

    def _images(self) -> Iterator[np.ndarray]:
        flag = cv2.IMREAD_COLOR if self.color else cv2.IMREAD_GRAYSCALE
        first: tuple[Path, tuple[int, ...]] | None = None
        for f in self.files:
            img = cv2.imread(str(f), flag)
            if img is None:
                raise InputError(
                    f"{f}: unreadable image (corrupt or not an image); replace or remove it"
                )
            if first is None:
                first = (f, img.shape)
            elif img.shape[:2] != first[1][:2]:
                raise InputError(
                    f"{f}: {img.shape[1]} x {img.shape[0]} pixels, but {first[0].name} and "
                    f"the frames after it are {first[1][1]} x {first[1][0]}; every frame of "
                    "a dataset must come from one camera at one size (resize or remove it)"
                )
            yield img

    def frames(self) -> Iterator[Frame]:
        return _frames_from_arrays(
            self._images(), self.t, self.vtrans, self.vrot, self._gt, str(self.path)
        )


# ----------------------------------------------------------------------------- video
class VideoReader(Reader):
    """A video file, with an odometry CSV (one row per frame) or without (visual odometry).

    Args:
        path: the video.
        odometry: odometry CSV (``t, vtrans, vrot``); None: timestamps from the frame
            rate and ``has_odometry`` False.
        groundtruth: optional ground-truth CSV (``t, x, y, theta``).
        color: keep BGR frames (default: grey).
        max_speed, max_turn_rate: odometry rows faster than these are refused.

    With an odometry CSV, the video's frame count must equal its rows (checked when the
    reader is made, before any work).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        odometry: str | Path | None = None,
        groundtruth: str | Path | None = None,
        color: bool = False,
        max_speed: float = MAX_SPEED,
        max_turn_rate: float = MAX_TURN_RATE,
    ) -> None:
        self.path = Path(path)
        self.name = self.path.stem
        if not self.path.is_file():
            raise InputError(f"{self.path}: video file not found")
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise InputError(f"{self.path}: cannot be opened as a video (unknown codec or corrupt)")
        self.fps = float(cap.get(cv2.CAP_PROP_FPS)) or 10.0
        self._count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        cap.release()
        self.color = color
        if odometry is not None:
            self.t, self.vtrans, self.vrot = read_odometry_csv(
                odometry, max_speed=max_speed, max_turn_rate=max_turn_rate
            )
            self.has_odometry = True
            if self._count != self.t.shape[0] and self._exact_count() != self.t.shape[0]:
                raise InputError(
                    f"{self.path}: {self._count} frames but {self.t.shape[0]} rows in "
                    f"{odometry}; the counts must match (one odometry row per frame)"
                )
        else:
            self.t = np.arange(max(self._count, 0), dtype=np.float64) / self.fps
            self.vtrans = np.zeros_like(self.t)
            self.vrot = np.zeros_like(self.t)
            self.has_odometry = False
            log.info(
                "%s: no odometry CSV; timestamps at %g frames/s, no odometry", self.path, self.fps
            )
        self._gt = read_groundtruth_csv(groundtruth) if groundtruth is not None else None
        check_time_bases(self.t, self._gt, str(self.path), str(groundtruth))

    def _exact_count(self) -> int:
        """The number of frames, counted by reading (the container's count can be off)."""
        cap = cv2.VideoCapture(str(self.path))
        n = 0
        try:
            while cap.grab():
                n += 1
        finally:
            cap.release()
        self._count = n
        return n

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def groundtruth(self) -> np.ndarray | None:
        return None if self._gt is None else self._gt.copy()

    def _images(self) -> Iterator[np.ndarray]:
        cap = cv2.VideoCapture(str(self.path))
        try:
            while True:
                ok, img = cap.read()
                if not ok:
                    break
                if not self.color and img.ndim == 3:
                    img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                yield img
        finally:
            cap.release()

    def frames(self) -> Iterator[Frame]:
        return _frames_from_arrays(
            self._images(), self.t, self.vtrans, self.vrot, self._gt, str(self.path)
        )


# ----------------------------------------------------------------------------- ROS bags
# ----------------------------------------------------------------------------- dispatch
def open_data(
    spec: str | Path,
    *,
    odometry: str | Path | None = None,
    groundtruth: str | Path | None = None,
    image_topic: str = IRAT_IMAGE_TOPIC,
    odom_topic: str | None = IRAT_ODOM_TOPIC,
    color: bool = False,
    max_speed: float = MAX_SPEED,
    max_turn_rate: float = MAX_TURN_RATE,
) -> Any:
    """Open a dataset from a spec.

    Args:
        spec: a dataset directory, a video file, a ROS 1 ``.bag`` file, a ROS 2 bag
            directory (or its ``.db3`` / ``.mcap`` file), or ``sim:NAME`` /
            ``sim:NAME/sessionK`` (the simulator's tours).
        odometry: an odometry CSV (for a video, or to replace a directory's).
        groundtruth: a ground-truth CSV (for a video, or to replace a directory's).
        image_topic, odom_topic: ROS topics for a bag.
        color: load BGR images instead of grey.
        max_speed, max_turn_rate: odometry faster than these (m/s, rad/s) is refused.

    Returns:
        A reader (or a simulator session) with ``frames()``, ``len()`` and
        ``groundtruth()``.

    Raises:
        InputError: the spec names nothing readable.
    """
    s = str(spec)
    if s.startswith("sim:"):
        given = [n for n, v in (("odometry", odometry), ("groundtruth", groundtruth)) if v]
        if given:
            raise InputError(
                f"data {s!r}: the simulator makes its own odometry and ground truth; "
                f"{' and '.join(given)} cannot be given with sim: data (write the tour with "
                "'torchratslam simulate' and edit its CSVs instead)"
            )
        from torchratslam.sim import open_sim

        return open_sim(s)
    limits = {"max_speed": max_speed, "max_turn_rate": max_turn_rate}
    p = Path(s)
    if not p.exists():
        raise InputError(
            f"data {s!r} not found; give a dataset directory, a video, a ROS bag, or sim:NAME"
        )
    from torchratslam.readers.bags import BagReader, is_bag

    if is_bag(p):
        return BagReader(p, image_topic=image_topic, odom_topic=odom_topic, color=color)
    if p.is_dir():
        return DirectoryReader(p, odometry=odometry, groundtruth=groundtruth, color=color, **limits)
    suffix = p.suffix.lower()
    if suffix in VIDEO_EXTENSIONS:
        return VideoReader(p, odometry=odometry, groundtruth=groundtruth, color=color, **limits)
    raise InputError(
        f"data {s!r}: unknown kind (expected a directory, a video {', '.join(VIDEO_EXTENSIONS)}, "
        "a ROS 1 .bag, a ROS 2 bag directory, or sim:NAME)"
    )
