"""The Gymnasium environment (skipped where gymnasium is not installed)."""

import sys

import numpy as np
import pytest

from torchratslam.errors import ConfigError
from torchratslam.sim.office import env as office_env


def test_a_missing_gymnasium_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "gymnasium", None)
    monkeypatch.setattr(office_env, "_ENV", None)
    with pytest.raises(ConfigError, match=r"pip install torchratslam\[gym\]"):
        office_env.make_office_env()


def test_the_env_passes_gymnasiums_checker_and_is_seeded():
    gym = pytest.importorskip(
        "gymnasium", reason="gymnasium is not installed (pip install torchratslam[gym])"
    )
    from gymnasium.utils.env_checker import check_env

    env = office_env.make_office_env(max_steps=20, render_mode="rgb_array")
    assert isinstance(env, gym.Env)
    assert isinstance(env, office_env.OfficeEnv)
    check_env(env, skip_render_check=False)
    o1, i1 = env.reset(seed=3)
    o2, i2 = env.reset(seed=3)
    np.testing.assert_array_equal(o1["image"], o2["image"])
    np.testing.assert_array_equal(i1["pose"], i2["pose"])
    for _ in range(20):
        obs, r, term, trunc, info = env.step(0)
        assert env.observation_space.contains(obs)
    assert trunc and not term and r == 0.0 and info["pose"].shape == (3,)
    assert env.render().shape == (8, 12, 3)
