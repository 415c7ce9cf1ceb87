"""Readers: each reads a small file the test writes, and fails clearly on bad input."""

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.readers.bags import BagReader
from torchratslam.readers.datasets import (
    DirectoryReader,
    VideoReader,
    open_data,
    read_odometry_csv,
)

N = 6


def _images(n=N, h=12, w=20):
    rng = np.random.default_rng(0)
    return [(rng.random((h, w)) * 255).astype(np.uint8) for _ in range(n)]


def _write_dir(root: Path, n=N, odo_rows=None, gt=True):
    (root / "frames").mkdir(parents=True)
    imgs = _images(n)
    for k, img in enumerate(imgs):
        cv2.imwrite(str(root / "frames" / f"{k:05d}.png"), img)
    rows = odo_rows if odo_rows is not None else [(0.1 * k, 0.5 + k, -0.1 * k) for k in range(n)]
    lines = ["t,vtrans,vrot,extra"] + [f"{t},{v},{w},99" for t, v, w in rows]
    (root / "odometry.csv").write_text("\n".join(lines) + "\n")
    if gt:
        g = ["t,x,y,theta"] + [f"{0.1 * k},{k},{2 * k},0.1" for k in range(n)]
        (root / "groundtruth.csv").write_text("\n".join(g) + "\n")
    return imgs


def test_directory_reader_reads_frames_odometry_and_groundtruth(tmp_path):
    imgs = _write_dir(tmp_path / "d")
    r = open_data(tmp_path / "d")
    assert isinstance(r, DirectoryReader) and len(r) == N and r.has_odometry
    frames = list(r)
    assert [f.index for f in frames] == list(range(N))
    for k, f in enumerate(frames):
        assert np.array_equal(f.image, imgs[k])  # PNG is lossless, sorted by name
        assert f.t == pytest.approx(0.1 * k) and f.vtrans == pytest.approx(0.5 + k)
        assert f.vrot == pytest.approx(-0.1 * k)
        assert f.dt == pytest.approx(0.0 if k == 0 else 0.1)
        assert f.pose == pytest.approx((k, 2 * k, 0.1))
    assert r.groundtruth().shape == (N, 4)


def test_directory_reader_errors(tmp_path):
    with pytest.raises(InputError, match="not found"):
        open_data(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="frames/"):
        open_data(tmp_path / "empty")
    _write_dir(tmp_path / "count", odo_rows=[(0.1 * k, 1, 0) for k in range(N - 1)])
    with pytest.raises(InputError, match="counts must match"):
        open_data(tmp_path / "count")
    _write_dir(tmp_path / "mono", odo_rows=[(0.1 * (k % 3), 1, 0) for k in range(N)])
    with pytest.raises(InputError, match="increase strictly"):
        open_data(tmp_path / "mono")
    _write_dir(
        tmp_path / "nan", odo_rows=[(0.1 * k, float("nan") if k == 2 else 1, 0) for k in range(N)]
    )
    with pytest.raises(InputError, match=r"line 4: NaN"):
        open_data(tmp_path / "nan")
    _write_dir(tmp_path / "bad")
    (tmp_path / "bad" / "frames" / "00002.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match=r"00002\.png: unreadable image"):
        list(open_data(tmp_path / "bad"))
    p = tmp_path / "hdr.csv"
    p.write_text("time,v,w\n0,1,2\n")
    with pytest.raises(InputError, match="lacks column"):
        read_odometry_csv(p)


def test_directory_without_odometry_needs_visual_odometry(tmp_path):
    _write_dir(tmp_path / "d")
    (tmp_path / "d" / "odometry.csv").unlink()
    r = DirectoryReader(tmp_path / "d", rate=4.0)
    assert not r.has_odometry
    assert [f.t for f in r] == pytest.approx([k / 4.0 for k in range(N)])


def test_video_reader_with_odometry_csv_and_without(tmp_path):
    path = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (32, 24), False)
    frames = [np.full((24, 32), 20 * k, dtype=np.uint8) for k in range(N)]
    for f in frames:
        writer.write(f)
    writer.release()
    odo = tmp_path / "odo.csv"
    odo.write_text("t,vtrans,vrot\n" + "".join(f"{0.2 * k},{k},0.5\n" for k in range(N)))
    r = open_data(path, odometry=odo)
    assert isinstance(r, VideoReader) and r.has_odometry
    got = list(r)
    assert len(got) == N and got[3].vtrans == 3.0 and got[3].dt == pytest.approx(0.2)
    for k, f in enumerate(got):  # lossy codec: brightness approximately preserved
        assert f.image.shape == (24, 32) and abs(float(f.image.mean()) - 20 * k) < 4
    r2 = VideoReader(path)
    assert not r2.has_odometry and [f.t for f in r2] == pytest.approx([k / 5.0 for k in range(N)])
    short = tmp_path / "short.csv"
    short.write_text("t,vtrans,vrot\n0,1,0\n1,1,0\n")
    with pytest.raises(InputError, match="counts must match"):
        list(VideoReader(path, odometry=short))
    (tmp_path / "junk.mp4").write_bytes(b"junk")
    with pytest.raises(InputError, match="cannot be opened"):
        open_data(tmp_path / "junk.mp4")


def _write_bag(path: Path, *, compressed: bool, image_topic: str, odom_topic: str):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Odometry, Twist, TwistWC = (
        T["nav_msgs/msg/Odometry"],
        T["geometry_msgs/msg/Twist"],
        T["geometry_msgs/msg/TwistWithCovariance"],
    )
    Vector3, Pose, PoseWC = (
        T["geometry_msgs/msg/Vector3"],
        T["geometry_msgs/msg/Pose"],
        T["geometry_msgs/msg/PoseWithCovariance"],
    )
    Point, Quat, PoseStamped = (
        T["geometry_msgs/msg/Point"],
        T["geometry_msgs/msg/Quaternion"],
        T["geometry_msgs/msg/PoseStamped"],
    )
    CImage, Image = T["sensor_msgs/msg/CompressedImage"], T["sensor_msgs/msg/Image"]

    def header(t, seq=0):
        sec = int(t)
        return Header(seq=seq, stamp=Time(sec=sec, nanosec=round((t - sec) * 1e9)), frame_id="x")

    imgs = _images(4, 10, 16)
    img_t = [10.0, 10.5, 11.0, 11.5]
    # odometry at 4 Hz: 0.2 m/s then 0.4 m/s; turn rate 0.1 rad/s throughout
    odo_t = [10.0 + 0.25 * i for i in range(8)]
    odo_v = [0.2 if t <= 10.75 else 0.4 for t in odo_t]
    with Writer(path) as w:
        ci = w.add_connection(
            image_topic, (CImage if compressed else Image).__msgtype__, typestore=ts
        )
        co = w.add_connection(odom_topic, Odometry.__msgtype__, typestore=ts)
        cg = w.add_connection("/overhead/pose", PoseStamped.__msgtype__, typestore=ts)
        events = []
        for t, v in zip(odo_t, odo_v):
            pose = PoseWC(
                pose=Pose(
                    position=Point(x=0.0, y=0.0, z=0.0),
                    orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0),
                ),
                covariance=np.zeros(36),
            )
            twist = TwistWC(
                twist=Twist(
                    linear=Vector3(x=v, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.1)
                ),
                covariance=np.zeros(36),
            )
            msg = Odometry(header=header(t), child_frame_id="b", pose=pose, twist=twist)
            events.append((t, co, ts.serialize_ros1(msg, Odometry.__msgtype__)))
        for t, img in zip(img_t, imgs):
            if compressed:
                _, buf = cv2.imencode(".png", img)
                msg = CImage(header=header(t), format="png", data=buf.ravel())
                events.append((t, ci, ts.serialize_ros1(msg, CImage.__msgtype__)))
            else:
                msg = Image(
                    header=header(t),
                    height=10,
                    width=16,
                    encoding="mono8",
                    is_bigendian=0,
                    step=16,
                    data=img.ravel(),
                )
                events.append((t, ci, ts.serialize_ros1(msg, Image.__msgtype__)))
            yaw = 0.3
            q = Quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
            gmsg = PoseStamped(
                header=header(t), pose=Pose(position=Point(x=t, y=1.0, z=0.0), orientation=q)
            )
            events.append((t, cg, ts.serialize_ros1(gmsg, PoseStamped.__msgtype__)))
        for t, conn, raw in sorted(events, key=lambda e: e[0]):
            w.write(conn, int(t * 1e9), raw)
    return imgs, img_t


@pytest.mark.parametrize("compressed", [True, False])
def test_bag_reader_reads_images_and_integrates_odometry(tmp_path, compressed):
    path = tmp_path / "tiny.bag"
    imgs, img_t = _write_bag(
        path,
        compressed=compressed,
        image_topic="/irat_red/camera/image/compressed" if compressed else "/cam/image",
        odom_topic="/irat_red/odom",
    )
    r = open_data(path) if compressed else BagReader(path, image_topic="/cam/image")
    assert len(r) == 4 and r.has_odometry
    frames = list(r)
    for k, f in enumerate(frames):
        assert np.array_equal(f.image, imgs[k])
        assert f.t == pytest.approx(img_t[k])
    # odometry messages hold their velocity over the interval ending at their stamp:
    # (10.0, 10.5]: 0.2 m/s; (10.5, 11.0]: 0.2 until 10.75 then 0.4 -> 0.3; (11.0, 11.5]: 0.4
    assert [f.vtrans for f in frames] == pytest.approx([0.0, 0.2, 0.3, 0.4])
    assert [f.vrot for f in frames[1:]] == pytest.approx([0.1] * 3)
    assert [f.dt for f in frames] == pytest.approx([0.0, 0.5, 0.5, 0.5])
    gt = r.groundtruth()
    assert gt.shape == (4, 4) and gt[:, 3] == pytest.approx([0.3] * 4)
    assert frames[2].pose == pytest.approx((11.0, 1.0, 0.3))


def test_bag_reader_errors(tmp_path):
    path = tmp_path / "tiny.bag"
    _write_bag(path, compressed=True, image_topic="/cam", odom_topic="/odom")
    with pytest.raises(InputError, match="no image topic '/irat_red"):
        open_data(path)
    r = BagReader(path, image_topic="/cam", odom_topic="/missing")
    assert not r.has_odometry
    (tmp_path / "bad.bag").write_bytes(b"#ROSBAG V2.0\nrubbish")
    with pytest.raises(InputError, match="cannot be read as a ROS 1 bag"):
        open_data(tmp_path / "bad.bag")
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(InputError, match="unknown kind"):
        open_data(tmp_path / "x.txt")


def test_raw_image_encodings_decode_to_grey_or_bgr():
    from types import SimpleNamespace

    from torchratslam.readers.bags import decode_image

    rng = np.random.default_rng(5)
    bgr = (rng.random((5, 7, 3)) * 255).astype(np.uint8)
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    padded = np.concatenate([bgr.reshape(5, 21), np.zeros((5, 3), np.uint8)], axis=1)  # step 24

    def msg(enc, data, step):
        return SimpleNamespace(encoding=enc, height=5, width=7, step=step, data=data.ravel())

    t = "sensor_msgs/msg/Image"
    assert np.array_equal(decode_image(msg("bgr8", padded, 24), t, True, "/c"), bgr)
    assert np.array_equal(decode_image(msg("bgr8", padded, 24), t, False, "/c"), grey)
    rgb = bgr[:, :, ::-1].reshape(5, 21)
    assert np.array_equal(decode_image(msg("rgb8", rgb, 21), t, True, "/c"), bgr)
    with pytest.raises(InputError, match="not supported"):
        decode_image(msg("32FC1", padded, 24), t, False, "/c")
    with pytest.raises(InputError, match="shorter"):
        decode_image(msg("mono8", padded[:2], 24), t, False, "/c")


# ------------------------------------------------------------------ rough input
def test_a_renamed_frame_is_a_gap_that_warns_and_is_kept(tmp_path, caplog):
    _write_dir(tmp_path / "d")
    assert open_data(tmp_path / "d").input_warnings == ()
    frames = tmp_path / "d" / "frames"
    (frames / "00002.png").rename(frames / "00009.png")  # counts still equal
    with caplog.at_level("WARNING", logger="torchratslam.readers"):
        r = open_data(tmp_path / "d")
    assert [f.name for f in r.files][-1] == "00009.png"  # read last: after 00005.png
    (msg,) = r.input_warnings
    assert "skip 2 (00001.png, then 00003.png)" in msg and "6..8 (00005.png, then 00009.png)" in msg
    assert str(frames) in msg and msg in caplog.text


@pytest.mark.parametrize(
    ("names", "problem"),
    [
        (["a_0.png", "a_5.png", "a_10.png", "a_15.png"], None),  # a regular step of 5
        (["cam2_0.png", "cam2_1.png", "cam2_2.png"], None),  # the varying number counts
        (["0.png", "5.png", "10.png", "20.png"], "skip 15 (10.png, then 20.png)"),
        (["1.png", "2.png", "2.jpg", "3.png"], "repeat or go back (2.png and 2.jpg)"),
        (["a_7.png", "b_1.png", "b_2.png", "b_3.png"], "repeat or go back (a_7.png and b_1.png)"),
        (["first.png", "second.png"], None),  # no numbers: nothing to check
    ],
)
def test_frame_numbering_against_a_brute_force_reading(names, problem):
    from torchratslam.readers.datasets import frame_numbering

    got = frame_numbering(names, "frames")
    assert (got == ()) == (problem is None)
    if problem is not None:
        assert any(problem in m for m in got), got


def test_an_odometry_csv_with_a_byte_order_mark_is_read(tmp_path):
    _write_dir(tmp_path / "d")
    odo = tmp_path / "d" / "odometry.csv"
    plain = read_odometry_csv(odo)
    odo.write_bytes(b"\xef\xbb\xbf" + odo.read_bytes())  # as spreadsheets save it
    for a, b in zip(read_odometry_csv(odo), plain, strict=True):
        assert np.array_equal(a, b)
    assert len(list(open_data(tmp_path / "d"))) == N


def test_a_frame_of_another_size_is_named(tmp_path):
    _write_dir(tmp_path / "d")
    odd = tmp_path / "d" / "frames" / "00003.png"
    cv2.imwrite(str(odd), np.zeros((6, 10), np.uint8))
    r = open_data(tmp_path / "d")
    with pytest.raises(InputError) as err:
        list(r)
    msg = str(err.value)
    assert msg.startswith(f"{odd}: 10 x 6 pixels, but 00000.png") and "20 x 12" in msg
    assert "LocalView" not in msg
