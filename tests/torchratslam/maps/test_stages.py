"""The stage records a map is made of: round trips through the stages' dictionaries."""

from __future__ import annotations

import numpy as np
import pytest

from ratslam_graph.map_state import STATE_FORMAT, STATE_VERSION
from ratslam_graph.state import ExperienceMapState
from torchratslam.config import load_config
from torchratslam.errors import MapFormatError
from torchratslam.local_view.state import LocalViewState
from torchratslam.maps.running import apply_state, state_from_slam
from torchratslam.maps.stages import compose, decompose
from torchratslam.messages import SessionState
from torchratslam.pipeline import RatSLAM
from torchratslam.pose_cells.state import PoseCellState
from torchratslam.protocols import SlamSystem

CONFIG = load_config(
    pc_dim_xy=7, pc_dim_th=10, template_x_size=5, template_y_size=3, vt_shift_match=2
)


def _run(n: int = 25) -> RatSLAM:
    rng = np.random.default_rng(3)
    slam = RatSLAM(CONFIG)
    for _ in range(n):
        slam.step(rng.random((12, 20)), (0.3, rng.normal(0, 0.2), 0.1))
    return slam


def test_each_record_gives_back_the_stage_dictionary():
    slam = _run()
    for module, record in (
        (slam.local_view, LocalViewState),
        (slam.pose_cells, PoseCellState),
        (slam.experience_map, ExperienceMapState),
    ):
        d = module.get_state()
        back = record.from_dict(d).to_dict()
        assert list(back) == list(d)  # same keys, same order
        for k, v in d.items():
            assert np.array_equal(np.asarray(back[k]), np.asarray(v)), k


def test_compose_then_decompose_is_the_identity_on_the_records():
    slam = _run()
    state = state_from_slam(slam)
    parts = decompose(state)
    again = compose(
        state.config,
        parts.local_view,
        parts.pose_cells,
        parts.experience_map,
        parts.session,
        parts.odometry or None,
    )
    assert again.equals(state)
    assert parts.session == slam.session == SessionState(25, slam.session.last_t)


def test_a_loaded_slam_has_the_session_and_stages_of_the_saved_one():
    slam = _run()
    other = RatSLAM(CONFIG)
    apply_state(state_from_slam(slam), other)
    assert other.session == slam.session
    assert isinstance(other, SlamSystem)
    assert state_from_slam(other).equals(state_from_slam(slam))


def test_the_experience_map_record_names_the_stage_format():
    assert (ExperienceMapState.FORMAT, ExperienceMapState.VERSION) == (STATE_FORMAT, STATE_VERSION)


def test_wrong_shapes_raise_map_format_errors():
    with pytest.raises(MapFormatError, match="templates"):
        LocalViewState(templates=np.zeros((2, 3)))
    with pytest.raises(MapFormatError, match="means"):
        LocalViewState(templates=np.zeros((2, 3, 4)), means=np.zeros(3))
    good = PoseCellState.empty()
    with pytest.raises(MapFormatError, match="template_decay"):
        good.replace(template_pc=np.zeros((2, 3)))
    with pytest.raises(MapFormatError, match="link_values"):
        ExperienceMapState.empty().replace(link_ends=np.zeros((1, 2), np.int64))
    with pytest.raises(MapFormatError, match="link_values"):
        ExperienceMapState.from_dict({"link_ends": np.zeros((0, 2))})


def _run_with(config, n: int, seed: int = 3, slam: RatSLAM | None = None) -> RatSLAM:
    rng = np.random.default_rng(seed)
    slam = slam if slam is not None else RatSLAM(config)
    for _ in range(n):
        slam.step(rng.random((12, 20)), (0.3, rng.normal(0, 0.2), 0.1))
    return slam


def test_a_rectangular_network_saves_its_shape_and_continues_bit_identically(tmp_path):
    from torchratslam.maps.native import load_map, save_map

    cfg = CONFIG.replace(pc_dim_x=9, pc_dim_y=6)
    slam = _run_with(cfg, 20)
    state = state_from_slam(slam)
    assert state.pc_dims == (9, 6, 10) and state.activity.shape == (10, 6, 9)
    save_map(state, tmp_path / "m")
    back = load_map(tmp_path / "m")
    assert back.pc_dims == (9, 6, 10)
    fresh = RatSLAM(cfg)
    apply_state(back, fresh)
    _run_with(cfg, 10, seed=4, slam=slam)
    _run_with(cfg, 10, seed=4, slam=fresh)
    assert np.array_equal(
        slam.pose_cells.get_state()["activity"], fresh.pose_cells.get_state()["activity"]
    )
    # a config of another shape is refused in one line naming both shapes
    with pytest.raises(MapFormatError, match=r"\(X, Y\) = \(9, 6\) in the map but \(6, 9\)"):
        apply_state(back, RatSLAM(CONFIG.replace(pc_dim_x=6, pc_dim_y=9)))


def test_a_map_saved_before_pc_dim_x_existed_is_square(tmp_path):
    from torchratslam.maps.native import load_map, save_map

    state = state_from_slam(_run())
    state.config = {k: v for k, v in state.config.items() if k not in ("pc_dim_x", "pc_dim_y")}
    save_map(state, tmp_path / "old")
    back = load_map(tmp_path / "old")
    assert back.pc_dims == (7, 7, 10)
    fresh = RatSLAM(CONFIG)
    apply_state(back, fresh)
    assert np.array_equal(fresh.pose_cells.get_state()["activity"], state.activity)


def test_a_map_made_by_the_activity_rule_saves_and_continues_bit_identically(tmp_path):
    """With exp_create_rule="activity" the map decides when to learn an experience and the
    pose cells keep their own list (their distance rule only gives the action's angle), so
    the two counts part; the saved map holds both and a loaded run continues identically."""
    from torchratslam.maps.native import load_map, save_map

    cfg = CONFIG.replace(exp_create_rule="activity", exp_delta_pc_threshold=0.5)
    views = np.random.default_rng(3).random((6, 12, 20))  # six views seen in turn
    slam = RatSLAM(cfg)
    for i in range(60):
        slam.step(views[i % 6], (0.3, 0.2, 0.1))
    n_pc = slam.pose_cells.get_state()["exp_pc"].shape[0]
    n_em = len(slam.experience_map)
    assert n_pc != n_em  # the situation that made saving fail
    state = state_from_slam(slam)
    assert state.n_experiences == n_em
    assert np.array_equal(state.exp_pc, slam.experience_map.get_state()["pc"])
    save_map(state, tmp_path / "m")
    fresh = RatSLAM(cfg)
    apply_state(load_map(tmp_path / "m"), fresh)
    for a, b in ((slam.pose_cells, fresh.pose_cells), (slam.experience_map, fresh.experience_map)):
        sa, sb = a.get_state(), b.get_state()
        assert list(sa) == list(sb)
        for k in sa:
            assert np.array_equal(np.asarray(sa[k]), np.asarray(sb[k])), k
    _run_with(cfg, 30, seed=4, slam=slam)
    _run_with(cfg, 30, seed=4, slam=fresh)
    assert state_from_slam(fresh).equals(state_from_slam(slam))
