"""One sweep run (or one batched group of runs) -> one table row each.

A row holds the run's identity (``index``, ``run_id``, ``dataset``, ``seed``,
``backend``), its swept parameter values, ``status`` (``ok`` or ``error``), ``error``
(the one-line message of a failed run) and the metrics of ``torchratslam run``:

=========================  ==========================================================
column                     meaning
=========================  ==========================================================
``frames``                 frames processed
``templates``              visual templates at the end
``experiences``            experiences at the end
``links``                  experience-map links at the end
``ate_m``                  ATE (m) of the experience trajectory vs ground truth
``dead_reckoning_ate_m``   ATE (m) of the integrated odometry alone
``ate_frames``             frames both ATEs are taken over (SE(2)-aligned; a map pose and
                           a ground-truth pose; under 3 both ATEs are nan, undefined)
``wall_s``                 wall-clock seconds of the run (timing)
``fps``                    frames per second (timing)
``ms_<module>``            mean ms per frame of odometry, local_view, pose_cells,
                           experience_map (timing)
``batch``                  how many runs shared one batched pose-cell network (timing)
=========================  ==========================================================

Runs whose configs differ only in parameters the local view and the pose-cell network
do not read (``vt_active_decay``, ``pc_vt_inject_energy``, ``pc_vt_restore``,
``exp_delta_pc_threshold`` and every experience-map key, backends included) see exactly
the same views and the same odometry, so :func:`run_group` reads the frames and
computes the odometry and local view once, and gives each run its own pose-cell
bookkeeping and experience map. When the network computes its dynamics on the whole
network (``separable``/``conv3d``, e.g. OpenRatSLAM's 21x21x36), one
:class:`PoseCellNetwork` with ``B`` networks steps all runs in one call per frame;
cropped networks (large ones) step one by one, since a batch's crop box follows its
widest packet and would change the others' rounding. Stepped one by one, runs with
equal pose-cell keys (a sweep of experience-map keys alone) step one module between
them. A run whose every key outside the pose-cell module's own equals an earlier run's,
and whose pose cells gave the same actions, centres and injection angles on every frame,
would compute that run's map again number for number: it takes the earlier run's
metrics instead (its ``wall_s`` is then its share of the group's common work). Either
way the rows equal separate runs' bit for bit
(``tests/torchratslam/sweeps/test_batched.py``).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from torchratslam.sweeps.replay import MODULE_ONLY_PC_KEYS, GroupPass, replay
from torchratslam.sweeps.spec import RunSpec

__all__ = [
    "METRICS",
    "MODULES",
    "TIMING_COLUMNS",
    "batch_key",
    "run_group",
    "run_one",
    "run_safely",
]

log = logging.getLogger(__name__)

MODULES = ("odometry", "local_view", "pose_cells", "experience_map")
METRICS = (
    "frames",
    "templates",
    "experiences",
    "links",
    "ate_m",
    "dead_reckoning_ate_m",
    "ate_frames",
    "wall_s",
    "fps",
    *(f"ms_{m}" for m in MODULES),
    "batch",
)
TIMING_COLUMNS = ("wall_s", "fps", *(f"ms_{m}" for m in MODULES), "batch")
"""Columns that depend on the machine's speed or the execution (excluded when tables
are compared for determinism)."""


def _identity(run: RunSpec, backend: str) -> dict[str, Any]:
    return {
        "index": run.index,
        "run_id": run.run_id,
        "dataset": run.dataset,
        "max_frames": run.max_frames if run.max_frames is not None else -1,
        "seed": run.seed,
        "backend": backend,
        **run.params,
    }


def _error_row(run: RunSpec, exc: BaseException) -> dict[str, Any]:
    message = " ".join(str(exc).split()) or type(exc).__name__
    row = _identity(run, run.backend or "")
    row.update(status="error", error=f"{type(exc).__name__}: {message}")
    row.update({k: math.nan for k in METRICS})
    return row


def _open(run: RunSpec) -> Any:
    from torchratslam.readers.datasets import open_data

    return open_data(run.data)


def _odometry_for(data: Any, config: Any) -> Any:
    """None (the config's choice) unless the data carries no odometry."""
    if getattr(data, "has_odometry", True):
        return None
    from torchratslam.readers.visual_odometry import VisualOdometry

    mirrored = bool(getattr(data, "mirrored", False)) or (
        getattr(getattr(data, "camera", None), "kind", None) == "panoramic"
    )
    return VisualOdometry(config.visual_odometry, mirrored=mirrored)


def _metrics(slam: Any, result: Any, data: Any, wall_s: float, batch: int) -> dict[str, Any]:
    table = None
    if slam.groundtruth_poses() is None and hasattr(data, "groundtruth"):
        table = data.groundtruth()
        if table is not None and not len(table):
            table = None
    ate = dr = None
    n_gt = 0
    if slam.groundtruth_poses() is not None or table is not None:
        n_gt = slam.history.ate_frames(slam.experience_map.poses, table)
        if n_gt >= 3:  # an ATE needs 3 poses: under 3 it is undefined (nan)
            ate = slam.ate(table)
            dr = slam.dead_reckoning_ate(table)
    timings = result.timings
    row: dict[str, Any] = {
        "status": "ok",
        "error": "",
        "frames": int(result.frames),
        "templates": int(result.templates),
        "experiences": int(result.experiences),
        "links": int(result.links),
        "ate_m": math.nan if ate is None else float(ate),
        "dead_reckoning_ate_m": math.nan if dr is None else float(dr),
        "ate_frames": int(n_gt),
        "wall_s": float(wall_s),
        "fps": float(result.frames / wall_s) if wall_s > 0 else 0.0,
        "batch": int(batch),
    }
    for m in MODULES:
        row[f"ms_{m}"] = float(timings.get(m, {}).get("mean_ms", math.nan))
    return row


def run_one(run: RunSpec) -> dict[str, Any]:
    """Run one configuration on its dataset (exceptions propagate).

    Returns:
        The table row (identity, parameters, ``status``, ``error``, metrics).
    """
    from torchratslam.pipeline import RatSLAM

    config = run.config()
    data = _open(run)
    t0 = time.perf_counter()
    slam = RatSLAM(config, odometry=_odometry_for(data, config))
    result = slam.run(data, max_frames=run.max_frames, progress=False)
    wall = time.perf_counter() - t0
    row = _identity(run, config.experience_map.exp_backend)
    row.update(_metrics(slam, result, data, wall, 1))
    return row


def run_safely(run: RunSpec) -> dict[str, Any]:
    """:func:`run_one`, with any failure recorded in the row instead of raised."""
    try:
        return run_one(run)
    except Exception as exc:  # a failing run is a result of the sweep
        log.warning("run %s failed: %s", run.run_id, exc)
        return _error_row(run, exc)


# ----------------------------------------------------------------- batched groups
def batch_key(run: RunSpec) -> tuple | None:
    """Runs with equal keys can share one batched pose-cell network (None: never).

    The key holds everything that decides the frames, the odometry, the views and the
    pose-cell *network*: the dataset, frame limit, and every config key except the
    module-only pose-cell keys and the experience map's keys.
    """
    try:
        config = run.config()
    except Exception:
        return None
    if config.general.pose_cells != "ratslam":
        return None
    flat = config.to_flat()
    em_keys = set(type(config.experience_map).keys())
    shared = tuple(
        sorted(
            (k, repr(v))
            for k, v in flat.items()
            if k not in MODULE_ONLY_PC_KEYS and k not in em_keys
        )
    )
    return (run.data, run.max_frames, shared)


def shares_network(network: Any, pc_engine: str) -> bool:
    """Whether a group may step its runs' networks as one batched network.

    Only the torch step (``pc_engine: torch``; a lone CPU network otherwise steps in
    numpy, whose rounding a batch would not reproduce) on networks whose dynamics run on
    the whole network (``separable``, ``conv3d``) gives the same numbers in a batch as
    alone; the ``crop`` method sizes its box by the widest packet of the batch, which
    changes the rounding of the others. Other groups still share the frames, odometry
    and local view, and step each run's network alone.
    """
    return pc_engine == "torch" and getattr(network, "method", None) in ("separable", "conv3d")


class _SlotNetwork:
    """Network ``b`` of a shared batched :class:`PoseCellNetwork`, as the pose-cell
    module sees it: injections are queued until the whole batch steps, and ``step``
    returns this network's row of the batch's packet centres."""

    def __init__(self, shared: Any, b: int, dims: tuple[int, int, int]) -> None:
        self.shared, self.b, self.dims = shared, b, dims
        self.pending: tuple[int, int, int, float] | None = None
        self.centre_row: Any = None

    @property
    def activity(self) -> Any:
        return self.shared.activity[self.b : self.b + 1]

    def inject(self, x: Any, y: Any, th: Any, energy: Any) -> None:
        if self.pending is not None:
            raise RuntimeError("two injections in one frame")  # not in RatSLAM's rules
        self.pending = (int(x), int(y), int(th), float(energy))

    def step(self, vtrans: Any, vrot: Any, dt: Any = 1.0) -> Any:
        return self.centre_row

    def step_one(self, vtrans: float, vrot: float, dt: float) -> tuple[float, float, float]:
        """:meth:`step` as Python floats (what the pose-cell module calls)."""
        c = self.step(vtrans, vrot, dt)[0].tolist()
        return (c[0], c[1], c[2])


def _frames(data: Any, max_frames: int | None) -> Iterator[Any]:
    it = iter(data.frames()) if hasattr(data, "frames") else iter(data)
    for i, frame in enumerate(it):
        if max_frames is not None and i >= max_frames:
            return
        yield frame


def run_group(runs: Sequence[RunSpec]) -> list[dict[str, Any]]:
    """Run several configurations that share a :func:`batch_key` as one group
    (exceptions propagate; one row per run, in order).

    The frames are read, and the odometry and local view computed, once; each frame
    steps all ``B`` pose-cell networks in one call (when :func:`shares_network`, else
    one by one, each exactly as its own run would: the numpy step of OpenRatSLAM's
    behaviour included); each run then replays its views and actions through its own
    :class:`~torchratslam.pipeline.RatSLAM` (its own experience map). With
    ``skip_first_odometry`` no network steps at frame 0, as in a separate run.
    """
    from torchratslam.messages import Action
    from torchratslam.pipeline import RatSLAM
    from torchratslam.pose_cells.network import PoseCellNetwork
    from torchratslam.pose_cells.stage import PoseCells

    if len(runs) == 1:
        return [run_one(runs[0])]
    configs = [r.config() for r in runs]
    data = _open(runs[0])
    t0 = time.perf_counter()
    ref = RatSLAM(configs[0], odometry=_odometry_for(data, configs[0]))
    modules = [PoseCells(c.pose_cells, dtype=ref.dtype) for c in configs]
    slots: list[_SlotNetwork] = []
    shared = None
    batched = shares_network(modules[0].network, configs[0].pose_cells.pc_engine)
    owner = list(range(len(runs)))
    if not batched:  # runs with equal pose-cell keys step one module: the same numbers
        first: dict[Any, int] = {}
        owner = [first.setdefault(c.pose_cells, b) for b, c in enumerate(configs)]
    else:
        shared = PoseCellNetwork(
            configs[0].pose_cells, len(runs), dtype=ref.dtype, method=modules[0].network.method
        )
        for b, m in enumerate(modules):
            slot = _SlotNetwork(shared, b, m.network.dims)
            m.network = slot  # type: ignore[assignment]  # the slot steps like a network
            slots.append(slot)
    stepped = sorted(set(owner))
    rec = GroupPass(modules, owner)
    t_odo = t_view = t_pc = 0.0
    zeros = np.zeros(len(runs), dtype=np.int64)
    skip_first = bool(configs[0].general.skip_first_odometry)  # a key the group shares
    for i, frame in enumerate(_frames(data, runs[0].max_frames)):
        rec.frames.append(frame)
        c0 = time.perf_counter()
        odo = tuple(float(v) for v in ref.odometry(frame))
        c1 = time.perf_counter()
        view = ref.local_view.process(frame.image, frame_index=i)
        c2 = time.perf_counter()
        rec.odos.append(odo)  # type: ignore[arg-type]
        rec.views.append(view)
        rec.sizes.append(len(ref.local_view))
        for b in stepped:
            modules[b].on_view_template(view)
        skip = skip_first and i == 0
        if shared is not None:  # every network in one call
            inj = [s.pending for s in slots]
            if any(p is not None for p in inj):
                x, y, th, e = zeros.copy(), zeros.copy(), zeros.copy(), np.zeros(len(runs))
                for b, p in enumerate(inj):
                    if p is not None:
                        x[b], y[b], th[b], e[b] = p
                        slots[b].pending = None
                shared.inject(x, y, th, e)
            if not skip:
                cents = shared.step(odo[0], odo[1], odo[2])
                for b, slot in enumerate(slots):
                    slot.centre_row = cents[b : b + 1]
        for b in stepped:
            m = modules[b]
            rec.actions[b].append(Action.none() if skip else m.on_odometry(*odo))
            c = m.centre
            rec.centres[b].append((float(c[0]), float(c[1]), float(c[2])))
            rec.angles[b].append(float(m.vt_delta_pc_th))
        c3 = time.perf_counter()
        t_odo += c1 - c0
        t_view += c2 - c1
        t_pc += c3 - c2
    rec.templates = ref.local_view.templates
    shared_s = time.perf_counter() - t0
    n, B = max(len(rec.frames), 1), len(runs)
    rows = []
    replays = replay(rec, configs, lambda slam, res: _metrics(slam, res, data, 1.0, B))
    for run, config, (metrics, own) in zip(runs, configs, replays):
        wall = shared_s / B + own
        row = _identity(run, config.experience_map.exp_backend)
        row.update(metrics, wall_s=wall, fps=float(metrics["frames"] / wall) if wall > 0 else 0.0)
        row["ms_odometry"] = t_odo / n * 1e3 / B
        row["ms_local_view"] = t_view / n * 1e3 / B
        row["ms_pose_cells"] = t_pc / n * 1e3 / B
        rows.append(row)
    return rows


def run_group_safely(runs: Sequence[RunSpec]) -> list[dict[str, Any]]:
    """:func:`run_group`; if the group fails, each run is retried alone so that only
    the runs that fail by themselves are recorded as errors."""
    try:
        return run_group(runs)
    except Exception as exc:
        if len(runs) == 1:
            return [_error_row(runs[0], exc)]
        log.info("batched group failed (%s); running its %d runs one by one", exc, len(runs))
        return [run_safely(r) for r in runs]
