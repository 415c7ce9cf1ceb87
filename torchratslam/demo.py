"""``python -m torchratslam.demo --out DIR``: the project's demo (``make demo``).

For now it runs the pose-cell demo (:mod:`torchratslam.demo_pose_cells`) and writes
``DIR/pose_cells.png``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import torch

from torchratslam.demo_pose_cells import run_pose_cell_demo


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m torchratslam.demo", description=__doc__)
    parser.add_argument(
        "--out", type=Path, default=Path("out"), help="output folder (default: out)"
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    path = run_pose_cell_demo(args.out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
