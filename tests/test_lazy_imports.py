"""``import torchratslam`` stays light, gtsam loads only for the gtsam backends, and a
run that writes no figure and reads no video loads neither matplotlib nor cv2.

Each check runs in a fresh interpreter and inspects ``sys.modules``.
"""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


HEAVY = ("torch", "gtsam")
PLOTTING = ("matplotlib", "cv2", "PIL")


def _loaded_after(code: str, tmp_path: Path, watch: tuple[str, ...] = HEAVY) -> set[str]:
    """Run ``code`` in a new interpreter (cwd outside the checkout); return which of
    the ``watch`` modules it left in ``sys.modules``."""
    probe = code + f"\nimport sys\nprint(sorted(set({watch!r}) & set(sys.modules)))\n"
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True, check=True
    )
    return set(eval(out.stdout.strip().splitlines()[-1]))


def test_import_torchratslam_loads_neither_torch_nor_gtsam(tmp_path):
    code = "import torchratslam\nfrom torchratslam import load_config, ConfigError\n"
    code += "load_config('virtual_tour')\n"
    assert _loaded_after(code, tmp_path) == set()


def test_experience_map_relaxed_by_the_alpha_rule_loads_no_gtsam(tmp_path):
    code = """
import ratslam_graph
from ratslam_graph.backends import make_backend
from ratslam_graph.experience_map import ExperienceMap
from ratslam_graph.messages import Action, ActionKind
from ratslam_graph.params import ExperienceMapParams

em = ExperienceMap(ExperienceMapParams(exp_backend="alpha", exp_loops=5))
for i in range(4):
    em.apply(Action(ActionKind.CREATE, dest_id=i))
    em.on_odometry(1.0, 1.5, 1.0)
em.apply(Action(ActionKind.LINK, dest_id=0))
before = em.poses.copy()
em.iterate()
assert (em.poses != before).any(), "the loop closure moved nothing"
make_backend("alpha_reference").relax(em.posegraph(), passes=2)
"""
    assert _loaded_after(code, tmp_path) == set()


def test_the_gtsam_backends_still_load_and_relax(tmp_path):
    code = """
import numpy as np
from ratslam_graph.backends import GraphErrorEvaluator, make_backend
from ratslam_graph.posegraph import PoseGraph

poses = np.array([[0.0, 0, 0], [1.1, 0, 0], [2.0, 0.2, 0]])
edges = np.array([[0, 1], [1, 2], [0, 2]])
meas = np.array([[1.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
pg = PoseGraph(poses, edges, meas, np.arange(3))
ev = GraphErrorEvaluator(pg)
for name in ("gtsam", "isam2"):
    out = make_backend(name).relax(pg, passes=1)
    assert ev(out) < 1e-9 < ev(poses), (name, ev(out))
"""
    assert _loaded_after(code, tmp_path) == {"gtsam"}


@pytest.mark.parametrize("name", ["GtsamBackend", "factor_graph", "nope"])
def test_lazy_names_resolve_or_fail_like_attributes(name):
    import ratslam_graph.backends as backends

    if name == "nope":
        with pytest.raises(AttributeError, match="nope"):
            getattr(backends, name)
    else:
        from ratslam_graph.backends import gtsam_backend

        assert getattr(backends, name) is getattr(gtsam_backend, name)


def test_the_pipeline_and_the_cli_import_no_plotting_or_image_library(tmp_path):
    code = "from torchratslam.pipeline import RatSLAM\nimport torchratslam.cli\n"
    assert _loaded_after(code, tmp_path, PLOTTING) == set()


# three frames of a run in memory (no reader, no outputs)
THREE_FRAMES = """
import sys
import numpy as np
from torchratslam import RatSLAM, load_config

slam = RatSLAM(load_config("irat"))
rng = np.random.default_rng(0)
for _ in range(3):
    slam.step(rng.integers(0, 255, (120, 160), dtype=np.uint8), (0.1, 0.01, 0.1))
assert slam.frame_index == 3, slam.frame_index
"""


def test_a_run_in_memory_loads_no_plotting_or_image_library(tmp_path):
    assert _loaded_after(THREE_FRAMES, tmp_path, PLOTTING) == set()


def test_a_run_in_memory_loads_networkx_only_when_its_graph_is_read(tmp_path):
    code = (
        THREE_FRAMES
        + """
assert "networkx" not in sys.modules, "networkx loaded by a run that never read its graph"
g = slam.experience_map.graph
assert g.number_of_nodes() == len(slam.experience_map) > 0
"""
    )
    assert _loaded_after(code, tmp_path, ("networkx",)) == {"networkx"}


def test_the_cli_parser_loads_no_plotting_image_or_tensor_library(tmp_path):
    """``torchratslam --help`` (every subcommand registered) imports neither cv2 (the
    simulator writes frames with it when it writes them) nor torch nor matplotlib."""
    code = "import torchratslam.cli\ntorchratslam.cli.build_parser()\n"
    assert _loaded_after(code, tmp_path, PLOTTING + HEAVY + ("networkx",)) == set()
