"""ROS bags: ROS 1, ROS 2 sqlite3 and ROS 2 MCAP bags, with raw and compressed images,
written here with rosbags' writers, read back and run through ``torchratslam run``."""

import json
import math
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from torchratslam.cli import main
from torchratslam.errors import InputError
from torchratslam.readers.bags import RAW_ENCODINGS, BagReader, bag_kind, decode_image
from torchratslam.readers.datasets import open_data

KINDS = ("ros1", "sqlite3", "mcap")
N = 12
IMG_T = [100.0 + 0.5 * k for k in range(N)]
SMALL = """\
template_x_size: 32
template_y_size: 8
vt_match_threshold: 0.06
vt_shift_match: 4
pc_dim_xy: 15
pc_dim_th: 18
exp_loops: 5
"""


def _images(n=N, h=24, w=32):
    rng = np.random.default_rng(1)
    return [(rng.random((h, w, 3)) * 255).astype(np.uint8) for _ in range(n)]


def _raw_fields(bgr: np.ndarray, encoding: str) -> dict:
    h, w = bgr.shape[:2]
    if encoding == "mono8":
        data = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    elif encoding == "mono16":
        data = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.uint16) * 257
    elif encoding == "bgr8":
        data = bgr
    elif encoding == "rgb8":
        data = bgr[:, :, ::-1]
    elif encoding.startswith("bayer_"):
        data = _mosaic(bgr, encoding[6:10])
    else:
        raise AssertionError(encoding)
    data = np.ascontiguousarray(data)
    return dict(
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=data.strides[0],
        data=data.view(np.uint8).ravel(),
    )


def _mosaic(bgr: np.ndarray, pattern: str) -> np.ndarray:
    """A Bayer mosaic by hand: ``pattern`` names the colours of the 2x2 cell row by row."""
    out = np.empty(bgr.shape[:2], np.uint8)
    chan = {"r": 2, "g": 1, "b": 0}
    for k, c in enumerate(pattern):
        dy, dx = divmod(k, 2)
        out[dy::2, dx::2] = bgr[dy::2, dx::2, chan[c]]
    return out


def write_bag(path: Path, kind: str, *, encoding: str | None, image_topic="/cam", odom="/odom"):
    """A small bag: N images at 2 Hz, odometry at 4 Hz (0.3 m/s, 0.2 rad/s), ground truth.

    ``encoding`` None writes PNG CompressedImages, else raw Images of that encoding."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    V3, Pt, Q = (
        T["geometry_msgs/msg/Vector3"],
        T["geometry_msgs/msg/Point"],
        T["geometry_msgs/msg/Quaternion"],
    )
    Pose, PoseWC = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/PoseWithCovariance"]
    Twist, TwistWC = T["geometry_msgs/msg/Twist"], T["geometry_msgs/msg/TwistWithCovariance"]
    Odometry, PoseStamped = T["nav_msgs/msg/Odometry"], T["geometry_msgs/msg/PoseStamped"]
    CImage, Image = T["sensor_msgs/msg/CompressedImage"], T["sensor_msgs/msg/Image"]

    def header(t):
        sec = int(t)
        stamp = Time(sec=sec, nanosec=round((t - sec) * 1e9))
        if kind == "ros1":
            return Header(seq=0, stamp=stamp, frame_id="x")
        return Header(stamp=stamp, frame_id="x")

    def ser(msg, typ):
        return ts.serialize_ros1(msg, typ) if kind == "ros1" else ts.serialize_cdr(msg, typ)

    imgs = _images()
    ident = Q(x=0.0, y=0.0, z=0.0, w=1.0)
    image_type = (CImage if encoding is None else Image).__msgtype__
    events = []
    for i in range(4 * N):
        t = IMG_T[0] + 0.125 * i
        pose = PoseWC(
            pose=Pose(position=Pt(x=0.0, y=0.0, z=0.0), orientation=ident), covariance=np.zeros(36)
        )
        twist = TwistWC(
            twist=Twist(linear=V3(x=0.3, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.2)),
            covariance=np.zeros(36),
        )
        msg = Odometry(header=header(t), child_frame_id="b", pose=pose, twist=twist)
        events.append((t, "odom", ser(msg, Odometry.__msgtype__)))
    for t, img in zip(IMG_T, imgs):
        if encoding is None:
            _, buf = cv2.imencode(".png", img)
            msg = CImage(header=header(t), format="png", data=buf.ravel())
        else:
            msg = Image(header=header(t), **_raw_fields(img, encoding))
        events.append((t, "image", ser(msg, image_type)))
        q = Q(x=0.0, y=0.0, z=math.sin(0.1 * t / 2), w=math.cos(0.1 * t / 2))
        g = PoseStamped(header=header(t), pose=Pose(position=Pt(x=t, y=1.0, z=0.0), orientation=q))
        events.append((t, "gt", ser(g, PoseStamped.__msgtype__)))
    topics = {
        "odom": (odom, Odometry),
        "image": (image_topic, CImage if encoding is None else Image),
        "gt": ("/overhead/pose", PoseStamped),
    }
    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.SQLITE3 if kind == "sqlite3" else StoragePlugin.MCAP
        writer = Writer(path, version=8, storage_plugin=plugin)
    with writer as w:
        conns = {
            k: w.add_connection(tp, typ.__msgtype__, typestore=ts)
            for k, (tp, typ) in topics.items()
        }
        for t, k, raw in sorted(events, key=lambda e: e[0]):
            w.write(conns[k], int(t * 1e9), raw)
    return imgs


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("encoding", [None, "mono8", "bgr8"])
def test_every_bag_kind_reads_images_odometry_and_groundtruth(tmp_path, kind, encoding):
    path = tmp_path / ("b.bag" if kind == "ros1" else "b2")
    imgs = write_bag(path, kind, encoding=encoding)
    assert bag_kind(path) == ("ros1" if kind == "ros1" else "ros2")
    r = open_data(path, image_topic="/cam", odom_topic="/odom")
    assert isinstance(r, BagReader) and len(r) == N and r.has_odometry
    frames = list(r)
    for f, img in zip(frames, imgs):
        assert np.array_equal(f.image, cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
    assert [f.t for f in frames] == pytest.approx(IMG_T)
    assert [f.vtrans for f in frames] == pytest.approx([0.0] + [0.3] * (N - 1))
    assert [f.vrot for f in frames] == pytest.approx([0.0] + [0.2] * (N - 1))
    assert frames[3].pose == pytest.approx(
        (IMG_T[3], 1.0, math.remainder(0.1 * IMG_T[3], math.tau))
    )
    color = BagReader(path, image_topic="/cam", odom_topic="/odom", color=True)
    first = next(iter(color))
    want = (
        imgs[0]
        if encoding != "mono8"
        else cv2.cvtColor(cv2.cvtColor(imgs[0], cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)
    )
    assert np.array_equal(first.image, want)


def test_a_ros2_storage_file_opens_its_bag(tmp_path):
    write_bag(tmp_path / "b2", "mcap", encoding=None)
    (f,) = list((tmp_path / "b2").glob("*.mcap"))
    r = open_data(f, image_topic="/cam", odom_topic="/odom")
    assert r.kind == "ros2" and r.path == tmp_path / "b2" and len(r) == N
    with pytest.raises(InputError, match="no image topic '/nope'"):
        open_data(tmp_path / "b2", image_topic="/nope")
    (tmp_path / "lonely.db3").write_bytes(b"x")
    with pytest.raises(InputError, match=r"metadata\.yaml"):
        open_data(tmp_path / "lonely.db3")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "metadata.yaml").write_text("rubbish: [")
    with pytest.raises(InputError, match="cannot be read as a ROS 2 bag"):
        open_data(tmp_path / "bad")


def _msg(bgr, encoding, pad=0):
    f = _raw_fields(bgr, encoding)
    if pad:
        rows = f["data"].reshape(f["height"], -1)
        rows = np.concatenate([rows, np.full((f["height"], pad), 7, np.uint8)], axis=1)
        f["data"], f["step"] = rows.ravel(), rows.shape[1]
    return SimpleNamespace(**f)


def test_raw_encodings_decode_like_the_definitions():
    rng = np.random.default_rng(3)
    bgr = (rng.random((6, 8, 3)) * 255).astype(np.uint8)
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    t = "sensor_msgs/msg/Image"
    for enc in ("bgr8", "rgb8"):
        for pad in (0, 5):  # rows padded beyond width (step > width * 3)
            assert np.array_equal(decode_image(_msg(bgr, enc, pad), t, True), bgr)
            assert np.array_equal(decode_image(_msg(bgr, enc, pad), t, False), grey)
    assert np.array_equal(decode_image(_msg(bgr, "mono8", 3), t), grey)
    assert np.array_equal(decode_image(_msg(bgr, "mono16"), t), grey)  # v*257 -> v
    ro = _msg(bgr, "mono8")
    ro.data = bytes(ro.data)  # messages hold read-only bytes: the image must be writable
    assert decode_image(ro, t).flags.writeable
    for enc in ("32FC1", "nv12", "weird"):
        m = _msg(bgr, "mono8")
        m.encoding = enc
        with pytest.raises(InputError, match="not supported"):
            decode_image(m, t)
    short = _msg(bgr, "bgr8")
    short.data = short.data[:50]
    with pytest.raises(InputError, match="shorter"):
        decode_image(short, t)
    bad = SimpleNamespace(format="jpeg", data=np.frombuffer(b"not a jpeg", np.uint8))
    with pytest.raises(InputError, match="could not be decoded"):
        decode_image(bad, "sensor_msgs/msg/CompressedImage")
    assert {"mono8", "mono16", "rgb8", "bgr8", "bayer_rggb8"} <= set(RAW_ENCODINGS)


@pytest.mark.parametrize("pattern", ["rggb", "bggr", "gbrg", "grbg"])
def test_bayer_patterns_demosaic_to_the_right_colour(pattern):
    # a flat colour, mosaicked by hand: inside the image every pixel must come back as it
    colour = np.array([40, 120, 220], np.uint8)  # B, G, R all different
    bgr = np.broadcast_to(colour, (8, 10, 3)).copy()
    for depth in (8, 16):
        m = _msg(bgr, f"bayer_{pattern}8")
        if depth == 16:
            m.encoding = f"bayer_{pattern}16"
            m.data = (m.data.astype(np.uint16) * 257).view(np.uint8)
            m.step *= 2
        out = decode_image(m, "sensor_msgs/msg/Image", True)
        assert np.abs(out[2:-2, 2:-2].astype(int) - colour).max() <= 1, (pattern, depth)
        g = decode_image(m, "sensor_msgs/msg/Image", False)
        want = cv2.cvtColor(colour.reshape(1, 1, 3), cv2.COLOR_BGR2GRAY)[0, 0]
        assert np.abs(g[2:-2, 2:-2].astype(int) - int(want)).max() <= 1, (pattern, depth)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("encoding", [None, "rgb8"])
def test_torchratslam_run_maps_every_bag_kind(tmp_path, kind, encoding):
    path = tmp_path / ("b.bag" if kind == "ros1" else "b2")
    write_bag(path, kind, encoding=encoding, image_topic="/camera/image", odom="/wheel/odom")
    cfg = tmp_path / "small.yaml"
    cfg.write_text(SMALL)
    out = tmp_path / "out"
    args = ["run", "--config", str(cfg), "--data", str(path), "--out", str(out), "--no-progress"]
    args += ["--image-topic", "/camera/image", "--odom-topic", "/wheel/odom", "--tum"]
    assert main(args) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == N and m["odometry"] == "given" and m["experiences"] >= 1
    assert "ate_rmse_m" in m and (out / "tum_groundtruth.txt").is_file()
    traj = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert traj[:, 1] == pytest.approx(IMG_T)
