"""MBARAM topological mapping on a simulated laser tour (Chin et al. 2015; the runner
behind ``torchratslam mbaram``): learn a map over the first laps, localise on the next
ones with and without the odometry channel, and write ``metrics.json``, ``state.npz``
and the figures.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import atomic_write_text, atomic_write_with
from ratslam_graph.out_checks import check_out_dir
from torchratslam.errors import ConfigError, InputError, option
from torchratslam.messages import Frame

__all__ = [
    "PAPER",
    "PRESETS",
    "MBARAMTourMetrics",
    "MBARAMTourOptions",
    "MBARAMTourResult",
    "laser_frames",
    "run_experiment",
    "sim_session",
    "split_laps",
    "summary_line",
]

# parameter presets: the paper's Table 3 values; the recommended settings of
# docs/mbaram.md (paper values plus units, the odometry channel's S_MAX,k sized for nodes
# about 1.5 m of path long as the paper's, the laser beam outlier term and localisation
# over consecutive frames); and "dense", nodes 0.4 m long that localise single frames
PRESETS: dict[str, dict[str, float]] = {
    "paper": {},
    "sim": {
        "laser_scale": 3.0,
        "s_max_odometry": 2e-5,
        "var_floor_odometry": 0.01,
        "laser_outlier": 0.01,
        "loc_track_hops": 1,
    },
    "dense": {
        "laser_scale": 3.0,
        "s_max_odometry": 3e-6,
        "var_floor_odometry": 0.01,
        "laser_outlier": 0.01,
    },
}

# the paper's robot experiment (Section 3.4) and Rawseeds results, for the figures
PAPER = {
    "nodes_per_lap": [24, 6, 6, 6, 5],
    "localisation_with_odometry": {"rawseeds": 0.974, "robot": 0.975},
    "localisation_without_odometry": {"rawseeds": 0.839, "robot": 0.86},
}


@dataclass(frozen=True)
class MBARAMTourOptions:
    """How :func:`run_experiment` maps and localises.

    Attributes:
        laps: mapping laps.
        loc_laps: localisation laps after the mapping.
        seed: the simulator's seed.
        moving_obstacles: pedestrians walking along the path.
        moved_obstacles: boxes that move between laps.
        odometry: ``groundtruth`` or ``integrated`` (the odometry channel's source).
        preset: a key of :data:`PRESETS`; ``overrides`` are MBARAM parameters over it.
        overrides: MBARAM parameters over the preset.
        plots: write the figures.
        progress: a labelled progress bar per lap (lap k/N, frames).
        mapper: the range-sensor mapper (a name in ``registry.RANGE_MAPPERS``).
    """

    laps: int = 5
    loc_laps: int = 5
    seed: int = 0
    moving_obstacles: int = 2
    moved_obstacles: int = 2
    odometry: str = "groundtruth"
    preset: str = "sim"
    overrides: Mapping[str, str] = field(default_factory=dict)
    plots: bool = True
    progress: bool = False
    mapper: str = "mbaram"


@dataclass(frozen=True)
class MBARAMTourMetrics:
    """What ``metrics.json`` holds: the mapper's metrics, then the tour's settings.

    Attributes:
        mapper: the :func:`~torchratslam.mbaram.run.run_mbaram` metrics (nodes, edges,
            frames, qe, qe_m, cr, nodes_per_lap, localisation rates, ...).
        data: the simulator spec.
        seed: the simulator's seed.
        moving_obstacles: pedestrians walking along the path.
        moved_obstacles: boxes that move between laps.
        preset: the parameter preset.
        laps: mapping laps run.
        loc_laps: localisation laps run.
        paper: the paper's results (:data:`PAPER`).
    """

    mapper: dict[str, Any]
    data: str
    seed: int
    moving_obstacles: int
    moved_obstacles: int
    preset: str
    laps: int
    loc_laps: int
    paper: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """The mapper's metrics followed by the tour's fields (metrics.json's order)."""
        tour = asdict(self)
        del tour["mapper"]
        return {**self.mapper, **tour}


@dataclass(frozen=True)
class MBARAMTourResult:
    """What :func:`run_experiment` returns.

    Attributes:
        run: the :func:`~torchratslam.mbaram.run.run_mbaram` result.
        metrics: the metrics written.
    """

    run: Any
    metrics: MBARAMTourMetrics


def sim_session(spec: str, *, laps: int, seed: int, moving: int, moved: int) -> Any:
    """The simulated session of ``spec`` with lasers on and enough laps."""
    from torchratslam.sim import get_tour
    from torchratslam.sim.dataset import parse_sim_spec
    from torchratslam.sim.tours import TOURS

    name, session, options = parse_sim_spec(spec)
    options.setdefault("lasers", True)
    options.setdefault("moving_obstacles", moving)
    options.setdefault("moved_obstacles", moved)
    if "laps" in TOURS[name].options:
        options.setdefault("laps", laps)
    seed = int(options.pop("seed", seed))
    tour = get_tour(name, seed=seed, **options)
    if session is None or session == "full":
        return tour.full()
    return tour.session(int(session) if session.isdigit() else session)


def laser_frames(session: Any, start: int, stop: int) -> Iterator[Frame]:
    """Frames ``start..stop`` with scans, odometry and pose but no image (fast)."""
    for k in range(start, stop):
        vt, vr, dt = (float(v) for v in session.odometry[k])
        x, y, th = (float(v) for v in session.poses[k])
        yield Frame(
            index=k,
            t=float(session.times[k]),
            image=None,
            vtrans=vt,
            vrot=vr,
            dt=dt,
            pose=(x, y, th),
            scans=session.scans(k),
            meta={"lap": int(session.laps[k])},
        )


def split_laps(lap_ids: np.ndarray, laps: int, loc_laps: int) -> tuple[list, list]:
    """Index ranges of the mapping and localisation laps (frames are in lap order)."""
    ranges = []
    for lap in range(laps + loc_laps):
        idx = np.flatnonzero(lap_ids == lap)
        if len(idx):
            ranges.append((int(idx[0]), int(idx[-1]) + 1))
    if len(ranges) < laps:
        raise InputError(
            f"the session has {len(ranges)} lap(s), fewer than --laps {laps}; "
            "ask the tour for more laps (sim:NAME?laps=N) or lower --laps"
        )
    return ranges[:laps], ranges[laps:]


def _with_progress(session: Any, ranges: Any, label: str, quiet: bool) -> list[Any]:
    """One frame stream per lap, each with a labelled progress bar (lap k/N, frames)."""
    laps = [laser_frames(session, a, b) for a, b in ranges]
    if quiet:
        return laps
    from tqdm import tqdm

    n = len(laps)
    return [
        tqdm(lap, total=int(b - a), desc=f"{label} {k}/{n}", unit="frame", leave=False)
        for k, (lap, (a, b)) in enumerate(zip(laps, ranges), start=1)
    ]


def _check(data: str, laps: int, loc_laps: int) -> None:
    if laps < 1 or loc_laps < 0:
        raise ConfigError("--laps must be >= 1 and --loc-laps >= 0")
    if not str(data).startswith("sim:"):
        raise InputError(
            f"--data {data!r}: MBARAM needs laser scans, which only the simulator "
            "provides for now; use sim:NAME (e.g. sim:loop)"
        )


def _write_outputs(result: Any, metrics: MBARAMTourMetrics, out: Path) -> None:
    """``metrics.json`` and ``state.npz`` (the map's arrays and node positions)."""
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "metrics.json", json.dumps(metrics.to_json(), indent=2) + "\n")
    state = result.model.get_state()
    arrays = {k.replace("/", "__"): np.asarray(v) for k, v in state.items() if k != "params"}
    atomic_write_with(
        out / "state.npz",
        lambda fh: np.savez(fh, **arrays, node_xy=result.node_xy),  # type: ignore[arg-type]
    )


def run_experiment(
    data: str,
    out: str | Path,
    options: MBARAMTourOptions | None = None,
    *,
    overwrite: bool = False,
) -> MBARAMTourResult:
    """Map ``options.laps`` laps of the simulated tour ``data``, localise on
    ``options.loc_laps`` more, and write OUT (``metrics.json``, ``state.npz``, and the
    figures when ``options.plots``).

    Args:
        data: the simulator spec ``sim:NAME[/SESSION][?key=value]``.
        out: the output folder.
        options: how to map and localise (default :class:`MBARAMTourOptions`).
        overwrite: replace an earlier MBARAM run in ``out`` (a folder holding anything
            else is always refused).

    Returns:
        The :func:`~torchratslam.mbaram.run.run_mbaram` result and the metrics written.

    Raises:
        ConfigError: bad lap counts or parameters.
        InputError: not a simulated tour with lasers; ``out`` holds something else, or
            an earlier MBARAM run without ``overwrite``.
    """
    import torch

    # OUT: new, empty, or an earlier MBARAM run's (replaced only with overwrite)
    if check_out_dir(out, what="MBARAM run", marks=("state.npz",)) and not overwrite:
        raise InputError(
            f"{out} holds a finished MBARAM run; choose another "
            f"{option('--out', 'out')}, or replace it with "
            f"{option('--overwrite', 'overwrite=True')}"
        )

    from torchratslam.mbaram.params import MBARAMParams
    from torchratslam.mbaram.run import run_mbaram

    o = options or MBARAMTourOptions()
    _check(data, o.laps, o.loc_laps)
    params = MBARAMParams.from_dict({**PRESETS[o.preset], **(o.overrides or {})})
    torch.set_num_threads(1)
    session = sim_session(
        data,
        laps=o.laps + o.loc_laps,
        seed=o.seed,
        moving=o.moving_obstacles,
        moved=o.moved_obstacles,
    )
    if not session.lasers:
        raise InputError(f"{data}: the session has no lasers; add ?lasers=true")
    map_r, loc_r = split_laps(np.asarray(session.laps), o.laps, o.loc_laps)
    result = run_mbaram(
        _with_progress(session, map_r, "mapping lap", not o.progress),
        _with_progress(session, loc_r, "localisation lap", not o.progress),
        params,
        odometry=o.odometry,
        mapper=o.mapper,
    )
    metrics = MBARAMTourMetrics(
        mapper=dict(result.metrics),
        data=data,
        seed=o.seed,
        moving_obstacles=o.moving_obstacles,
        moved_obstacles=o.moved_obstacles,
        preset=o.preset,
        laps=len(map_r),
        loc_laps=len(loc_r),
        paper=PAPER,
    )
    out = Path(out)
    _write_outputs(result, metrics, out)
    if o.plots:
        from torchratslam.viz.mbaram import plot_results

        plot_results(result, session, out, paper=PAPER)
    return MBARAMTourResult(run=result, metrics=metrics)


def summary_line(data: str, metrics: MBARAMTourMetrics, out: Path) -> str:
    """The one-line summary the CLI prints."""
    m = metrics.mapper
    return (
        f"MBARAM {data}: {m['nodes']} nodes, {m['edges']} edges, nodes per lap "
        f"{m['nodes_per_lap']}, QE {m['qe']:.3f} ({m['qe_m']:.2f} m), CR {m['cr']:.0f}:1, "
        f"localisation {100 * m['localisation_rate_with_odometry']:.1f}% with odometry, "
        f"{100 * m['localisation_rate_without_odometry']:.1f}% without -> {out}"
    )
