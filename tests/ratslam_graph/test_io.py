"""Pose-graph files: g2o, TORO, the city10000 variant, ground truth; exact round trips."""

import gtsam
import numpy as np
import pytest

from ratslam_graph.errors import InputError, MapFormatError
from ratslam_graph.geometry import between, compose, wrap_angle
from ratslam_graph.io import (
    CITY_SIGMAS,
    example_file,
    read_posegraph,
    read_poses,
    write_g2o,
    write_toro,
)
from ratslam_graph.posegraph import PoseGraph, compose_odometry


def _gtsam_reference(path):
    """gtsam's own reader: factor keys and measurements, initial values."""
    graph, initial = gtsam.load2D(str(path))
    factors = []
    for i in range(graph.size()):
        f = graph.at(i)
        if isinstance(f, gtsam.BetweenFactorPose2):
            m = f.measured()
            factors.append((*f.keys(), m.x(), m.y(), m.theta()))
    poses = {k: initial.atPose2(k) for k in initial.keys()}
    return factors, poses


@pytest.mark.parametrize("name", ["w100.graph", "w10000.graph"])
def test_toro_files_read_like_gtsam_does(name):
    path = example_file(name)
    pg = read_posegraph(path)
    lines = path.read_text().splitlines()
    assert pg.num_poses == sum(line.startswith("VERTEX2") for line in lines)
    assert pg.num_edges == sum(line.startswith("EDGE2") for line in lines)
    factors, poses = _gtsam_reference(path)
    ids = pg.ids
    ours = sorted(
        (int(ids[a]), int(ids[b]), *m) for (a, b), m in zip(pg.edges, pg.measurements.tolist())
    )
    theirs = np.array(sorted(factors))
    ours = np.array(ours)
    assert len(ours) == len(theirs)
    ours[:, 4] = wrap_angle(ours[:, 4])  # files may hold angles beyond pi; gtsam wraps
    np.testing.assert_allclose(ours, theirs, atol=1e-9)
    for row, vid in enumerate(ids[:200].tolist()):
        p = poses[vid]
        np.testing.assert_allclose(pg.poses[row], [p.x(), p.y(), p.theta()], atol=1e-9)
    np.testing.assert_array_equal(pg.information, np.broadcast_to(np.eye(3), (pg.num_edges, 3, 3)))


def test_g2o_information_order(tmp_path):
    # g2o: I11 I12 I13 I22 I23 I33; TORO: I11 I12 I22 I33 I13 I23
    g2o = tmp_path / "a.g2o"
    g2o.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 2 3 4 5 6\n")
    toro = tmp_path / "a.graph"
    toro.write_text("VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 2 4 6 3 5\n")
    expect = np.array([[1, 2, 3], [2, 4, 5], [3, 5, 6]], float)
    np.testing.assert_array_equal(read_posegraph(g2o).information[0], expect)
    np.testing.assert_array_equal(read_posegraph(toro).information[0], expect)
    # TORO tags in a .g2o file (gtsam's w100_30.g2o) follow the g2o order
    mixed = tmp_path / "b.g2o"
    mixed.write_text("VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 1 2 3 4 5 6\n")
    np.testing.assert_array_equal(read_posegraph(mixed).information[0], expect)


def _random_pg(seed, n=40, e=70, with_info=True, ids=True):
    rng = np.random.default_rng(seed)
    poses = rng.normal(0, 10, (n, 3))
    poses[:, 2] = rng.uniform(-np.pi, np.pi, n)
    a = rng.integers(0, n, e)
    b = (a + rng.integers(1, n, e)) % n
    meas = rng.normal(0, 3, (e, 3))
    info = None
    if with_info:
        m = rng.normal(size=(e, 3, 3))
        info = m @ m.transpose(0, 2, 1) + 3 * np.eye(3)
    vid = rng.permutation(10 * n)[:n] if ids else None
    return PoseGraph(poses, np.stack([a, b], 1), meas, vid, info)


@pytest.mark.parametrize("writer", [write_g2o, write_toro])
@pytest.mark.parametrize("seed", range(3))
def test_round_trip_is_exact(tmp_path, writer, seed):
    pg = _random_pg(seed)
    path = tmp_path / ("g.g2o" if writer is write_g2o else "g.graph")
    writer(pg, path)
    back = read_posegraph(path)
    np.testing.assert_array_equal(back.poses, pg.poses)
    np.testing.assert_array_equal(back.edges, pg.edges)
    np.testing.assert_array_equal(back.measurements, pg.measurements)
    np.testing.assert_array_equal(back.ids, pg.ids)
    np.testing.assert_array_equal(back.information, pg.information)
    # and a second trip writes the identical file
    again = tmp_path / ("h" + path.suffix)
    writer(back, again)
    assert again.read_text() == path.read_text()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # atomic


def test_round_trip_of_shipped_w100_and_missing_information(tmp_path):
    pg = read_posegraph(example_file("w100.graph"))
    for writer, name in ((write_g2o, "w.g2o"), (write_toro, "w.graph")):
        writer(pg, tmp_path / name)
        back = read_posegraph(tmp_path / name)
        for field in ("poses", "edges", "measurements", "ids", "information"):
            np.testing.assert_array_equal(getattr(back, field), getattr(pg, field))
    bare = _random_pg(9, with_info=False, ids=False)
    write_g2o(bare, tmp_path / "bare.g2o")
    back = read_posegraph(tmp_path / "bare.g2o")
    np.testing.assert_array_equal(back.ids, np.arange(bare.num_poses))
    np.testing.assert_array_equal(
        back.information, np.broadcast_to(np.eye(3), (bare.num_edges, 3, 3))
    )


def test_city10000_first_hypothesis_city_sigmas_and_composed_odometry():
    path = example_file("T1_city10000_04.txt")
    pg = read_posegraph(path)
    lines = [line.split() for line in path.read_text().splitlines() if line.strip()]
    assert (pg.num_poses, pg.num_edges) == (10000, 20687)
    assert sum(len(t) == 12 for t in lines) == 200  # the lines with a second hypothesis
    for i in (0, 93, 5000, len(lines) - 1):
        t = lines[i]
        assert pg.edges[i].tolist() == [int(t[1]), int(t[3])]
        np.testing.assert_array_equal(pg.measurements[i], [float(v) for v in t[6:9]])
    np.testing.assert_allclose(pg.information[7], np.diag(1 / np.square(CITY_SIGMAS)))
    # initial estimate: odometry composed pose by pose, as gtsam's example does
    p = gtsam.Pose2(0, 0, 0)
    odo = {
        (int(t[1]), int(t[3])): gtsam.Pose2(*map(float, t[6:9]))
        for t in lines
        if int(t[3]) == int(t[1]) + 1
    }
    for k in range(1, 300):
        p = p.compose(odo[(k - 1, k)])
        np.testing.assert_allclose(pg.poses[k], [p.x(), p.y(), p.theta()], atol=1e-9)
    gt = read_poses(example_file("ISAM2_GT_city10000.txt"))
    assert gt.shape == (10000, 3)


def test_compose_odometry_accepts_backward_edges_and_matches_compose():
    rng = np.random.default_rng(1)
    steps = rng.normal(0, 1, (30, 3))
    truth = [np.zeros(3)]
    for s in steps:
        truth.append(compose(truth[-1], s))
    truth = np.array(truth)
    edges = np.array([[i + 1, i] if i % 3 == 0 else [i, i + 1] for i in range(30)])
    meas = between(truth[edges[:, 0]], truth[edges[:, 1]])
    np.testing.assert_allclose(compose_odometry(31, edges, meas), truth, atol=1e-9)
    with pytest.raises(InputError, match="no edge between nodes 4 and 5"):
        compose_odometry(31, np.delete(edges, 4, 0), np.delete(meas, 4, 0))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 7 1 0 0\n", "no VERTEX line"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nEDGE_SE2 0 1 1 x 0\n", "malformed"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_XY 1 0 0\n", "unsupported record 'VERTEX_XY'"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\n", "duplicate vertex"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0\n", "fields"),
        ("# nothing\n", "no VERTEX or EDGE"),
    ],
)
def test_bad_files_say_what_is_wrong(tmp_path, text, match):
    path = tmp_path / "bad.g2o"
    path.write_text(text)
    with pytest.raises(MapFormatError, match=match):
        read_posegraph(path)


def test_missing_files_and_bad_arguments(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        read_posegraph(tmp_path / "nope.g2o")
    with pytest.raises(InputError, match="does not exist"):
        read_poses(tmp_path / "nope.txt")
    (tmp_path / "x.g2o").write_text("VERTEX_SE2 0 0 0 0\n")
    with pytest.raises(MapFormatError, match="unknown pose-graph format"):
        read_posegraph(tmp_path / "x.g2o", format="json")


def test_posegraph_validation():
    with pytest.raises(InputError, match="measurements"):
        PoseGraph(np.zeros((2, 3)), [[0, 1]], np.zeros((2, 3)))
    with pytest.raises(InputError, match="row indices"):
        PoseGraph(np.zeros((2, 3)), [[0, 2]], np.zeros((1, 3)))
    with pytest.raises(InputError, match="itself"):
        PoseGraph(np.zeros((2, 3)), [[1, 1]], np.zeros((1, 3)))
    with pytest.raises(InputError, match="finite"):
        PoseGraph(np.full((2, 3), np.nan), [[0, 1]], np.zeros((1, 3)))
    pg = PoseGraph.from_links(np.zeros((2, 3)), [[0, 1]], [2.0], [np.pi / 2], [0.3])
    np.testing.assert_allclose(pg.measurements, [[0.0, 2.0, 0.3]], atol=1e-15)
    d, heading, facing = pg.links()
    np.testing.assert_allclose([d[0], heading[0], facing[0]], [2.0, np.pi / 2, 0.3])


def test_initial_estimate_from_odometry_instead_of_vertices():
    path = example_file("w100.graph")
    from_file = read_posegraph(path)
    odo = read_posegraph(path, initial="odometry")
    np.testing.assert_array_equal(odo.edges, from_file.edges)
    expect = compose_odometry(
        100, from_file.edges, from_file.measurements, start=from_file.poses[0]
    )
    np.testing.assert_allclose(odo.poses, expect)
    # every odometry edge is then satisfied exactly
    chain = np.abs(odo.edges[:, 0] - odo.edges[:, 1]) == 1
    assert np.abs(odo.relative_errors()[chain]).max() < 1e-9
    assert np.abs(from_file.relative_errors()[chain]).max() > 1e-3
    with pytest.raises(InputError, match="initial"):
        read_posegraph(path, initial="zero")
