"""ROS bags: ROS 1 (``.bag``) and ROS 2 (sqlite3 ``.db3`` or MCAP) through ``rosbags``.

:class:`BagReader` reads any of them with ``rosbags``' ``AnyReader`` (no ROS install):

* images: ``sensor_msgs/CompressedImage`` (JPEG, PNG, ...) or ``sensor_msgs/Image``
  decoded by ``rosbags-image`` (raw encodings ``mono8``, ``mono16``, ``rgb8``, ``bgr8``,
  ``rgba8``, ``bgra8``, 16-bit colour, ``8UC1``/``8UC3``/``16UC1``, the Bayer patterns
  ``bayer_{rggb,bggr,gbrg,grbg}{8,16}`` and the packed YUV 4:2:2 forms), then turned
  into 8-bit grey (or BGR with ``color=True``); 16-bit images are scaled by 255/65535;
* odometry: ``nav_msgs/Odometry`` (``twist.twist.linear.x``, ``twist.twist.angular.z``);
* ground truth (optional): ``geometry_msgs/PoseStamped``.

Topic names are arguments (``--image-topic`` / ``--odom-topic`` on the command line);
the defaults are the iRat 2011 bag's. Unlike the ROS node, every message is used, in
header-stamp order, so results do not depend on playback speed. The odometry between
two images is the exact integral of the odometry messages' piecewise-constant
velocities over that interval, divided by its length (OpenRatSLAM instead feeds each
odometry message to the pose cells as it arrives; the distance travelled is the same).

A ROS 2 bag is a directory holding ``metadata.yaml`` and its storage files; give the
directory, or one of its ``.db3`` / ``.mcap`` files.
"""

from __future__ import annotations

import logging
import math
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from torchratslam.errors import InputError, option
from torchratslam.messages import Frame
from torchratslam.readers.datasets import (
    IRAT_GROUNDTRUTH_TOPIC,
    IRAT_IMAGE_TOPIC,
    IRAT_ODOM_TOPIC,
    Reader,
    _frames_from_arrays,
)

__all__ = ["RAW_ENCODINGS", "BagReader", "bag_kind", "decode_image", "is_bag"]

log = logging.getLogger(__name__)

RAW_ENCODINGS = (
    "mono8",
    "mono16",
    "rgb8",
    "bgr8",
    "rgba8",
    "bgra8",
    "rgb16",
    "bgr16",
    "rgba16",
    "bgra16",
    "8UC1",
    "8UC3",
    "8UC4",
    "16UC1",
    "bayer_rggb8",
    "bayer_bggr8",
    "bayer_gbrg8",
    "bayer_grbg8",
    "bayer_rggb16",
    "bayer_bggr16",
    "bayer_gbrg16",
    "bayer_grbg16",
    "uyvy",
    "yuv422",
    "yuyv",
    "yuv422_yuy2",
)
"""The ``sensor_msgs/Image`` encodings the reader decodes (through ``rosbags-image``)."""

_ROS2_SUFFIXES = (".db3", ".mcap")


def bag_kind(path: str | Path) -> str | None:
    """``"ros1"``, ``"ros2"`` or None: what kind of bag ``path`` is, from its name and layout.

    A ``.bag`` file is ROS 1; a directory with ``metadata.yaml``, or a ``.db3`` / ``.mcap``
    file next to one, is ROS 2.
    """
    p = Path(path)
    if p.is_file() and p.suffix.lower() == ".bag":
        return "ros1"
    if p.is_dir() and (p / "metadata.yaml").is_file():
        return "ros2"
    if p.is_file() and p.suffix.lower() in _ROS2_SUFFIXES:
        return "ros2"
    return None


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` looks like a ROS 1 or ROS 2 bag (see :func:`bag_kind`)."""
    return bag_kind(path) is not None


def _stamp(msg: Any, fallback_ns: int) -> float:
    header = getattr(msg, "header", None)
    if header is not None:
        s = header.stamp
        t = float(s.sec) + float(s.nanosec) * 1e-9
        if t > 0:
            return t
    return fallback_ns * 1e-9


def _encoding(enc: str, topic: str) -> str:
    norm = enc.upper() if enc.lower() in ("8uc1", "8uc3", "8uc4", "16uc1") else enc
    if norm not in RAW_ENCODINGS:
        raise InputError(
            f"{topic}: image encoding {enc!r} is not supported (use one of "
            f"{', '.join(RAW_ENCODINGS)}, or a CompressedImage)"
        )
    return norm


def _unpadded(msg: Any, enc: str, topic: str) -> Any:
    """The message's pixels without row padding (``step`` beyond ``width`` pixels)."""
    from rosbags.image.image import to_cvtype

    depth, _, _, nchan = to_cvtype(enc)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * nchan * depth // 8
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    step = step or row
    if step < row or data.size < h * step:
        raise InputError(
            f"{topic}: image data is shorter than height*step ({data.size} < {h * step}) "
            f"for {w}x{h} {enc}"
        )
    if step != row or data.size != h * row:
        data = np.ascontiguousarray(data[: h * step].reshape(h, step)[:, :row]).reshape(-1)
    return types.SimpleNamespace(
        height=h,
        width=w,
        encoding=enc,
        is_bigendian=int(getattr(msg, "is_bigendian", 0)),
        step=row,
        data=data,
    )


def decode_image(msg: Any, msgtype: str, color: bool = False, topic: str = "image") -> np.ndarray:
    """Decode a ``sensor_msgs/Image`` or ``CompressedImage`` to 8-bit grey or BGR.

    Args:
        msg: the deserialised message.
        msgtype: its type name (``sensor_msgs/msg/Image`` or ``.../CompressedImage``).
        color: return BGR ``(H, W, 3)`` instead of grey ``(H, W)``.
        topic: the topic, for error messages.

    Returns:
        ``uint8`` image. Shape: ``(H, W)`` or ``(H, W, 3)``.

    Raises:
        InputError: an unsupported encoding, truncated data or an undecodable payload.
    """
    from rosbags.image import ImageError, compressed_image_to_cvimage, image_to_cvimage

    try:
        if msgtype.endswith("CompressedImage"):
            try:
                img = compressed_image_to_cvimage(msg)
            except AssertionError:  # cv2.imdecode returned None
                img = None
            if img is None:
                raise InputError(
                    f"{topic}: a CompressedImage ({getattr(msg, 'format', '?')!r}) "
                    "could not be decoded"
                )
            if img.dtype != np.uint8:
                img = (img.astype(np.float64) * (255.0 / 65535.0)).astype(np.uint8)
            if img.ndim == 3 and img.shape[2] == 4:
                img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
            if color and img.ndim == 2:
                img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
            elif not color and img.ndim == 3:
                img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        else:
            enc = _encoding(str(msg.encoding), topic)
            raw = _unpadded(msg, enc, topic)
            if enc in ("8UC1", "16UC1"):  # generic one-channel: treat as mono
                raw.encoding = "mono8" if enc == "8UC1" else "mono16"
            elif enc in ("8UC3", "8UC4"):  # generic three/four channels: treat as BGR(A)
                raw.encoding = "bgr8" if enc == "8UC3" else "bgra8"
            img = image_to_cvimage(raw, "bgr8" if color else "mono8")
    except InputError:
        raise
    except (ImageError, cv2.error, ValueError, TypeError) as exc:
        raise InputError(f"{topic}: image could not be decoded ({exc})") from None
    out = np.ascontiguousarray(img)
    return out if out.flags.writeable else out.copy()  # a view of the message's bytes


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
    """A ROS 1 or ROS 2 bag (read with ``rosbags``; no ROS install needed).

    Args:
        path: a ROS 1 ``.bag`` file, a ROS 2 bag directory (sqlite3 or MCAP), or a
            ``.db3`` / ``.mcap`` file of one.
        image_topic: ``sensor_msgs/CompressedImage`` or ``sensor_msgs/Image`` topic.
        odom_topic: ``nav_msgs/Odometry`` topic; None or absent from the bag: no
            odometry (``has_odometry`` False; use visual odometry).
        groundtruth_topic: optional ``geometry_msgs/PoseStamped`` topic (the iRat's
            overhead camera); ignored when absent from the bag.
        color: decode images as BGR (default: grey).

    Attributes:
        kind: ``"ros1"`` or ``"ros2"``.
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
        if not self.path.exists():
            raise InputError(f"{self.path}: bag not found")
        kind = bag_kind(self.path)
        if kind is None:
            raise InputError(
                f"{self.path}: not a ROS bag (a .bag file, or a ROS 2 bag directory with "
                "metadata.yaml, or its .db3 / .mcap file)"
            )
        self.kind = kind
        if kind == "ros2" and self.path.is_file():
            if not (self.path.parent / "metadata.yaml").is_file():
                raise InputError(
                    f"{self.path}: a ROS 2 storage file without metadata.yaml next to it; "
                    "give the bag directory"
                )
            self.path = self.path.parent
        self.name = self.path.stem if kind == "ros1" else self.path.name
        self.image_topic, self.odom_topic, self.color = image_topic, odom_topic, color
        store = Stores.ROS1_NOETIC if kind == "ros1" else Stores.LATEST
        self._typestore = get_typestore(store)
        self._AnyReader = AnyReader
        label = "a ROS 1 bag" if kind == "ros1" else "a ROS 2 bag"
        try:
            with AnyReader([self.path], default_typestore=self._typestore) as reader:
                topics = {c.topic: c for c in reader.connections}
                if image_topic not in topics:
                    raise InputError(
                        f"{self.path}: no image topic {image_topic!r} "
                        f"(topics: {', '.join(sorted(topics))}); pass "
                        f"{option('--image-topic', 'image_topic')}"
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
                        gmsg: Any = reader.deserialize(raw, conn.msgtype)
                        p = gmsg.pose
                        gt.append(
                            (_stamp(gmsg, ts), p.position.x, p.position.y, _yaw(p.orientation))
                        )
        except InputError:
            raise
        except Exception as exc:  # rosbags raises its own hierarchy
            raise InputError(f"{self.path}: cannot be read as {label} ({exc})") from None
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
                    yield decode_image(
                        reader.deserialize(raw, conn.msgtype),
                        conn.msgtype,
                        self.color,
                        self.image_topic,
                    )
                return
            raws = [(conn.msgtype, raw) for conn, _, raw in reader.messages(connections=conns)]
        for i in self._order:
            msgtype, raw = raws[i]
            yield decode_image(
                reader.deserialize(raw, msgtype), msgtype, self.color, self.image_topic
            )

    def frames(self) -> Iterator[Frame]:
        return _frames_from_arrays(
            self._images(), self.t, self.vtrans, self.vrot, self._gt, str(self.path)
        )
