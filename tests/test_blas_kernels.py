"""The same bits under every BLAS kernel and torch CPU kernel set this CPU runs.

numpy's OpenBLAS picks its kernels by CPU (``OPENBLAS_CORETYPE`` forces one) and torch
picks its vectorised kernels by CPU too (``ATEN_CPU_CAPABILITY``). No decision of the
default path rests on a BLAS call: the pose cells' convolution sums its taps in a fixed
order in compiled code, the template search and the relaxation are compiled loops. The
template errors are torch sums, whose order follows torch's vector width (the
``avx512`` variant, run where the CPU has AVX-512, checks that dependence). Each
variant below runs the OpenRatSLAM pose-cell traces (float32 and float64, the default
engine) and a short simulated run in a subprocess; every variant must give
OpenRatSLAM's actions in both dtypes and the same bits as every other variant (packet
centres, activity, templates, experience poses, ATE). The kernels tried: OpenBLAS's
Haswell (always), Sandybridge and Prescott cores where the CPU has AVX, SkylakeX where
it has AVX-512 and Zen on AMD; torch's ``default`` kernel set (no vector code), and
``avx2`` and ``avx512`` where the CPU has AVX-512 (``default`` adds as ``avx2`` does).
"""

from __future__ import annotations

import configparser
import hashlib
import json
import os
import platform
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
TRACES = ROOT / "tests" / "data" / "openratslam"
TRACE_NAMES = ("irat_like", "loop_default", "fast_turns")


def _cpu_flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    for line in text.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()


def _vendor() -> str:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return ""
    for line in text.splitlines():
        if line.startswith("vendor_id"):
            return line.split(":", 1)[1].strip()
    return ""


def variants() -> list[dict[str, str]]:
    """The kernel choices this CPU can run, as environment settings."""
    flags = _cpu_flags()
    out: list[dict[str, str]] = []
    if {"avx2", "fma"} <= flags:
        out.append({"OPENBLAS_CORETYPE": "Haswell"})
    if "avx" in flags:
        out.append({"OPENBLAS_CORETYPE": "Sandybridge"})
    out.append({"OPENBLAS_CORETYPE": "Prescott"})
    if "avx512f" in flags:
        out.append({"OPENBLAS_CORETYPE": "SkylakeX"})
    if _vendor() == "AuthenticAMD" and "avx2" in flags:
        out.append({"OPENBLAS_CORETYPE": "Zen"})
    out.append({"ATEN_CPU_CAPABILITY": "default"})
    if "avx512f" in flags:  # else avx2 is what the variants above run already
        out.append({"ATEN_CPU_CAPABILITY": "avx2"})
        out.append({"ATEN_CPU_CAPABILITY": "avx512"})
    return out


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def probe() -> dict[str, Any]:
    """What a variant computes: action mismatches against the traces, and digests."""
    import torch

    from ratslam_graph.geometry import ate_rmse
    from torchratslam.config import PoseCellParams, load_config
    from torchratslam.messages import ViewMatch
    from torchratslam.pipeline.ratslam import RatSLAM
    from torchratslam.pose_cells.stage import PoseCells
    from torchratslam.sim import get_tour

    torch.set_num_threads(1)
    out: dict[str, Any] = {}
    for name in TRACE_NAMES:
        cp = configparser.ConfigParser()
        cp.read(TRACES / f"{name}.txt")
        rows = np.loadtxt(TRACES / f"{name}.csv", delimiter=",", skiprows=1)
        for dtype in (torch.float32, torch.float64):
            params: dict[str, Any] = dict(cp["ratslam"])
            pc = PoseCells(PoseCellParams(**params), dtype=dtype)
            acts, centres = [], []
            for frame, vt, rad, v, w, dt in rows[:, :6]:
                pc.on_view_template(ViewMatch(template_id=int(vt), relative_rad=float(rad)))
                act = 0
                if frame > 0 and dt > 0:
                    act = int(pc.on_odometry(float(v), float(w), float(dt)).kind)
                acts.append(act)
                centres.append(pc.centre)
            key = f"{name}/{str(dtype).rsplit('.', 1)[-1]}"
            out[key + "/action_mismatches"] = int((np.array(acts) != rows[:, 9]).sum())
            out[key + "/bits"] = _digest(np.array(centres), pc.activity.numpy())
    frames = get_tour("lab_tour").full().frames()
    slam = RatSLAM(load_config("lab_tour"))
    slam.run(frames, max_frames=120, progress=False)
    poses = np.asarray(slam.experience_map.poses, dtype=np.float64)
    c, s = np.cos(0.3), np.sin(0.3)
    moved = poses[:, :2] @ np.array([[c, s], [-s, c]]) + np.sin(np.arange(len(poses)))[:, None]
    out["run/experiences"] = len(poses)
    out["run/bits"] = _digest(poses, slam.templates.numpy(), slam.activity.numpy())
    out["run/ate"] = ate_rmse(poses, moved).hex()
    return out


def _run(env: dict[str, str]) -> dict[str, Any]:
    full = {**os.environ, **env, "OPENBLAS_VERBOSE": "2", "OMP_NUM_THREADS": "1"}
    # run_path keeps tests/ off sys.path (its torchratslam/ folder would shadow the package)
    code = f"import runpy; runpy.run_path({__file__!r}, run_name='__main__')"
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=full,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, f"{env}: {done.stderr[-3000:]}"
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="x86-64 kernels")
def test_every_kernel_gives_the_openratslam_actions_and_the_same_bits():
    envs = variants()
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(_run, envs))
    for env, got in zip(envs, results, strict=True):
        for key, value in got.items():
            if key.endswith("action_mismatches"):
                assert value == 0, f"{env}: {key} = {value}"
        assert got["run/experiences"] > 5  # the run does make a map
    for env, got in zip(envs[1:], results[1:], strict=True):
        differ = sorted(k for k in got if got[k] != results[0][k])
        assert not differ, f"{env} against {envs[0]}: {differ}"


if __name__ == "__main__":
    print(json.dumps(probe()))
