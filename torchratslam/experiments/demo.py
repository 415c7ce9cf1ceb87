"""``python -m torchratslam.experiments.demo --out DIR``: the project's demo (``make demo``).

1. The pose-cell demo (:mod:`torchratslam.experiments.pose_cell_demo`): ``DIR/pose_cells.png``.
2. The multisession experiment on the simulated virtual tour (the multisession paper's
   Section 4.1): ``torchratslam multisession --tour sim:virtual_tour --ablation
   --backends alpha,gtsam``, writing the Fig. 9-style maps, the ICP overlay, the
   ablation map and ``report.json`` / ``report.md`` (the metrics table) under
   ``DIR/multisession/``. About half a minute on one core.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import torch

from torchratslam.experiments.pose_cell_demo import run_pose_cell_demo


def run_multisession_demo(
    out_dir: Path, *, progress: bool = True, overrides: dict[str, str] | None = None
) -> Path:
    """Run the virtual-tour multisession experiment with the alpha and GTSAM backends.

    Args:
        out_dir: the demo's output folder; results go to ``out_dir/multisession``.
        progress: progress bars.
        overrides: flat config keys replaced in the tour's config (e.g.
            ``{"behaviour": "torchratslam"}``).

    Returns:
        The path of the written ``report.md``.
    """
    from torchratslam.experiments.multisession_report import report_markdown
    from torchratslam.experiments.multisession_tour import MultisessionOptions, run_experiment

    out = Path(out_dir) / "multisession"
    result = run_experiment(
        None,
        "sim:virtual_tour",
        out,
        MultisessionOptions(
            ablation=True,
            backends=("alpha", "gtsam"),
            progress=progress,
            overrides=overrides or {},
        ),
        overwrite=True,  # the demo's own folder: `make demo` again replaces its last run
    )
    print(report_markdown(result["report"]))
    return out / "report.md"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog="python -m torchratslam.experiments.demo", description=__doc__
    )
    parser.add_argument(
        "--out", type=Path, default=Path("out"), help="output folder (default: out)"
    )
    parser.add_argument("--skip-multisession", action="store_true", help="only the pose-cell demo")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config key of the multisession run (repeatable)",
    )
    args = parser.parse_args(argv)
    bad = [s for s in args.set if "=" not in s]
    if bad:
        parser.error(f"--set needs KEY=VALUE, got {bad[0]!r}")
    overrides = dict(s.split("=", 1) for s in args.set)
    torch.set_num_threads(1)
    path = run_pose_cell_demo(args.out)
    print(f"wrote {path}")
    if not args.skip_multisession:
        t0 = time.perf_counter()
        report = run_multisession_demo(args.out, progress=not args.quiet, overrides=overrides)
        print(f"wrote {report.parent} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
