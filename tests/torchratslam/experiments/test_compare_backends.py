"""compare-backends takes the project's own ground truth (``groundtruth.csv``, as
``run`` and ``simulate`` write it) for a saved map: each experience at its creation
time, SE(2)-aligned, the count said; a graph file without creation times is refused in
one line."""

from __future__ import annotations

import math

import numpy as np

from torchratslam.cli import main
from torchratslam.experiments.compare_backends import run_comparison
from torchratslam.maps.io import load_state


def _se2_ate(p, q):
    pc, qc = p - p.mean(0), q - q.mean(0)
    th = math.atan2(
        float(np.sum(pc[:, 0] * qc[:, 1] - pc[:, 1] * qc[:, 0])),
        float(np.sum(pc[:, 0] * qc[:, 0] + pc[:, 1] * qc[:, 1])),
    )
    c, s = math.cos(th), math.sin(th)
    moved = pc @ np.array([[c, -s], [s, c]]).T + q.mean(0)
    return float(np.sqrt(np.mean(np.sum((moved - q) ** 2, axis=1))))


def test_the_projects_own_groundtruth_csv_is_accepted(small_run, tmp_path, capsys):
    from torchratslam.sim import open_sim, write_dataset

    data = write_dataset(open_sim("sim:loop?laps=1&frames=40"), tmp_path / "ds")
    csv = data / "groundtruth.csv"
    assert csv.read_text().startswith("t,x,y,theta")
    state = load_state(small_run.out)
    capsys.readouterr()
    argv = ["compare-backends", "--map", str(small_run.out / "state"), "--backends", "alpha"]
    assert main([*argv, "--groundtruth", str(csv)]) == 0
    out = capsys.readouterr().out
    n = state.n_experiences
    assert f"ATE: SE(2)-aligned, over {n} of {n} nodes with ground truth" in out
    _, rows = run_comparison(small_run.out / "state", ("alpha",), groundtruth=csv)
    gt = np.loadtxt(csv, delimiter=",", skiprows=1)
    truth = np.column_stack([np.interp(state.exp_t, gt[:, 0], gt[:, k]) for k in (1, 2)])
    want = _se2_ate(np.asarray(rows[0]["poses"])[:, :2], truth)
    assert abs(rows[0]["ate_rmse_m"] - want) < 1e-9 and rows[0]["ate_poses"] == n
    # part of the times: only the experiences inside count, none clamped
    cut = float(np.quantile(state.exp_t, 0.5))
    part = tmp_path / "part.csv"
    np.savetxt(part, gt[gt[:, 0] <= cut], delimiter=",", header="t,x,y,theta", comments="")
    _, rows = run_comparison(small_run.out / "state", ("alpha",), groundtruth=part)
    assert rows[0]["ate_poses"] == int((state.exp_t <= gt[gt[:, 0] <= cut][-1, 0]).sum()) < n


def test_a_timed_groundtruth_for_a_graph_file_is_one_line(small_run, tmp_path, capsys):
    from ratslam_graph.io import write_g2o
    from torchratslam.experiments.compare_backends import posegraph_from_state

    g2o = tmp_path / "m.g2o"
    write_g2o(posegraph_from_state(load_state(small_run.out)), g2o)
    csv = tmp_path / "gt.csv"
    csv.write_text("t,x,y,theta\n0,0,0,0\n1,1,0,0\n")
    capsys.readouterr()
    assert main(["compare-backends", "--map", str(g2o), "--groundtruth", str(csv)]) == 2
    err = capsys.readouterr().err
    assert "--groundtruth: a timed ground truth" in err and "Traceback" not in err


def test_a_per_node_groundtruth_of_fewer_than_three_nodes_gives_no_ate(tmp_path):
    from ratslam_graph.io import write_g2o
    from ratslam_graph.posegraph import PoseGraph

    pg = PoseGraph(
        np.array([[0.0, 0, 0], [1, 0, 0]]),
        np.array([[0, 1]]),
        np.array([[1.0, 0, 0]]),
        np.arange(2),
    )
    g2o, gt = tmp_path / "two.g2o", tmp_path / "gt.txt"
    write_g2o(pg, g2o)
    gt.write_text("0 0 0\n1 0 0\n")
    _, rows = run_comparison(g2o, ("alpha",), groundtruth=gt)
    assert rows[0]["ate_rmse_m"] is None and rows[0]["ate_poses"] == 2
