"""The rerun viewer: ``run --rerun-save`` records every stream, read back from the .rrd
file and compared with the run's own outputs."""

import json

import numpy as np
import pytest

rr = pytest.importorskip("rerun", reason="rerun-sdk (the 'viewer' extra) is not installed")

from torchratslam.cli import main  # noqa: E402
from torchratslam.viz.rerun_viewer import ENTITIES  # noqa: E402

SMALL = """\
template_x_size: 32
template_y_size: 8
vt_panoramic: 1
vt_step_match: 1
vt_match_threshold: 0.06
pc_dim_xy: 15
pc_dim_th: 18
pc_cell_x_size: 0.5
pc_vt_inject_energy: 0.1
exp_loops: 5
"""
SIM = "sim:loop?laps=1&frames=40"
N = 40


def _read(path):
    """``{entity: {column: [values in frame order]}}`` and each entity's frame numbers."""
    chunks = rr.chunk.RrdReader(str(path)).stream().to_chunks()
    data: dict = {}
    for c in chunks:
        rb = c.to_record_batch()
        if "frame" not in rb.schema.names:
            continue
        ent = data.setdefault(c.entity_path.lstrip("/"), {})
        cols = rb.to_pydict()
        for name, values in cols.items():
            ent.setdefault(name, []).extend(values)
    for ent in data.values():  # sort every column by frame
        order = np.argsort(np.asarray(ent["frame"]), kind="stable")
        for name in ent:
            ent[name] = [ent[name][i] for i in order]
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
    from torchratslam.maps.state import load_state

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
