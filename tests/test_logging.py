"""The library logs with the standard ``logging`` module under the package's name and
never prints: merges, fallbacks, skipped entries and unconverged solves are logged."""

import ast
import logging
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parent.parent
APPS = ("cli", "experiments")  # may print: they are the command line's output


def _library_files() -> list[Path]:
    files = sorted((ROOT / "graph").rglob("*.py"))
    files += [
        f
        for f in sorted((ROOT / "torchratslam").rglob("*.py"))
        if f.relative_to(ROOT / "torchratslam").parts[0] not in APPS and f.name != "__main__.py"
    ]
    return files


def _prints_and_loggers(path: Path) -> tuple[list[int], list[str]]:
    """Lines calling print(), and the source of every getLogger(...) argument."""
    tree = ast.parse(path.read_text(), filename=str(path))
    prints, loggers = [], []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Name) and f.id == "print":
                prints.append(node.lineno)
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name == "getLogger":
                loggers.append(", ".join(ast.unparse(a) for a in node.args))
    return prints, loggers


def test_library_code_never_prints_and_logs_under_its_module_name():
    files = _library_files()
    assert len(files) > 40
    prints, loggers = {}, {}
    for f in files:
        p, lg = _prints_and_loggers(f)
        if p:
            prints[str(f.relative_to(ROOT))] = p
        if lg:
            loggers[str(f.relative_to(ROOT))] = lg
    assert not prints, f"library code must log, not print: {prints}"
    assert len(loggers) >= 6, loggers
    bad = {k: v for k, v in loggers.items() if v != ["__name__"]}
    assert not bad, f"use logging.getLogger(__name__): {bad}"


def test_the_checker_sees_a_print_and_a_foreign_logger(tmp_path):
    f = tmp_path / "m.py"
    f.write_text(
        '"""print(1) in a docstring is fine."""\nimport logging\n'
        'log = logging.getLogger("x")\nprint("hi")\n'
    )
    assert _prints_and_loggers(f) == ([4], ["'x'"])


def test_a_multisession_merge_is_logged(caplog):
    from torchratslam import load_config
    from torchratslam.maps.running import state_from_slam
    from torchratslam.multisession.session import MultiSessionRatSLAM
    from torchratslam.pipeline import RatSLAM
    from torchratslam.sim import get_tour

    torch.set_num_threads(1)
    config = load_config("virtual_tour")
    session = get_tour("virtual_tour").sessions[0]
    first = RatSLAM(config)
    first.run(session.frames(0, 12), progress=False)
    ms = MultiSessionRatSLAM(config, [state_from_slam(first)], session="again")
    with caplog.at_level(logging.INFO, logger="torchratslam"):
        ms.run(session.frames(0, 3), progress=False)
    assert len(ms.merges) == 1
    merge = [r for r in caplog.records if r.name == "torchratslam.maps.merge"]
    session_log = [r for r in caplog.records if r.name == "torchratslam.multisession.session"]
    assert len(merge) == 1 and "experiences" in merge[0].getMessage()
    assert len(session_log) == 1 and session_log[0].levelno == logging.INFO
    rec = ms.merges[0]
    assert f"frame {rec['frame']}: merged stored map" in session_log[0].getMessage()


def test_skipped_files_and_missing_odometry_are_logged(tmp_path, caplog):
    import cv2

    from torchratslam.pipeline import RatSLAM
    from torchratslam.readers.datasets import DirectoryReader

    frames = tmp_path / "frames"
    frames.mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):
        cv2.imwrite(str(frames / f"{k:03d}.png"), rng.integers(0, 255, (24, 80), np.uint8))
    (frames / "notes.txt").write_text("not an image")
    with caplog.at_level(logging.INFO, logger="torchratslam"):
        reader = DirectoryReader(tmp_path)
    assert len(reader) == 3
    messages = [r.getMessage() for r in caplog.records if r.name.startswith("torchratslam.")]
    assert any("skipped 1 entries that are not images (notes.txt)" in m for m in messages)
    assert any("no odometry.csv" in m for m in messages)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="torchratslam"):
        slam = RatSLAM()
        slam.run(reader, progress=False)
    warned = [r for r in caplog.records if r.name == "torchratslam.pipeline.ratslam"]
    assert len(warned) == 1 and warned[0].levelno == logging.WARNING
    assert "odometry='visual'" in warned[0].getMessage()
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="torchratslam"):
        RatSLAM(odometry="visual").run(reader, progress=False)
    assert not [r for r in caplog.records if r.name == "torchratslam.pipeline"]


def test_an_unconverged_lm_solve_is_logged(caplog):
    from ratslam_graph.backends import make_backend
    from ratslam_graph.posegraph import PoseGraph

    rng = np.random.default_rng(3)
    n = 30
    meas = np.tile([1.0, 0.0, 2 * np.pi / n], (n, 1))
    edges = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    poses = np.cumsum(rng.normal(0, 0.5, (n, 3)), axis=0)
    pg = PoseGraph(poses, edges, meas, np.arange(n))
    with caplog.at_level(logging.WARNING, logger="torchratslam"):
        make_backend("gtsam").relax(pg, passes=0)
    assert not caplog.records
    with caplog.at_level(logging.WARNING, logger="torchratslam"):
        make_backend("gtsam", max_iterations=1).relax(pg, passes=0)
    (rec,) = caplog.records
    assert rec.name == "ratslam_graph.backends.gtsam_backend"
    assert "limit of 1 iterations" in rec.getMessage()


def test_a_relaxation_that_keeps_moving_is_logged_at_debug(caplog):
    from ratslam_graph.experience_map import ExperienceMap
    from ratslam_graph.messages import Action, ActionKind
    from ratslam_graph.params import ExperienceMapParams

    em = ExperienceMap(ExperienceMapParams(exp_loops=1))
    for i in range(4):
        em.apply(Action(ActionKind.CREATE, dest_id=i))
        em.on_odometry(1.0, 1.5, 1.0)
    em.apply(Action(ActionKind.LINK, dest_id=0))
    with caplog.at_level(logging.DEBUG, logger="ratslam_graph"):
        em.iterate()
    (rec,) = [r for r in caplog.records if r.name == "ratslam_graph.relaxation"]
    assert rec.levelno == logging.DEBUG and "1 passes of 'alpha'" in rec.getMessage()
