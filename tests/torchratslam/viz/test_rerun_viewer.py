"""The rerun viewer: ``run --rerun-save`` records every stream, read back from the .rrd
file and compared with the run's own outputs."""

import json
from pathlib import Path

import numpy as np
import pytest

rr = pytest.importorskip("rerun", reason="rerun-sdk (the 'viewer' extra) is not installed")

from torchratslam.cli import main  # noqa: E402
from torchratslam.viz.rerun_viewer import ENTITIES  # noqa: E402

SMALL = (Path(__file__).resolve().parents[2] / "data" / "small.yaml").read_text()
SIM = "sim:loop?laps=1&frames=40"
N = 40


def _read(path):
    """``{entity: {column: [values in frame order]}}`` (None where a row lacks a column)."""
    chunks = rr.chunk.RrdReader(str(path)).stream().to_chunks()
    rows: dict = {}
    for c in chunks:
        cols = c.to_record_batch().to_pydict()
        if "frame" not in cols:
            continue
        n = len(cols["frame"])
        rows.setdefault(c.entity_path.lstrip("/"), []).extend(
            {k: v[i] for k, v in cols.items()} for i in range(n)
        )
    data = {}
    for ent, rs in rows.items():
        rs.sort(key=lambda r: r["frame"])
        names = {k for r in rs for k in r}
        data[ent] = {k: [r.get(k) for r in rs] for k in names}
    return data


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    root = tmp_path_factory.mktemp("rerun")
    cfg = root / "small.yaml"
    cfg.write_text(SMALL)
    base = ["--config", str(cfg), "--data", SIM, "--no-progress"]
    assert main(["run", *base, "--out", str(root / "s1")]) == 0
    # the same tour again on the stored map: it merges at once (scenario i)
    rrd = root / "again.rrd"
    args = ["run", *base, "--out", str(root / "s2"), "--load", str(root / "s1" / "state")]
    assert main([*args, "--rerun-save", str(rrd)]) == 0
    return root, rrd


def test_every_stream_is_recorded_and_matches_the_run(recorded):
    root, rrd = recorded
    data = _read(rrd)
    for ent in ENTITIES:
        if ent == "timings":
            for m in ("odometry", "local_view", "pose_cells", "experience_map"):
                assert f"timings/{m}" in data, m
        else:
            assert ent in data, ent
    # one row per frame for the per-frame streams, on the frame timeline 0..N-1
    for ent in (
        "camera/image",
        "local_view/template",
        "local_view/offset",
        "pose_cells/centre",
        "map/current",
        "timings/pose_cells",
    ):
        assert data[ent]["frame"] == list(range(N)), ent
    # the packet centre is the run's pose-cell log; the timings its per-frame ms
    from torchratslam.maps.native import load_state

    metrics = json.loads((root / "s2" / "metrics.json").read_text())
    assert metrics["merges"] and metrics["merges"][0]["frame"] == 0
    centres = np.array([p[0] for p in data["pose_cells/centre"]["Points3D:positions"]])
    assert centres.shape == (N, 3) and np.all((centres >= 0) & (centres < [15, 15, 18]))
    # the final logged map is the saved map
    state = load_state(root / "s2" / "state")
    last = np.asarray(data["map/experiences"]["Points2D:positions"][-1])
    np.testing.assert_allclose(last, state.exp_pose[:, :2], atol=1e-5)
    strips = data["map/links"]["LineStrips2D:strips"][-1]
    assert len(strips) == state.n_links
    # the timings series are the run's per-frame times (same mean as metrics.json)
    for m in ("local_view", "pose_cells", "experience_map"):
        series = np.concatenate(data[f"timings/{m}"]["Scalars:scalars"])
        assert series.size == N
        assert series.mean() == pytest.approx(metrics["ms_per_frame"][m]["mean_ms"], rel=1e-9)
    # the merge is marked with a label, and logged as an event
    labels = data["map/merges"]["Points2D:labels"][-1]
    assert len(labels) == len(metrics["merges"]) and "merge with map 0" in labels[0]
    assert any("merge" in str(t) for t in data["events"]["TextLog:text"])
    # activity points lie inside the pose-cell network
    pts = np.asarray(data["pose_cells/activity"]["Points3D:positions"][-1])
    assert len(pts) > 0 and pts.min() >= 0 and pts[:, :2].max() < 15 and pts[:, 2].max() < 18
    # camera images and templates carry pixels
    assert all(len(b[0]) > 0 for b in data["camera/image"]["Image:buffer"])
    assert all(len(b[0]) == 32 * 8 for b in data["local_view/template"]["Image:buffer"])


def test_missing_extra_is_one_clear_error(monkeypatch):
    import builtins

    from torchratslam.errors import ConfigError
    from torchratslam.viz import rerun_viewer

    real = builtins.__import__

    def fake(name, *a, **k):
        if name == "rerun" or name.startswith("rerun."):
            raise ImportError("no rerun")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(ConfigError, match=r"torchratslam\[viewer\]"):
        rerun_viewer.import_rerun()


def test_multisession_sessions_continue_one_timeline(tmp_path):
    from torchratslam.config import load_config
    from torchratslam.experiments.multisession_tour import run_sessions
    from torchratslam.readers.datasets import open_data
    from torchratslam.viz.rerun_viewer import RerunObserver

    cfg = tmp_path / "small.yaml"
    cfg.write_text(SMALL)
    rrd = tmp_path / "ms.rrd"
    obs = RerunObserver(None, save=rrd)
    sessions = [open_data(SIM), open_data(SIM)]
    for k, s in enumerate(sessions):
        s.name = f"s{k + 1}"
    res = run_sessions(load_config(cfg), sessions, max_frames=20, observer=obs)
    obs.close()
    assert len(res["merges"]) == 1  # the second session starts on the first one's map
    data = _read(rrd)
    assert data["camera/image"]["frame"] == list(range(40))
    texts = [t[0] for t in data["events"]["TextLog:text"]]
    at = res["merges"][0]["frame"]  # 0, or 1 in OpenRatSLAM's behaviour (frame 0 not stepped)
    assert texts == ["session s1 starts", "session s2 starts", f"s2 merge with map 0 at frame {at}"]
    assert data["events"]["frame"] == [0, 20, 20 + at]  # session 2 starts at timeline frame 20
    assert data["map/merges"]["frame"] == [20 + at]
