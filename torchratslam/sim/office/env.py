"""A Gymnasium environment around :class:`~torchratslam.sim.office.sim.OfficeSim`.

Gymnasium is optional (``pip install torchratslam[gym]``); it is imported when the
environment is made, so the rest of the package works without it.

Observation: ``{"image": (8, 12) uint8, "odometry": (3,) float32 [vtrans, vrot, dt],
"scan": (beams,) float32}``; action: a behaviour index
(:class:`~torchratslam.sim.office.motion.Behaviour`); reward 0 (the environment serves
navigation research, not a task); ``info`` holds the ground-truth pose and the step's
events. An episode is truncated after ``max_steps`` ticks.

Example:
    >>> from torchratslam.sim.office.env import make_office_env
    >>> env = make_office_env(max_steps=10)  # doctest: +SKIP
    >>> obs, info = env.reset(seed=0)  # doctest: +SKIP
"""

from __future__ import annotations

from typing import Any

import numpy as np

from torchratslam.errors import ConfigError
from torchratslam.sim.office.motion import Behaviour
from torchratslam.sim.office.sim import OfficeParams, OfficeSim, OfficeStep

__all__ = ["make_office_env", "office_env_class"]


def _gymnasium() -> Any:
    try:
        import gymnasium
    except ModuleNotFoundError:
        raise ConfigError(
            "the office environment needs gymnasium: pip install torchratslam[gym]"
        ) from None
    return gymnasium


def make_office_env(
    params: OfficeParams | None = None, *, max_steps: int = 2000, render_mode: str | None = None
) -> Any:
    """Make an ``OfficeEnv`` (a ``gymnasium.Env``).

    Raises:
        ConfigError: when gymnasium is not installed.
    """
    return office_env_class()(params, max_steps=max_steps, render_mode=render_mode)


def office_env_class() -> type:
    """The ``OfficeEnv`` class, defined on first use over the installed gymnasium.

    Raises:
        ConfigError: when gymnasium is not installed.
    """
    global _ENV
    if _ENV is None:
        _ENV = _define(_gymnasium())
    return _ENV


_ENV: type | None = None


def __getattr__(name: str) -> Any:
    """``OfficeEnv`` resolves on first access (gymnasium imported then)."""
    if name == "OfficeEnv":
        return office_env_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _define(gym: Any) -> type:
    spaces = gym.spaces

    class OfficeEnv(gym.Env):
        """The office robot as a Gymnasium environment (see the module docstring).

        Args:
            params: the simulation's settings.
            max_steps: ticks per episode before truncation.
            render_mode: None or ``"rgb_array"`` (the camera image as RGB).
        """

        metadata = {"render_modes": ["rgb_array"], "render_fps": 7}  # noqa: RUF012

        def __init__(
            self,
            params: OfficeParams | None = None,
            *,
            max_steps: int = 2000,
            render_mode: str | None = None,
        ) -> None:
            if render_mode not in (None, "rgb_array"):
                raise ConfigError(f"render_mode {render_mode!r} is not None or 'rgb_array'")
            self.sim = OfficeSim(params=params)
            self.max_steps = int(max_steps)
            self.render_mode = render_mode
            sp = self.sim.params.sensors
            h, w = sp.image_size
            n = sp.laser.n_beams
            self.observation_space = spaces.Dict(
                {
                    "image": spaces.Box(0, 255, (h, w), np.uint8),
                    "odometry": spaces.Box(
                        np.array([-5.0, -10.0, 0.0], np.float32),
                        np.array([5.0, 10.0, 1.0], np.float32),
                        dtype=np.float32,
                    ),
                    "scan": spaces.Box(0.0, sp.laser.max_range, (n,), np.float32),
                }
            )
            self.action_space = spaces.Discrete(len(Behaviour))
            self._steps = 0
            self._last: OfficeStep | None = None

        @staticmethod
        def _obs(s: OfficeStep) -> dict[str, np.ndarray]:
            return {
                "image": s.image,
                "odometry": s.odometry.astype(np.float32),
                "scan": s.scan.astype(np.float32),
            }

        @staticmethod
        def _info(s: OfficeStep) -> dict[str, Any]:
            return {
                "pose": s.pose.copy(),
                "time": s.time,
                "node": s.node,
                "behaviour": s.behaviour,
                "blocked": s.blocked,
            }

        def reset(
            self, *, seed: int | None = None, options: dict[str, Any] | None = None
        ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
            super().reset(seed=seed)
            s = self.sim.reset(int(self.np_random.integers(2**31)))
            self._steps = 0
            self._last = s
            return self._obs(s), self._info(s)

        def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict]:
            s = self.sim.step(int(action))
            self._steps += 1
            self._last = s
            return self._obs(s), 0.0, False, self._steps >= self.max_steps, self._info(s)

        def render(self) -> np.ndarray | None:
            if self.render_mode != "rgb_array" or self._last is None:
                return None
            return np.repeat(self._last.image[..., None], 3, axis=2)

    return OfficeEnv
