"""What a run's fixed memory is made of: peak RSS after each import, in a fresh process.

Each step of :data:`STEPS` is imported cumulatively in one fresh interpreter and the
process's peak RSS (``VmHWM``) is read after it, so the difference between two rows is
what that import adds. The last step runs ``torchratslam run`` in the same process on
the first frames of a dataset (default: 3), with the peak read when its mapping starts,
when it ends, and around its figures; the heavy modules it left loaded are
listed (what a run imports that it may not use)::

    python -m benchmarks.bench_memory --data out/bench/suburb-20000 [--frames 3]

Without ``--data`` only the imports are measured.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

STEPS = (
    ("python", "pass"),
    ("numpy", "import numpy"),
    ("yaml", "import yaml"),
    ("torch", "import torch"),
    ("numba", "import numba"),
    (
        "numba's implementations",
        "from numba.core.registry import cpu_target; cpu_target.target_context.refresh()",
    ),
    ("cv2", "import cv2"),
    ("matplotlib.pyplot", "import matplotlib; matplotlib.use('Agg'); import matplotlib.pyplot"),
    ("networkx", "import networkx"),
    ("gtsam", "try:\n    import gtsam\nexcept ImportError:\n    pass"),
    ("torchratslam", "import torchratslam"),
    ("torchratslam.pipeline", "from torchratslam.pipeline import RatSLAM"),
    ("torchratslam.cli", "import torchratslam.cli"),
)
"""(label, statement) imported one after the other. "numba's implementations" is what
loading the first compiled kernel adds to ``import numba`` (numba's typing and lowering
registries, which import ``scipy.linalg`` for its BLAS); gtsam is loaded by the gtsam
backends only, networkx when a map's graph is read, matplotlib when a figure is
written, cv2 by the image readers."""

HEAVY = (
    "torch",
    "numba",
    "cv2",
    "matplotlib",
    "matplotlib.pyplot",
    "networkx",
    "gtsam",
    "scipy",
    "scipy.linalg",
    "PIL",
)

_PROBE = """
import json, sys
def hwm():
    for line in open('/proc/self/status'):
        if line.startswith('VmHWM:'):
            return int(line.split()[1]) / 1024.0
    return float('nan')
steps = json.loads(sys.argv[1])
rows = []
for label, stmt in steps:
    exec(stmt, {})
    rows.append((label, hwm()))
run = json.loads(sys.argv[2])
if run:
    from torchratslam.cli import main
    from torchratslam.pipeline import RatSLAM
    try:
        from torchratslam.experiments import run_outputs as ro
    except ImportError:
        ro = None
    def mark(obj, name, before, after):
        f = getattr(obj, name, None)
        if f is None:
            return
        def wrapped(*a, **k):
            rows.append((before, hwm()))
            out = f(*a, **k)
            rows.append((after, hwm()))
            return out
        setattr(obj, name, wrapped)
    mark(RatSLAM, 'run', 'run: set up', 'run: %s frames mapped' % sys.argv[3])
    if ro is not None:
        mark(ro, '_write_figures', 'run: outputs but figures', 'run: figures written')
    main(run)
    rows.append(('run: done', hwm()))
heavy = [m for m in json.loads(sys.argv[4]) if m in sys.modules]
print(json.dumps({'rows': rows, 'loaded': heavy}))
"""


def measure(
    steps: tuple[tuple[str, str], ...] = STEPS, data: Path | None = None, frames: int = 3
) -> dict:
    """Peak RSS (MiB) after each step (and after the run) in one fresh process."""
    run: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        if data is not None:
            run = ["run", "--data", str(data), "--out", tmp, "--no-progress", "--overwrite"]
            run += ["--max-frames", str(frames), "--set", "behaviour=openratslam"]
            if (data / "config.txt").exists():
                run += ["--config", str(data / "config.txt")]
        out = subprocess.run(
            [
                sys.executable,
                "-c",
                _PROBE,
                json.dumps(steps),
                json.dumps(run),
                str(frames),
                json.dumps(HEAVY),
            ],
            check=True,
            capture_output=True,
            text=True,
        )
    return json.loads(out.stdout.strip().splitlines()[-1])


def report(result: dict) -> str:
    lines = [f"{'step':<28} {'peak MiB':>9} {'added':>7}", "-" * 46]
    prev = 0.0
    for label, mib in result["rows"]:
        lines.append(f"{label:<28} {mib:9.1f} {mib - prev:7.1f}")
        prev = mib
    lines.append("heavy modules loaded at the end: " + ", ".join(result["loaded"]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=None, help="dataset for the short run")
    p.add_argument("--frames", type=int, default=3)
    p.add_argument(
        "--run-only",
        action="store_true",
        help="import only Python before the run (what the run itself loads)",
    )
    a = p.parse_args(argv)
    steps = STEPS[:1] if a.run_only else STEPS
    print(report(measure(steps, a.data, a.frames)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
