"""Readers: datasets as a stream of :class:`~torchratslam.messages.Frame`.

Every reader has ``frames()`` (also ``iter(reader)``), ``len(reader)``,
``groundtruth()`` (``(T, 4)`` rows ``[t, x, y, theta]`` or None), ``name`` and
``has_odometry`` (False when the data carries no odometry, so the pipeline must use
visual odometry). Frames are read lazily, one at a time.

* :class:`DirectoryReader` -- ``frames/`` (images sorted by file name),
  ``odometry.csv`` (header with ``t``, ``vtrans`` m/s, ``vrot`` rad/s; row k is the
  velocity over the interval that ends at row k's ``t``; other columns are ignored),
  optional ``groundtruth.csv`` (``t, x, y, theta``), optional ``meta.json`` (its
  ``camera.columns`` saying "counter-clockwise" sets ``mirrored``). This is what
  ``torchratslam.sim.write_dataset`` writes.
* :class:`VideoReader` -- a video file plus an optional odometry CSV (same format,
  one row per video frame); without it, timestamps come from the video's frame rate
  and the pipeline uses visual odometry.
* :class:`BagReader` -- a ROS 1 bag read with ``rosbags`` (no ROS install):
  ``sensor_msgs/CompressedImage`` or ``sensor_msgs/Image`` and ``nav_msgs/Odometry``
  (``twist.twist.linear.x``, ``twist.twist.angular.z``), optional
  ``geometry_msgs/PoseStamped`` ground truth. Defaults are the iRat 2011 bag's topics.
  Unlike the ROS node, every message is used, in header-stamp order, so results do
  not depend on playback speed. The odometry between two images is the exact
  integral of the odometry messages' piecewise-constant velocities over that
  interval, divided by its length (OpenRatSLAM instead feeds each odometry message to
  the pose cells as it arrives; the distance travelled is the same).
* :func:`open_data` -- dispatch on a spec: a directory, a video, a ``.bag``, or
  ``sim:NAME`` / ``sim:NAME/sessionK`` (the simulator).

Errors (missing files, unreadable images, mismatched counts, non-monotonic or NaN
timestamps and values) raise :class:`~torchratslam.graph.errors.InputError` naming the file.
"""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np

from torchratslam.graph.errors import InputError
from torchratslam.graph.geometry import wrap_angle
from torchratslam.messages import Frame

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_EXTENSIONS",
    "BagReader",
    "DirectoryReader",
    "Reader",
    "VideoReader",
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


# ----------------------------------------------------------------------------- CSV files
def _read_csv_columns(path: Path, required: tuple[str, ...]) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        with path.open(newline="") as fh:
            rows = list(
                csv.reader(line for line in fh if line.strip() and not line.startswith("#"))
            )
    except (OSError, UnicodeDecodeError) as exc:
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


def read_odometry_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read an odometry CSV: ``(t, vtrans, vrot)``, each ``(N,)`` float64.

    Raises:
        InputError: missing file or columns, non-numeric/NaN values, non-increasing t.
    """
    c = _read_csv_columns(Path(path), ("t", "vtrans", "vrot"))
    return c["t"], c["vtrans"], c["vrot"]


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
    """

    def __init__(
        self,
        path: str | Path,
        *,
        odometry: str | Path | None = None,
        color: bool = False,
        rate: float = 10.0,
    ) -> None:
        self.path = Path(path)
        self.name = self.path.name
        if not self.path.is_dir():
            raise InputError(f"{self.path}: not a directory")
        fdir = self.path / "frames"
        if not fdir.is_dir():
            raise InputError(f"{self.path}: no frames/ folder; put the images in {fdir}")
        entries = sorted(fdir.iterdir())
        self.files = [p for p in entries if p.suffix.lower() in IMAGE_EXTENSIONS]
        if len(self.files) < len(entries):
            other = [p.name for p in entries if p.suffix.lower() not in IMAGE_EXTENSIONS]
            log.info(
                "%s: skipped %d entries that are not images (%s)",
                fdir,
                len(other),
                ", ".join(other[:3]) + (", ..." if len(other) > 3 else ""),
            )
        if not self.files:
            raise InputError(f"{fdir}: no images ({', '.join(IMAGE_EXTENSIONS)})")
        self.color = color
        odo = Path(odometry) if odometry is not None else self.path / "odometry.csv"
        if odo.is_file() or odometry is not None:
            self.t, self.vtrans, self.vrot = read_odometry_csv(odo)
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
        gt = self.path / "groundtruth.csv"
        self._gt = read_groundtruth_csv(gt) if gt.is_file() else None
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
        for f in self.files:
            img = cv2.imread(str(f), flag)
            if img is None:
                raise InputError(
                    f"{f}: unreadable image (corrupt or not an image); replace or remove it"
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
    """

    def __init__(
        self,
        path: str | Path,
        *,
        odometry: str | Path | None = None,
        groundtruth: str | Path | None = None,
        color: bool = False,
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
            self.t, self.vtrans, self.vrot = read_odometry_csv(odometry)
            self.has_odometry = True
        else:
            self.t = np.arange(max(self._count, 0), dtype=np.float64) / self.fps
            self.vtrans = np.zeros_like(self.t)
            self.vrot = np.zeros_like(self.t)
            self.has_odometry = False
            log.info(
                "%s: no odometry CSV; timestamps at %g frames/s, no odometry", self.path, self.fps
            )
        self._gt = read_groundtruth_csv(groundtruth) if groundtruth is not None else None

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


# ----------------------------------------------------------------------------- ROS 1 bag
def _stamp(msg: Any, fallback_ns: int) -> float:
    header = getattr(msg, "header", None)
    if header is not None:
        s = header.stamp
        t = float(s.sec) + float(s.nanosec) * 1e-9
        if t > 0:
            return t
    return fallback_ns * 1e-9


def _decode_image(msg: Any, msgtype: str, color: bool, topic: str) -> np.ndarray:
    if msgtype.endswith("CompressedImage"):
        buf = np.frombuffer(bytes(msg.data), dtype=np.uint8)
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR if color else cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise InputError(f"{topic}: a CompressedImage ({msg.format!r}) could not be decoded")
        return img
    enc = str(msg.encoding).lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    channels = {"mono8": 1, "8uc1": 1, "bgr8": 3, "rgb8": 3, "8uc3": 3, "bgra8": 4, "rgba8": 4}
    if enc not in channels:
        raise InputError(
            f"{topic}: image encoding {msg.encoding!r} is not supported (use mono8/bgr8/rgb8)"
        )
    c = channels[enc]
    if data.size < h * step or step < w * c:
        raise InputError(
            f"{topic}: image data is shorter than height*step ({data.size} < {h * step})"
        )
    img = (
        data[: h * step].reshape(h, step)[:, : w * c].reshape(h, w, c)
        if c > 1
        else data[: h * step].reshape(h, step)[:, :w]
    )
    if c > 1:
        code = {
            "rgb8": cv2.COLOR_RGB2BGR,
            "rgba8": cv2.COLOR_RGBA2BGR,
            "bgra8": cv2.COLOR_BGRA2BGR,
        }.get(enc)
        img = cv2.cvtColor(img, code) if code is not None else img
        if not color:
            img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2GRAY)
    return np.ascontiguousarray(img)


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _interval_means(t_img: np.ndarray, t_odo: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Mean of the piecewise-constant velocity (value v_i on (t_{i-1}, t_i]) over each
    image interval (t_img[k-1], t_img[k]]; 0 for the first image."""
    if t_odo.size == 0:
        return np.zeros_like(t_img)
    seg = np.diff(t_odo) * v[1:]  # integral over (t_{i-1}, t_i]
    cum = np.concatenate([[0.0], np.cumsum(seg)])  # integral from t_odo[0] to t_odo[i]
    integral = np.interp(t_img, t_odo, cum)  # exact for piecewise-constant v (linear cum)
    # beyond the last message: hold the last velocity
    after = t_img > t_odo[-1]
    integral[after] = cum[-1] + (t_img[after] - t_odo[-1]) * v[-1]
    out = np.zeros_like(t_img)
    dt = np.diff(t_img)
    out[1:] = np.where(dt > 0, np.diff(integral) / np.where(dt > 0, dt, 1.0), 0.0)
    return out


class BagReader(Reader):
    """A ROS 1 bag (read with ``rosbags``; no ROS install needed).

    Args:
        path: the ``.bag`` file.
        image_topic: ``sensor_msgs/CompressedImage`` or ``sensor_msgs/Image`` topic.
        odom_topic: ``nav_msgs/Odometry`` topic; None or absent from the bag: no
            odometry (``has_odometry`` False; use visual odometry).
        groundtruth_topic: optional ``geometry_msgs/PoseStamped`` topic (the iRat's
            overhead camera); ignored when absent from the bag.
        color: decode images as BGR (default: grey).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        image_topic: str = IRAT_IMAGE_TOPIC,
        odom_topic: str | None = IRAT_ODOM_TOPIC,
        groundtruth_topic: str | None = IRAT_GROUNDTRUTH_TOPIC,
        color: bool = False,
    ) -> None:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(path)
        self.name = self.path.stem
        if not self.path.is_file():
            raise InputError(f"{self.path}: bag file not found")
        self.image_topic, self.odom_topic, self.color = image_topic, odom_topic, color
        self._typestore = get_typestore(Stores.ROS1_NOETIC)
        self._AnyReader = AnyReader
        try:
            with AnyReader([self.path], default_typestore=self._typestore) as reader:
                topics = {c.topic: c for c in reader.connections}
                if image_topic not in topics:
                    raise InputError(
                        f"{self.path}: no image topic {image_topic!r} "
                        f"(topics: {', '.join(sorted(topics))}); pass --image-topic"
                    )
                self._count = sum(c.msgcount for c in reader.connections if c.topic == image_topic)
                # header stamps of the images (deserialising is needed for the stamps)
                self._t_img = self._image_stamps(reader)
                t_odo, v, w = [], [], []
                self.has_odometry = odom_topic is not None and odom_topic in topics
                if self.has_odometry:
                    conns = [c for c in reader.connections if c.topic == odom_topic]
                    for conn, ts, raw in reader.messages(connections=conns):
                        msg: Any = reader.deserialize(raw, conn.msgtype)
                        t_odo.append(_stamp(msg, ts))
                        v.append(float(msg.twist.twist.linear.x))
                        w.append(float(msg.twist.twist.angular.z))
                gt = []
                if groundtruth_topic and groundtruth_topic in topics:
                    conns = [c for c in reader.connections if c.topic == groundtruth_topic]
                    for conn, ts, raw in reader.messages(connections=conns):
                        msg = reader.deserialize(raw, conn.msgtype)
                        p = cast(Any, msg).pose
                        gt.append(
                            (_stamp(msg, ts), p.position.x, p.position.y, _yaw(p.orientation))
                        )
        except InputError:
            raise
        except Exception as exc:  # rosbags raises its own hierarchy
            raise InputError(f"{self.path}: cannot be read as a ROS 1 bag ({exc})") from None
        self._order = np.argsort(self._t_img, kind="stable")
        t_img = self._t_img[self._order]
        if not np.all(np.isfinite(t_img)):
            raise InputError(f"{self.path}: image timestamps contain NaN")
        if t_img.size > 1 and np.any(np.diff(t_img) <= 0):
            raise InputError(f"{self.path}: duplicate image timestamps on {image_topic}")
        self.t = t_img
        if self.has_odometry:
            o = np.argsort(np.asarray(t_odo), kind="stable")
            t_o, v_o, w_o = np.asarray(t_odo)[o], np.asarray(v)[o], np.asarray(w)[o]
            if not (
                np.all(np.isfinite(t_o)) and np.all(np.isfinite(v_o)) and np.all(np.isfinite(w_o))
            ):
                raise InputError(f"{self.path}: NaN in the odometry on {odom_topic}")
            self.vtrans = _interval_means(t_img, t_o, v_o)
            self.vrot = _interval_means(t_img, t_o, w_o)
        else:
            log.info(
                "%s: no odometry topic %r; the frames carry no odometry", self.path, odom_topic
            )
            self.vtrans = np.zeros_like(t_img)
            self.vrot = np.zeros_like(t_img)
        self._gt = np.asarray(sorted(gt), dtype=np.float64) if gt else None

    def _image_stamps(self, reader: Any) -> np.ndarray:
        conns = [c for c in reader.connections if c.topic == self.image_topic]
        stamps = []
        for conn, ts, raw in reader.messages(connections=conns):
            stamps.append(_stamp(reader.deserialize(raw, conn.msgtype), ts))
        return np.asarray(stamps, dtype=np.float64)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def groundtruth(self) -> np.ndarray | None:
        return None if self._gt is None else self._gt.copy()

    def _images(self) -> Iterator[np.ndarray]:
        with self._AnyReader([self.path], default_typestore=self._typestore) as reader:
            conns = [c for c in reader.connections if c.topic == self.image_topic]
            if np.all(np.diff(self._order) == 1):  # already in stamp order: stream
                for conn, _, raw in reader.messages(connections=conns):
                    yield _decode_image(
                        reader.deserialize(raw, conn.msgtype),
                        conn.msgtype,
                        self.color,
                        self.image_topic,
                    )
                return
            raws = [(conn.msgtype, raw) for conn, _, raw in reader.messages(connections=conns)]
        for i in self._order:
            msgtype, raw = raws[i]
            yield _decode_image(
                reader.deserialize(raw, msgtype), msgtype, self.color, self.image_topic
            )

    def frames(self) -> Iterator[Frame]:
        return _frames_from_arrays(
            self._images(), self.t, self.vtrans, self.vrot, self._gt, str(self.path)
        )


# ----------------------------------------------------------------------------- dispatch
def open_data(
    spec: str | Path,
    *,
    odometry: str | Path | None = None,
    groundtruth: str | Path | None = None,
    image_topic: str = IRAT_IMAGE_TOPIC,
    odom_topic: str | None = IRAT_ODOM_TOPIC,
    color: bool = False,
) -> Any:
    """Open a dataset from a spec.

    Args:
        spec: a dataset directory, a video file, a ``.bag`` file, or ``sim:NAME`` /
            ``sim:NAME/sessionK`` (the simulator's tours).
        odometry: an odometry CSV (for a video, or to replace a directory's).
        groundtruth: a ground-truth CSV for a video.
        image_topic, odom_topic: ROS topics for a bag.
        color: load BGR images instead of grey.

    Returns:
        A reader (or a simulator session) with ``frames()``, ``len()`` and
        ``groundtruth()``.

    Raises:
        InputError: the spec names nothing readable.
    """
    s = str(spec)
    if s.startswith("sim:"):
        from torchratslam.sim import open_sim

        return open_sim(s)
    p = Path(s)
    if not p.exists():
        raise InputError(
            f"data {s!r} not found; give a dataset directory, a video, a .bag file, or sim:NAME"
        )
    if p.is_dir():
        return DirectoryReader(p, odometry=odometry, color=color)
    suffix = p.suffix.lower()
    if suffix == ".bag":
        return BagReader(p, image_topic=image_topic, odom_topic=odom_topic, color=color)
    if suffix in VIDEO_EXTENSIONS:
        return VideoReader(p, odometry=odometry, groundtruth=groundtruth, color=color)
    raise InputError(
        f"data {s!r}: unknown kind (expected a directory, a video {', '.join(VIDEO_EXTENSIONS)}, "
        "a .bag file, or sim:NAME)"
    )
