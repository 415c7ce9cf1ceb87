"""The default behaviour ("openratslam") against golden traces of OpenRatSLAM's C++.

``tests/data/openratslam/<name>/`` holds what OpenRatSLAM's own classes (compiled,
unmodified, driven as its ROS nodes drive them) did on three of the project's simulated
datasets: per frame the template id, relative angle, action, current experience and
pose-cell centre, then the final experiences and links (see its README). The frames are
re-rendered here by the simulator (their pixels are checked against the CRC-32 of the
images the C++ read) and fed with the odometry rows the C++ read.

Asserted: in float64 the same template id and angle on every frame, the same action
(kind, source, destination) on every frame, and final experience poses within 1e-9 m
(and 1e-9 rad) of the C++'s; in float32 the same actions up to a frame (if any) whose
decision lies within float32's rounding. The experience map alone is also replayed on
the C++'s actions (independent of the pose cells).
"""

from __future__ import annotations

import csv
import functools
import json
import math
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch

from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.messages import Action, ActionKind
from torchratslam.config import load_config
from torchratslam.messages import Frame
from torchratslam.pipeline import RatSLAM

TRACES = Path(__file__).resolve().parent.parent / "data" / "openratslam"
NAMES = ("loop", "turns", "templates")


@functools.cache
def trace(name: str) -> dict:
    d = TRACES / name
    with open(d / "frames.csv") as f:
        rows = list(csv.DictReader(f))
    cols = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    ints = ("frame", "crc32", "vt_id", "action", "src_exp_id", "current_exp_id", "em_current_id")
    for k in ints:
        cols[k] = cols[k].astype(np.int64)
    exps = np.loadtxt(d / "experiences.csv", delimiter=",", skiprows=1, ndmin=2)
    links = np.loadtxt(d / "links.csv", delimiter=",", skiprows=1, ndmin=2)
    meta = json.loads((d / "meta.json").read_text())
    return {"f": cols, "exps": exps, "links": links, "meta": meta, "config": d / "config.txt"}


@functools.cache
def images(spec: str, n: int) -> tuple[np.ndarray, ...]:
    from torchratslam.sim import open_sim

    session = open_sim(spec)
    return tuple(session.render(k) for k in range(n))


def frames(name: str) -> list[Frame]:
    tr = trace(name)
    f = tr["f"]
    n = len(f["frame"])
    imgs = images(tr["meta"]["spec"], n)
    crc = [zlib.crc32(np.ascontiguousarray(im).tobytes()) for im in imgs]
    assert crc == f["crc32"].tolist(), f"{name}: the simulator no longer renders these frames"
    t = f["t"]
    return [
        Frame(
            k,
            float(t[k]),
            imgs[k],
            vtrans=float(f["vtrans"][k]),
            vrot=float(f["vrot"][k]),
            dt=0.0 if k == 0 else float(t[k] - t[k - 1]),
        )
        for k in range(n)
    ]


def run(name: str, dtype: torch.dtype) -> tuple[RatSLAM, np.ndarray]:
    torch.set_num_threads(1)
    slam = RatSLAM(load_config(trace(name)["config"]), dtype=dtype)
    rows: list[tuple] = []

    def cb(r):
        a = r.action
        rows.append((r.view.template_id, r.view.relative_rad, int(a.kind), a.src_id, a.dest_id))

    slam.run(frames(name), progress=False, callback=cb)
    return slam, np.array(rows, dtype=np.float64)


def assert_map_equal(poses: np.ndarray, want: np.ndarray, atol: float = 1e-9) -> None:
    assert poses.shape == want[:, 1:4].shape
    dxy = np.hypot(poses[:, 0] - want[:, 1], poses[:, 1] - want[:, 2])
    dth = np.abs((poses[:, 2] - want[:, 3] + math.pi) % (2 * math.pi) - math.pi)
    assert dxy.max() < atol and dth.max() < atol, (dxy.max(), dth.max())


def test_the_traces_are_what_the_readme_says():
    for name in NAMES:
        tr = trace(name)
        f = tr["f"]
        act = f["action"]
        assert len(tr["exps"]) == tr["meta"]["experiences"] == (act == 1).sum()
        assert len(tr["links"]) == tr["meta"]["links"]
        assert act[0] == 0 and f["frame"].tolist() == list(range(len(act)))
    assert (trace("loop")["f"]["action"] == 2).sum() > 100  # many loop closures
    assert trace("templates")["meta"]["templates"] > 500
    turns = trace("turns")["f"]
    wraps = [np.sum(np.abs(np.diff(turns[c])) > n / 2) for c, n in (("pc_x", 11), ("pc_th", 36))]
    assert min(wraps) > 5  # the packet crosses the wrap in x and theta
    rot = np.abs(turns["vrot"][1:] * np.diff(turns["t"]))
    assert rot.max() > math.radians(45)  # fast turns


@pytest.mark.parametrize("name", NAMES)
def test_the_experience_map_replays_the_cpps_actions(name):
    """The experience map alone, on the C++'s own action sequence and odometry."""
    tr = trace(name)
    f = tr["f"]
    em = ExperienceMap(load_config(tr["config"]).experience_map)
    t = f["t"]
    for k in range(len(t)):
        if k > 0:  # the first odometry message is skipped
            em.on_odometry(float(f["vtrans"][k]), float(f["vrot"][k]), float(t[k] - t[k - 1]))
        kind = int(f["action"][k])
        if kind:
            em.apply(
                Action(
                    ActionKind(kind),
                    dest_id=int(f["current_exp_id"][k]),
                    src_id=int(f["src_exp_id"][k]),
                    relative_rad=float(f["rel_rad"][k]),
                )
            )
            em.iterate()
        assert em.current_id == f["em_current_id"][k]
    assert_map_equal(np.asarray(em.poses), tr["exps"])
    lk = em.links()
    np.testing.assert_array_equal(np.stack([lk["src"], lk["dst"]], 1), tr["links"][:, :2])
    got = np.stack([lk["d"], lk["heading"], lk["facing"]], 1)
    np.testing.assert_allclose(got, tr["links"][:, 2:5], rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_the_reference_behaviour_reproduces_the_trace_in_float64(name):
    tr = trace(name)
    f = tr["f"]
    slam, got = run(name, torch.float64)
    np.testing.assert_array_equal(got[:, 0], f["vt_id"])
    np.testing.assert_allclose(got[:, 1], f["vt_rad"], rtol=0, atol=1e-12)
    bad = np.nonzero(got[:, 2] != f["action"])[0]
    assert bad.size == 0, f"actions differ on {bad.size} frames, first {bad[:5].tolist()}"
    act = f["action"] != 0
    first = np.argmax(act)  # the first CREATE has no source: -1 here, the C++'s initial 0
    assert got[first, 3] == -1 and f["src_exp_id"][first] == 0
    act[first] = False
    np.testing.assert_array_equal(got[act, 3], f["src_exp_id"][act])
    np.testing.assert_array_equal(got[act, 4], f["current_exp_id"][act])
    assert_map_equal(np.asarray(slam.experience_map.poses), tr["exps"])
    assert slam.trajectory()[:, 2].astype(int).tolist() == f["em_current_id"].tolist()


def _torus(a: np.ndarray, b: np.ndarray, dims: tuple[int, int, int]) -> np.ndarray:
    """Per axis the shorter way round the ring, then Euclidean (written out here)."""
    d = np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64)) % np.array(dims)
    d = np.minimum(d, np.array(dims) - d)
    return np.sqrt((d * d).sum(-1))


@pytest.mark.parametrize("name", NAMES)
def test_float32_takes_the_cpps_actions_but_where_its_rounding_reaches_a_decision(name):
    """float32 and float64 stepped side by side: the same template and action on every
    frame, up to a frame (if any) whose double-precision decision lies within the float32
    rounding: some experience's distance from the packet within ``2 * delta`` of
    ``exp_delta_pc_threshold``, or two experiences of the template within ``2 * delta`` of
    each other, ``delta`` being how far float32 has carried the centre and the
    experiences' cells (the distance is 1-Lipschitz in both). The float64 run is the
    C++'s (the test above)."""
    f = trace(name)["f"]
    cfg = load_config(trace(name)["config"])
    torch.set_num_threads(1)
    s64, s32 = RatSLAM(cfg, dtype=torch.float64), RatSLAM(cfg, dtype=torch.float32)
    p = cfg.pose_cells
    dims = (p.pc_dim_xy, p.pc_dim_xy, p.pc_dim_th)
    for fr in frames(name):
        r64, r32 = s64.step_frame(fr), s32.step_frame(fr)
        assert r32.view.template_id == r64.view.template_id
        same = (r32.action.kind, r32.action.src_id, r32.action.dest_id) == (
            r64.action.kind,
            r64.action.src_id,
            r64.action.dest_id,
        )
        if same:
            continue
        pc64, pc32 = s64.pose_cells, s32.pose_cells
        delta = float(_torus(r32.pc, r64.pc, dims)) + float(
            _torus(pc32.exp_pc[: len(pc64.exp_pc)], pc64.exp_pc, dims).max(initial=0.0)
        )
        th = (r64.pc[2] - pc64.vt_delta_pc_th) % dims[2]
        d = _torus(pc64.exp_pc, np.array([r64.pc[0], r64.pc[1], th]), dims)
        mine = np.sort(d[pc64.exp_template == r64.view.template_id])
        margins = [np.abs(d - p.exp_delta_pc_threshold).min(), np.diff(mine).min(initial=np.inf)]
        assert min(margins) <= 2 * delta + 1e-9, (fr.index, margins, delta)
        assert delta > 0  # the two runs did part by rounding
        break
    else:
        assert (f["action"] != 0).sum() > 10  # the trace did exercise the actions
