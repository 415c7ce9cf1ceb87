"""OpenRatSLAM's C++ next to torchratslam: datasets, runs, golden traces.

Shared by ``bench_openratslam.py`` (the side-by-side table of ``make bench``) and the
golden traces of ``tests/data/openratslam/`` (``python -m benchmarks.openratslam traces``).

The C++ is OpenRatSLAM's three core classes (local view, pose cells, experience map)
built unmodified, without ROS, with a synchronous driver (``ratslam_driver``) that wires
them as the ROS nodes do; this project does not ship it. Point ``OPENRATSLAM_BUILD`` at
a folder holding ``ratslam_driver`` (``make bench OPENRATSLAM_BUILD=/path``); without it
``build/openratslam`` under the repository root is tried. :data:`BUILD_HELP` says how to
build it.

Usage:
    python -m benchmarks.openratslam traces [--out tests/data/openratslam]
        (re)writes the golden traces (needs the build; renders the datasets into a
        temporary folder first).
    python -m benchmarks.openratslam long-traces [--out tests/data/openratslam]
        the same for the long sequences of the default's frame-for-frame guard.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import tempfile
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TRACES = ROOT / "tests" / "data" / "openratslam"

BUILD_HELP = """\
OpenRatSLAM's C++ build was not found. Build it (once) and point OPENRATSLAM_BUILD at it:
  1. apt-get install g++ libboost-dev libopencv-imgcodecs-dev
  2. git clone https://github.com/davidmball/ratslam  (its src/ratslam, unmodified)
  3. build its three core classes with a synchronous driver writing frames.csv,
     experiences.csv, links.csv and summary.txt (the side-by-side tools' build.sh
     SOURCE BUILD_DIR does this, -O3)
  4. make bench OPENRATSLAM_BUILD=BUILD_DIR   (the folder holding ratslam_driver)"""

LOOP_TXT = """\
; the project's simulated loop (sim:loop) with the parameters of the OpenRatSLAM comparison
[general]
[ratslam]
template_x_size=64
template_y_size=16
vt_panoramic=1
vt_shift_match=4
vt_step_match=1
vt_match_threshold={threshold}
pc_dim_xy=21
pc_cell_x_size=0.25
pc_vt_inject_energy=0.1
exp_delta_pc_threshold=2
exp_loops=20
"""

IRAT_TXT = """\
; OpenRatSLAM's config_irat.txt values (image crop left at the image) for sim:irat_like
[general]
[ratslam]
template_x_size=60
template_y_size=20
vt_shift_match=4
vt_step_match=1
vt_match_threshold=0.03
vt_active_decay=1.0
pc_dim_xy=11
pc_vt_inject_energy=0.1
pc_cell_x_size=0.015
exp_delta_pc_threshold=2
exp_loops=20
exp_initial_em_deg=140
"""


@dataclass(frozen=True)
class Dataset:
    """A simulated dataset and the OpenRatSLAM config it runs with.

    Attributes:
        name: folder name.
        spec: the ``sim:`` spec (``torchratslam simulate SPEC`` writes it).
        config: the OpenRatSLAM ``.txt`` config.
        frames: the first this many frames (None: all).
        about: what it exercises.
    """

    name: str
    spec: str
    config: str
    frames: int | None
    about: str


TRACE_SETS = (
    Dataset(
        "loop",
        "sim:loop",
        LOOP_TXT.format(threshold=0.06),
        600,
        "the corridor loop, two laps: many loop closures",
    ),
    Dataset(
        "turns",
        "sim:irat_like/continuous?hz=3",
        IRAT_TXT,
        None,
        "the iRat-scale road network at 3 Hz: turns of up to 62 degrees a frame; the "
        "packet crosses the pose-cell wrap in x, y and theta many times",
    ),
    Dataset(
        "templates",
        "sim:loop",
        LOOP_TXT.format(threshold=0.015),
        600,
        "the corridor loop with a strict match threshold: more than 500 templates",
    ),
)

#: Long end-to-end sequences for the frame-for-frame guard of the default
#: (``tests/torchratslam/test_openratslam_long_traces.py``): many near-ties, so a run whose
#: decisions are not the C++'s own (float32's rounding, a reordered sum) parts from the
#: trace. Written compactly (:data:`LONG_TRACE_COLUMNS`, gzip).
LONG_TRACE_SETS = (
    Dataset(
        "loop_30_laps",
        "sim:loop?seed=11&laps=30",
        LOOP_TXT.format(threshold=0.06),
        None,
        "a corridor loop (seed 11) driven 30 times: hundreds of loop closures onto the same "
        "experiences, the packet passing them again and again near the creation threshold",
    ),
    Dataset(
        "figure_eight",
        "sim:bicocca_like?seed=5",
        LOOP_TXT.format(threshold=0.06),
        None,
        "two ring corridors joined by a passage driven both ways (a figure of eight, seed 5): "
        "the passage re-seen in the other direction, templates of both rings alike",
    ),
)

BENCH_SETS = (
    Dataset("loop tour", "sim:loop", LOOP_TXT.format(threshold=0.06), None, "1781 frames"),
    Dataset(
        "loop tour, lit differently each lap",
        "sim:loop?illumination=0.3&illumination_mode=lap",
        LOOP_TXT.format(threshold=0.02),
        None,
        "1781 frames, 1000+ templates",
    ),
)


def find_build() -> Path | None:
    """The folder holding ``ratslam_driver``: ``$OPENRATSLAM_BUILD``, else
    ``build/openratslam`` under the repository root; None if neither has it."""
    env = os.environ.get("OPENRATSLAM_BUILD", "").strip()
    for cand in ([Path(env)] if env else []) + [ROOT / "build" / "openratslam"]:
        if (cand / "ratslam_driver").is_file() and os.access(cand / "ratslam_driver", os.X_OK):
            return cand
    return None


def write_dataset_dir(ds: Dataset, out: Path) -> Path:
    """Render ``ds`` into ``out`` (frames/, odometry.csv, groundtruth.csv) and the config."""
    from torchratslam.sim import open_sim, write_dataset

    session = open_sim(ds.spec)
    if ds.frames is not None:
        session = session.subset(0, ds.frames)
    write_dataset(session, out, progress=False)
    (out / "config.txt").write_text(ds.config)
    return out


def run_cpp(build: Path, data: Path, out: Path) -> dict:
    """Run ``ratslam_driver`` on a dataset folder; returns its summary (key -> float)."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "stdout.log", "w") as log:
        subprocess.run(
            [str(build / "ratslam_driver"), str(data / "config.txt"), str(data), str(out)],
            check=True,
            stdout=log,
            stderr=subprocess.DEVNULL,
        )
    summary = {}
    for line in (out / "summary.txt").read_text().splitlines():
        k, _, v = line.partition("=")
        summary[k] = float(v)
    summary["total_ms_median"] = float(np.median(read_csv(out / "frames.csv")["total_ms"]))
    return summary


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """A numeric CSV with a header as ``{column: float64 array}``."""
    with open(path) as f:
        head = f.readline().strip().split(",")
    a = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {k: a[:, i] for i, k in enumerate(head)}


def load_frames(data: Path) -> list:
    """Every frame of a dataset folder, images decoded (before any timing)."""
    from torchratslam.readers import open_data

    return list(open_data(str(data)).frames())


def run_py(config: Path, frames: list, behaviour: str, dtype: str | None = None) -> dict:
    """torchratslam's pipeline on decoded frames (one thread); per-frame module times,
    the loop's wall time and its process CPU time. ``dtype`` None: the config's (double,
    OpenRatSLAM's, unless the config says otherwise)."""
    import torch

    from torchratslam.config import load_config
    from torchratslam.pipeline import RatSLAM

    torch.set_num_threads(1)
    slam = RatSLAM(
        load_config(config, behaviour=behaviour),
        dtype=None if dtype is None else getattr(torch, dtype),
    )
    t0, c0 = time.perf_counter(), time.process_time()
    res = slam.run(frames, progress=False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = res.timings
    return {
        "wall_s": wall,
        "cpu_s": cpu,
        "lv": s["local_view"]["mean_ms"],
        "pc": s["pose_cells"]["mean_ms"],
        "em": s["experience_map"]["mean_ms"],
        "odo": s["odometry"]["mean_ms"],
        "total": s["total"]["mean_ms"],
        "total_median": s["total"]["median_ms"],
        "templates": res.templates,
        "experiences": res.experiences,
        "links": res.links,
        "ate": slam.ate(),
        "slam": slam,
    }


# ----------------------------------------------------------------------------- traces
TRACE_COLUMNS = (
    "frame",
    "vt_id",
    "vt_rad",
    "action",
    "src_exp_id",
    "current_exp_id",
    "em_current_id",
    "rel_rad",
    "pc_x",
    "pc_y",
    "pc_th",
)


#: The per-frame columns of a long trace (:data:`LONG_TRACE_SETS`): the decisions only.
LONG_TRACE_COLUMNS = ("frame", "vt_id", "action", "src_exp_id", "current_exp_id", "em_current_id")


def write_trace(
    ds: Dataset, data: Path, cpp: Path, dest: Path, columns: tuple[str, ...] = TRACE_COLUMNS
) -> dict:
    """Copy one C++ run into ``dest`` as golden trace files.

    ``frames.csv``: per frame the odometry row the C++ read (``t, vtrans, vrot`` as
    written in ``odometry.csv``), the CRC-32 of the frame's pixels and the C++'s
    per-frame outputs (``columns``, as the C++ printed them: 17 significant digits);
    ``frames.csv.gz`` instead when ``columns`` is :data:`LONG_TRACE_COLUMNS`;
    ``experiences.csv`` and ``links.csv``: the C++'s final map, as it wrote them.
    """
    import gzip

    import cv2

    dest.mkdir(parents=True, exist_ok=True)
    with open(data / "odometry.csv") as f:
        odo = list(csv.DictReader(f))
    with open(cpp / "frames.csv") as f:
        rows = list(csv.DictReader(f))
    pngs = sorted((data / "frames").glob("*.png"))
    compact = columns == LONG_TRACE_COLUMNS
    path = dest / ("frames.csv.gz" if compact else "frames.csv")
    opener = gzip.open(path, "wt", newline="") if compact else open(path, "w", newline="")
    with opener as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["t", "vtrans", "vrot", "crc32", *columns])
        for k, r in enumerate(rows):
            img = cv2.imread(str(pngs[k]), cv2.IMREAD_UNCHANGED)
            crc = zlib.crc32(np.ascontiguousarray(img).tobytes())
            o = odo[k]
            w.writerow([o["t"], o["vtrans"], o["vrot"], crc, *(r[c] for c in columns)])
    for name in ("experiences.csv", "links.csv"):
        shutil.copyfile(cpp / name, dest / name)
    (dest / "config.txt").write_text(ds.config)
    summary = dict(line.split("=", 1) for line in (cpp / "summary.txt").read_text().splitlines())
    meta = {
        "spec": ds.spec,
        "frames": len(rows),
        "about": ds.about,
        "templates": int(summary["templates"]),
        "experiences": int(summary["experiences"]),
        "links": int(summary["links"]),
    }
    (dest / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    return meta


def make_traces(build: Path, out: Path, long: bool = False) -> None:
    """Render every :data:`TRACE_SETS` dataset (:data:`LONG_TRACE_SETS` with ``long``),
    run the C++ on it, write its trace."""
    sets, columns = (LONG_TRACE_SETS, LONG_TRACE_COLUMNS) if long else (TRACE_SETS, TRACE_COLUMNS)
    with tempfile.TemporaryDirectory() as tmp:
        for ds in sets:
            data = write_dataset_dir(ds, Path(tmp) / ds.name)
            cpp = Path(tmp) / f"{ds.name}_cpp"
            run_cpp(build, data, cpp)
            meta = write_trace(ds, data, cpp, out / ds.name, columns)
            print(f"{ds.name}: {meta}")


def main() -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.openratslam")
    ap.add_argument("what", choices=("traces", "long-traces"))
    ap.add_argument("--out", type=Path, default=TRACES)
    a = ap.parse_args()
    build = find_build()
    if build is None:
        raise SystemExit(BUILD_HELP)
    make_traces(build, a.out, long=a.what == "long-traces")


if __name__ == "__main__":
    main()
