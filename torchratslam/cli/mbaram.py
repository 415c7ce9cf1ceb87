"""``torchratslam mbaram``: MBARAM topological mapping on a simulated laser tour.

Example:
    torchratslam mbaram --data sim:loop --out out/mbaram --laps 5 --loc-laps 5
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import numpy as np

from torchratslam.graph.errors import ConfigError, InputError
from torchratslam.graph.io import atomic_write_text
from torchratslam.messages import Frame

# parameter presets: the paper's Table 3 values, and those used for the results in
# docs/mbaram.md (paper values plus units and the odometry channel's S_MAX,k)
PRESETS: dict[str, dict[str, float]] = {
    "paper": {},
    "sim": {
        "laser_scale": 3.0,
        "s_max_odometry": 3e-6,
        "var_floor_odometry": 0.01,
        "laser_outlier": 0.01,
    },
}

# the paper's robot experiment (Section 3.4) and Rawseeds results, for the figures
PAPER: dict[str, Any] = {
    "nodes_per_lap": [24, 6, 6, 6, 5],
    "localisation_with_odometry": {"rawseeds": 0.974, "robot": 0.975},
    "localisation_without_odometry": {"rawseeds": 0.839, "robot": 0.86},
}


def register(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``mbaram`` subcommand."""
    p = subparsers.add_parser(
        "mbaram",
        help="MBARAM topological map from laser scans and odometry (simulated tours)",
        description=(
            "Learn an MBARAM topological map (Chin et al. 2015) over the first LAPS laps "
            "of a simulated tour with front and rear lasers, then localise on the next "
            "LOC_LAPS laps with and without the odometry channel. Writes OUT/metrics.json, "
            "OUT/map.png, OUT/nodes_per_lap.png, OUT/localisation.png and OUT/state.npz."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--data", required=True, help="simulator spec sim:NAME[/SESSION][?key=value]")
    p.add_argument("--out", required=True, type=Path, help="output directory")
    p.add_argument("--laps", type=int, default=5, help="mapping laps")
    p.add_argument("--loc-laps", type=int, default=5, help="localisation laps after the mapping")
    p.add_argument("--seed", type=int, default=0, help="simulator seed")
    p.add_argument(
        "--moving-obstacles", type=int, default=2, help="pedestrians walking along the path"
    )
    p.add_argument("--moved-obstacles", type=int, default=2, help="boxes that move between laps")
    p.add_argument(
        "--odometry",
        choices=("groundtruth", "integrated"),
        default="groundtruth",
        help="odometry channel: ground-truth pose (the paper assumes accurate odometry) "
        "or dead reckoning of the noisy odometry",
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default="sim",
        help="parameter preset: paper (Table 3 as printed) or sim (paper values with laser "
        "units and the odometry channel's S_MAX,k set for the simulated tours)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an MBARAM parameter over the preset, e.g. --set laser_scale=5 (repeatable)",
    )
    p.add_argument(
        "--mapper",
        default="mbaram",
        help="range-sensor mapper, a name in torchratslam.registry.RANGE_MAPPERS",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.set_defaults(func=main)
    return p


def sim_session(spec: str, *, laps: int, seed: int, moving: int, moved: int) -> Any:
    """The simulated session of ``spec`` with lasers on and enough laps."""
    from torchratslam.sim import get_tour
    from torchratslam.sim.dataset import parse_sim_spec
    from torchratslam.sim.tours import TOURS

    name, session, options = parse_sim_spec(spec)
    options.setdefault("lasers", True)
    options.setdefault("moving_obstacles", moving)
    options.setdefault("moved_obstacles", moved)
    if "laps" in inspect.signature(TOURS[name]).parameters:
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
        yield Frame(
            index=k,
            t=float(session.times[k]),
            image=None,
            vtrans=vt,
            vrot=vr,
            dt=dt,
            pose=cast(tuple[float, float, float], tuple(float(v) for v in session.poses[k])),
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


def _parse_sets(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--set expects KEY=VALUE, got {item!r}")
        out[key.strip()] = value.strip()
    return out


def plot_results(result: Any, session: Any, out: Path) -> None:
    """``map.png``, ``nodes_per_lap.png`` and ``localisation.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g, xy = result.model.graph, result.node_xy
    fig, ax = plt.subplots(figsize=(7, 6))
    session.world.plot(ax)
    ax.plot(result.path[:, 0], result.path[:, 1], color="0.75", lw=0.6, label="path")
    for u, v in g.edges:
        ax.plot(xy[[u, v], 0], xy[[u, v], 1], "k-", lw=0.8)
    ax.plot(xy[:, 0], xy[:, 1], "o", color="red", ms=5, label=f"{len(xy)} nodes")
    ax.set_aspect("equal")
    ax.set_title(f"MBARAM topological map: {len(xy)} nodes, {g.number_of_edges()} edges")
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(out / "map.png", dpi=120, bbox_inches="tight")
    plt.close(fig)

    per_lap = result.nodes_per_lap
    fig, ax = plt.subplots(figsize=(6, 4))
    laps = np.arange(1, len(per_lap) + 1)
    ax.bar(laps - 0.2, per_lap, width=0.4, label="nodes added (this run)")
    paper = PAPER["nodes_per_lap"][: len(per_lap)]
    ax.bar(
        np.arange(1, len(paper) + 1) + 0.2,
        paper,
        width=0.4,
        label="paper, Fig. 13a (24, then 5-6; 47 after 5)",
    )
    ax.set_xlabel("lap")
    ax.set_ylabel("nodes added")
    ax.set_xticks(laps)
    ax.legend()
    fig.savefig(out / "nodes_per_lap.png", dpi=120, bbox_inches="tight")
    plt.close(fig)

    m = result.metrics
    w, wo = m["localisation_per_lap_with_odometry"], m["localisation_per_lap_without_odometry"]
    if w:
        fig, ax = plt.subplots(figsize=(6, 4))
        laps = np.arange(1, len(w) + 1)
        ax.plot(laps, np.array(w) * 100, "o-", label="with odometry")
        ax.plot(laps, np.array(wo) * 100, "s-", label="lasers only")
        ax.axhline(97.5, color="C0", ls=":", lw=1, label="paper 97.5% / 86% (robot)")
        ax.axhline(86.0, color="C1", ls=":", lw=1)
        ax.set_ylim(0, 105)
        ax.set_xlabel("localisation lap")
        ax.set_ylabel("success rate (%)")
        ax.set_xticks(laps)
        ax.legend()
        fig.savefig(out / "localisation.png", dpi=120, bbox_inches="tight")
        plt.close(fig)


def main(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    import torch

    from torchratslam.mbaram.model import MBARAMParams, run_mbaram

    if args.laps < 1 or args.loc_laps < 0:
        raise ConfigError("--laps must be >= 1 and --loc-laps >= 0")
    if not str(args.data).startswith("sim:"):
        raise InputError(
            f"--data {args.data!r}: MBARAM needs laser scans, which only the simulator "
            "provides for now; use sim:NAME (e.g. sim:loop)"
        )
    params = MBARAMParams.from_dict({**PRESETS[args.preset], **_parse_sets(args.set)})
    torch.set_num_threads(1)
    session = sim_session(
        args.data,
        laps=args.laps + args.loc_laps,
        seed=args.seed,
        moving=args.moving_obstacles,
        moved=args.moved_obstacles,
    )
    if not session.lasers:
        raise InputError(f"{args.data}: the session has no lasers; add ?lasers=true")
    map_r, loc_r = split_laps(np.asarray(session.laps), args.laps, args.loc_laps)
    result = run_mbaram(
        [laser_frames(session, a, b) for a, b in map_r],
        [laser_frames(session, a, b) for a, b in loc_r],
        params,
        odometry=args.odometry,
        mapper=args.mapper,
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    metrics = {
        **result.metrics,
        "data": args.data,
        "seed": args.seed,
        "moving_obstacles": args.moving_obstacles,
        "moved_obstacles": args.moved_obstacles,
        "preset": args.preset,
        "laps": len(map_r),
        "loc_laps": len(loc_r),
        "paper": PAPER,
    }
    atomic_write_text(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    state = result.model.get_state()
    arrays: dict[str, Any] = {
        k.replace("/", "__"): np.asarray(v) for k, v in state.items() if k != "params"
    }
    tmp = out / ".state.tmp.npz"
    np.savez(tmp, **arrays, node_xy=result.node_xy)
    os.replace(tmp, out / "state.npz")
    if not args.no_plots:
        plot_results(result, session, out)
    m = result.metrics
    print(
        f"MBARAM {args.data}: {m['nodes']} nodes, {m['edges']} edges, nodes per lap "
        f"{m['nodes_per_lap']}, QE {m['qe']:.3f} ({m['qe_m']:.2f} m), CR {m['cr']:.0f}:1, "
        f"localisation {100 * m['localisation_rate_with_odometry']:.1f}% with odometry, "
        f"{100 * m['localisation_rate_without_odometry']:.1f}% without -> {out}"
    )
    return 0
