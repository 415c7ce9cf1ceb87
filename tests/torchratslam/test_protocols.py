"""One typed Protocol per pluggable stage: the shipped modules have the interfaces, the
registries check what they build against them, and the state code asks for Stateful."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ratslam_graph.backends import AlphaBackend
from ratslam_graph.experience_map import ExperienceMap
from torchratslam.config import RatSLAMConfig, load_config
from torchratslam.errors import ConfigError, MapFormatError
from torchratslam.maps.running import state_from_slam
from torchratslam.messages import Frame
from torchratslam.pipeline import RatSLAM
from torchratslam.pipeline.defaults import DEFAULTS
from torchratslam.protocols import (
    ExperienceMapModule,
    FrameSource,
    GroundTruthSource,
    InjectionAngle,
    LocalViewModule,
    OdometrySource,
    PoseCellModule,
    RelaxationBackend,
    Stateful,
)
from torchratslam.readers.visual_odometry import GivenOdometry, VisualOdometry
from torchratslam.registry import EXPERIENCE_MAPS, LOCAL_VIEWS, ODOMETRY, POSE_CELLS, Registry
from torchratslam.sim import get_tour


def test_shipped_modules_have_their_stage_interfaces():
    slam = RatSLAM(load_config("virtual_tour"))
    assert isinstance(slam.local_view, LocalViewModule) and isinstance(slam.local_view, Stateful)
    assert isinstance(slam.pose_cells, PoseCellModule) and isinstance(slam.pose_cells, Stateful)
    assert isinstance(slam.experience_map, ExperienceMapModule)
    assert isinstance(slam.experience_map, Stateful)
    assert isinstance(ExperienceMap(slam.config.experience_map), ExperienceMapModule)
    for odo in (GivenOdometry(), VisualOdometry()):
        assert isinstance(odo, OdometrySource) and isinstance(odo, Stateful)
    assert isinstance(AlphaBackend(), RelaxationBackend)
    session = get_tour("virtual_tour").sessions[0]
    assert isinstance(session, FrameSource) and isinstance(session, GroundTruthSource)
    assert not isinstance([Frame(0, 0.0, None)], FrameSource)
    for name in LOCAL_VIEWS:
        assert isinstance(LOCAL_VIEWS.build(name, slam.config.local_view), LocalViewModule)
    for name in POSE_CELLS:
        assert isinstance(POSE_CELLS.build(name, slam.config.pose_cells), PoseCellModule)
    for name in ODOMETRY:
        assert callable(ODOMETRY.build(name, slam.config.visual_odometry))


def test_the_default_stages_have_what_the_pipeline_reads():
    slam = RatSLAM(load_config("virtual_tour"))
    slam.run(get_tour("virtual_tour").sessions[0].frames(0, 30), progress=False)
    em, pcs = slam.experience_map, slam.pose_cells
    for registry, name, _ in DEFAULTS:  # tests may register maps of their own
        if registry is EXPERIENCE_MAPS:
            built = EXPERIENCE_MAPS.build(name, slam.config.experience_map)
            assert isinstance(built, ExperienceMapModule)
    # the members the protocol names answer like the map's own arrays and graph
    assert len(em) == em.poses.shape[0] == em.graph.number_of_nodes() > 1
    assert em.num_links == em.graph.number_of_edges() == len(em.links()["src"])
    assert slam.counts() == (len(slam.local_view), len(em), em.num_links)
    # the shipped pose cells report their injection angle; a bare stage does not
    assert isinstance(pcs, InjectionAngle) and pcs.dims == (
        pcs.activity.shape[2],
        pcs.activity.shape[1],
        pcs.activity.shape[0],
    )
    assert not isinstance(object(), InjectionAngle)


def test_an_experience_map_without_poses_or_graph_is_refused():
    class ChainOnly:
        current_id = -1

        def __len__(self):
            return 0

        def on_odometry(self, vtrans, vrot, dt):
            pass

        def apply(self, action, *, frame, t, pc, template_id):
            pass

        def iterate(self):
            pass

    with pytest.raises(
        ConfigError, match=r"ChainOnly is not .*: it lacks graph, num_links, poses "
    ):
        RatSLAM(experience_map=ChainOnly())


def test_registry_rejects_a_module_without_the_interface_naming_what_it_lacks():
    class HalfView:
        def process(self, observation, frame_index=None):
            return None

    with pytest.raises(ConfigError, match=r"HalfView is not a local view: it lacks __len__, tem"):
        RatSLAM(local_view=HalfView())
    reg: Registry[PoseCellModule] = Registry("pose-cell module", PoseCellModule)
    reg.register("half", HalfView)
    with pytest.raises(ConfigError, match="activity, centre, on_odometry, on_view_template"):
        reg.build("half")
    with pytest.raises(ConfigError, match="no pose-cell module given"):
        reg.build(None)
    plain: Registry[object] = Registry("thing")  # no protocol: anything goes
    assert plain.build(3) == 3


def test_state_code_asks_for_stateful_modules():
    class NoState:
        """A working local view that cannot be saved."""

        def __init__(self):
            self.n = 0

        def process(self, observation, frame_index=None):
            from torchratslam.messages import ViewMatch

            self.n = 1
            return ViewMatch(0, 0.0, 0.0, 0, frame_index == 0)

        def __len__(self):
            return self.n

        @property
        def templates(self):
            return torch.zeros(self.n, 1, 1)

    slam = RatSLAM(RatSLAMConfig(), local_view=NoState())
    slam.step(np.zeros((4, 4), np.uint8), (0.1, 0.0, 0.1))
    with pytest.raises(MapFormatError, match=r"the local view \(NoState\) has no get_state"):
        state_from_slam(slam)
