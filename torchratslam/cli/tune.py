"""``torchratslam tune``: Optuna searches parameters within ranges to minimise a metric."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from torchratslam.cli.sweep import add_execution_args

DESCRIPTION = """Tune parameters with Optuna (pip install 'torchratslam[tune]').

Each trial runs the config with suggested values on every --data (and seed) and scores
the mean of --metric (ATE against ground truth by default), plus --map-penalty per
experience; --max-experiences is a constraint. Default: the loop tour of the simulator,
the virtual_tour config and four parameters (vt_match_threshold, pc_vt_inject_energy,
exp_delta_pc_threshold, vt_active_decay).

OUT receives best.yaml (a ready config: torchratslam run --config OUT/best.yaml),
history.csv (one row per trial), optimization_history.png, param_importances.png and
the study's storage (study.journal) so that --resume continues it and several
processes can share it (--storage)."""

EPILOG = """examples:
  torchratslam tune --out out/tune --trials 24
  torchratslam tune --out out/tune --param vt_match_threshold=0.02:0.1 \\
      --param pc_vt_inject_energy=0.02:0.5:log --param exp_loops=5:100:int
  torchratslam tune --data sim:loop --data sim:virtual_tour --max-experiences 600 --out out/t
  torchratslam tune --out out/tune --resume --trials 40     # 40 trials in all
"""


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "tune",
        help="search parameters with Optuna to minimise ATE (or another metric)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", required=True, metavar="OUT", help="output folder, e.g. --out out/t")
    p.add_argument(
        "--config",
        default="virtual_tour",
        metavar="CONFIG",
        help="base config (preset name or path; default virtual_tour), e.g. --config lab_tour",
    )
    p.add_argument(
        "--data",
        action="append",
        default=[],
        metavar="DATA",
        help="dataset (repeatable; default sim:loop), e.g. --data sim:virtual_tour/session1",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=RANGE",
        help="searched parameter (repeatable): LOW:HIGH[:log][:int] or a,b,c, "
        "e.g. --param vt_match_threshold=0.02:0.1",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="fixed config key in every trial (repeatable), e.g. --set exp_loops=50",
    )
    p.add_argument(
        "--metric",
        default="ate_m",
        help="metric to minimise (a results-table column; default ate_m), e.g. --metric links",
    )
    p.add_argument(
        "--trials",
        type=int,
        default=20,
        help="finished trials the study should have (default 20), e.g. --trials 40",
    )
    p.add_argument(
        "--max-frames",
        type=int,
        default=None,
        metavar="N",
        help="frames per dataset, e.g. --max-frames 500",
    )
    p.add_argument(
        "--seeds", default="0", metavar="S,S", help="simulator seeds (default 0), e.g. --seeds 0,1"
    )
    p.add_argument(
        "--map-penalty",
        type=float,
        default=0.0,
        metavar="W",
        help="add W x experiences to the objective, e.g. --map-penalty 0.0001",
    )
    p.add_argument(
        "--max-experiences",
        type=int,
        default=None,
        metavar="N",
        help="constraint: trials with more experiences are infeasible, e.g. --max-experiences 800",
    )
    p.add_argument(
        "--storage",
        default=None,
        metavar="URL",
        help="Optuna storage shared by workers: a journal file or sqlite:///FILE "
        "(default OUT/study.journal), e.g. --storage sqlite:///studies.db",
    )
    p.add_argument(
        "--study-name",
        default="torchratslam",
        help="study name in the storage, e.g. --study-name loop",
    )
    p.add_argument("--seed", type=int, default=0, help="sampler seed (default 0), e.g. --seed 1")
    add_execution_args(p)
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the study in the storage; several processes may run the same "
        "command with --resume at once to share one study, "
        "e.g. --resume",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar, e.g. --no-progress")
    p.set_defaults(func=main)
    return p


def _pairs(items: list[str], flag: str) -> dict[str, str]:
    from torchratslam.errors import ConfigError

    out: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"{flag} {item!r}: expected KEY=VALUE, e.g. {flag} exp_loops=50")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def main(args: argparse.Namespace) -> int:
    from torchratslam.errors import InputError
    from torchratslam.sweeps import tune

    try:
        seeds = [int(s) for s in str(args.seeds).split(",") if s.strip()]
    except ValueError:
        raise InputError(f"--seeds: expected integers like 0,1, got {args.seeds!r}") from None
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    if args.max_frames is not None and args.max_frames < 1:
        raise InputError(f"--max-frames must be >= 1, got {args.max_frames}")
    params = _pairs(args.param, "--param") or None
    result = tune(
        args.data or "sim:loop",
        params,
        config=args.config,
        fixed=_pairs(args.set, "--set"),
        metric=args.metric,
        trials=args.trials,
        max_frames=args.max_frames,
        seeds=seeds or [0],
        map_penalty=args.map_penalty,
        max_experiences=args.max_experiences,
        out=Path(args.out),
        storage=args.storage,
        study_name=args.study_name,
        resume=args.resume,
        sampler_seed=args.seed,
        workers=args.workers,
        ray=args.ray,
        ray_address=args.ray_address,
        progress=not args.no_progress,
    )
    if result["best_value"] is None:
        print(f"no trial finished successfully; see {Path(args.out) / 'history.csv'}")
        return 1
    values = ", ".join(
        f"{k}={v:.4g}" if isinstance(v, float) and math.isfinite(v) else f"{k}={v}"
        for k, v in result["best_params"].items()
    )
    base = result.get("baseline_value")
    vs = f" (the base config's: {base:.4f})" if base is not None else ""
    if str(args.metric).startswith("ate"):  # which ATE: as each run's metrics.json
        vs += "; ATE SE(2)-aligned over the frames with ground truth"
    print(
        f"best {args.metric} {result['best_value']:.4f}{vs} in trial {result['best_trial']} "
        f"of {result['trials']}: {values}; wrote {Path(args.out) / 'best.yaml'}"
    )
    return 0
