"""A group's second pass: each run's experience map fed from the first pass's record.

:func:`~torchratslam.sweeps.runner.run_group` reads the frames and computes the
odometry, the views and every run's pose cells once, recording them frame by frame
(:class:`GroupPass`); :func:`replay` then runs each run's own
:class:`~torchratslam.pipeline.RatSLAM` on that record, with stand-ins for the stages
already computed. Two runs whose replays would read the same keys and the same record
give the same map number for number: the second takes the first's metrics.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["MODULE_ONLY_PC_KEYS", "GroupPass", "replay", "replay_key"]

# Pose-cell keys read by the pose-cell *module* only, not by its network.
MODULE_ONLY_PC_KEYS = frozenset(
    {"vt_active_decay", "pc_vt_inject_energy", "pc_vt_restore", "exp_delta_pc_threshold"}
)


@dataclass
class GroupPass:
    """What a group's first pass recorded, frame by frame.

    ``owner[b]`` is the run whose pose-cell module stepped for run ``b`` (runs with
    equal pose-cell keys share one); ``actions``, ``centres`` and ``angles`` are filled
    for owners only.
    """

    modules: list[Any]
    owner: list[int]
    frames: list[Any] = field(default_factory=list)
    odos: list[tuple[float, float, float]] = field(default_factory=list)
    views: list[Any] = field(default_factory=list)
    sizes: list[int] = field(default_factory=list)
    templates: Any = None
    actions: list[list[Any]] = field(init=False)
    centres: list[list[tuple]] = field(init=False)
    angles: list[list[float]] = field(init=False)

    def __post_init__(self) -> None:
        n = len(self.modules)
        self.actions = [[] for _ in range(n)]
        self.centres = [[] for _ in range(n)]
        self.angles = [[] for _ in range(n)]

    def same_pose_cells(self, a: int, b: int) -> bool:
        """Whether runs ``a`` and ``b`` got the same actions, centres and angles."""
        a, b = self.owner[a], self.owner[b]
        return a == b or (
            self.actions[a] == self.actions[b]
            and self.centres[a] == self.centres[b]
            and self.angles[a] == self.angles[b]
        )


def replay_key(config: Any) -> tuple:
    """Every key a replay reads: all but the pose-cell module's own (whose effect
    reaches the replay only through the actions, centres and injection angles)."""
    flat = config.to_flat()
    return tuple(sorted((k, repr(v)) for k, v in flat.items() if k not in MODULE_ONLY_PC_KEYS))


class _ReplayView:
    """A local view that hands out views computed once for a whole group."""

    def __init__(self, views: list[Any], sizes: list[int], templates: Any) -> None:
        self._views, self._sizes, self._templates = views, sizes, templates
        self._i = 0

    def process(self, observation: Any, frame_index: int | None = None) -> Any:
        view = self._views[self._i]
        self._i += 1
        return view

    def __len__(self) -> int:
        return self._sizes[self._i - 1] if self._i else 0

    @property
    def templates(self) -> Any:
        return self._templates


class _ReplayPoseCells:
    """A pose-cell module that hands out the actions, centres and injection angles
    (``vt_delta_pc_th``, what the pipeline's ``action_angle: injection`` reads) of a
    group's pass, frame by frame."""

    def __init__(
        self, actions: list[Any], centres: list[tuple], angles: list[float], module: Any
    ) -> None:
        self._actions, self._centres, self._angles = actions, centres, angles
        self._module = module
        self._i = -1

    def on_view_template(self, match: Any) -> None:
        self._i += 1

    def on_odometry(self, vtrans: float, vrot: float, dt: float) -> Any:
        return self._actions[self._i]

    @property
    def centre(self) -> tuple[float, float, float]:
        return self._centres[self._i]

    @property
    def vt_delta_pc_th(self) -> float:
        return self._angles[self._i]

    @property
    def activity(self) -> Any:
        return self._module.activity

    def __getattr__(self, name: str) -> Any:  # state, counts: the real module's
        return getattr(self._module, name)


class _ReplayOdometry:
    def __init__(self, odos: list[tuple[float, float, float]]) -> None:
        self._odos, self._i = odos, 0

    def __call__(self, frame: Any) -> tuple[float, float, float]:
        odo = self._odos[self._i]
        self._i += 1
        return odo


def replay(
    record: GroupPass, configs: Sequence[Any], metrics: Callable[[Any, Any], dict[str, Any]]
) -> list[tuple[dict[str, Any], float]]:
    """Each run's metrics (``metrics(slam, result)`` of its replay, or of its twin's)
    and the seconds its replay took, in order."""
    from torchratslam.pipeline import RatSLAM

    done: list[tuple[tuple, int, dict[str, Any]]] = []  # (key, run, metrics)
    out = []
    for b, config in enumerate(configs):
        t1 = time.perf_counter()
        key = replay_key(config)
        twin = next((m for k, r, m in done if k == key and record.same_pose_cells(r, b)), None)
        if twin is None:  # this run's map is its own
            o = record.owner[b]
            slam = RatSLAM(
                config,
                local_view=_ReplayView(record.views, record.sizes, record.templates),
                pose_cells=_ReplayPoseCells(
                    record.actions[o], record.centres[o], record.angles[o], record.modules[o]
                ),
                odometry=_ReplayOdometry(record.odos),
            )
            twin = metrics(slam, slam.run(record.frames, progress=False))
            done.append((key, b, twin))
        out.append((dict(twin), time.perf_counter() - t1))
    return out
