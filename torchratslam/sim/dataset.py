"""``sim:`` data specs and dataset directories written from simulated sessions.

A spec names a tour, optionally a session and options::

    sim:loop                      the whole tour (Tour.full(): sessions concatenated)
    sim:virtual_tour/session2     one session (also /2, or /full)
    sim:virtual_tour/continuous   every session in one continuous run (Tour.continuous())
    sim:loop?laps=2&lasers=0      options of get_tour (values parsed as YAML scalars)
    sim:lab_tour/session1?seed=3

A dataset directory (the reader format) holds::

    frames/000000.png ...         uint8 grey images
    odometry.csv                  t,vtrans,vrot      (header line; m/s, rad/s)
    groundtruth.csv               t,x,y,theta        (header line; m, m, rad)
    scans.npz                     laser_front, laser_rear: (T, N) float32 (when lasers are on)
    meta.json                     tour, session, seed, options, camera, frame count, ...
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl

import numpy as np
import yaml

from torchratslam.errors import InputError, option
from torchratslam.sim.session import Session
from torchratslam.sim.tours import TOURS, get_tour

__all__ = ["FORMAT_VERSION", "open_sim", "parse_sim_spec", "write_dataset"]

FORMAT_VERSION = 1

log = logging.getLogger(__name__)


def parse_sim_spec(spec: str) -> tuple[str, str | None, dict]:
    """Split ``sim:NAME[/SESSION][?key=value&...]`` into (name, session, options).

    Raises:
        InputError: not a ``sim:`` spec, or an unknown tour.
    """
    if not isinstance(spec, str) or not spec.startswith("sim:"):
        raise InputError(
            f"{spec!r} is not a simulator spec; write sim:NAME (tours: {', '.join(TOURS)})"
        )
    body = spec[4:]
    query = ""
    if "?" in body:
        body, query = body.split("?", 1)
    name, _, session = body.partition("/")
    if name not in TOURS:
        from ratslam_graph.errors import unknown_name_message

        raise InputError(unknown_name_message("simulator tour", name, TOURS) + f" in {spec!r}")
    options = {}
    for key, value in parse_qsl(query, keep_blank_values=True):
        try:
            options[key] = yaml.safe_load(value) if value != "" else True
        except yaml.YAMLError as exc:
            raise InputError(f"option {key}={value!r} in {spec!r} is not a scalar") from exc
    return name, session or None, options


def open_sim(spec: str) -> Session:
    """Resolve a ``sim:`` spec to a session (``sim:NAME`` gives ``Tour.full()``).

    Raises:
        InputError: unknown tour, session or option.
    """
    name, session, options = parse_sim_spec(spec)
    seed = options.pop("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise InputError(f"seed={seed!r} in {spec!r} must be an integer")
    tour = get_tour(name, seed=seed, **options)
    if session is None or session == "full":
        return tour.full()
    if session.isdigit():
        return tour.session(int(session))
    return tour.session(session)


def _camera_meta(session: Session) -> dict:
    cam = session.camera
    return {
        "kind": cam.kind,
        "width": cam.width,
        "height": cam.height,
        "fov_deg": 360.0 if cam.kind == "panoramic" else cam.fov_deg,
        "cam_height": cam.cam_height,
        "columns": "column 0 = heading, counter-clockwise"
        if cam.kind == "panoramic"
        else "left to right",
    }


def _remove_stale_temps(out: Path) -> None:
    """Remove the hidden temp folders (``.NAME.new-PID-RANDOM``) that an earlier
    ``write_dataset`` into ``out`` left when it was killed (its process is gone), saying
    so; a live writer's folder is left alone."""
    import re
    import shutil

    pattern = re.compile(rf"^\.{re.escape(out.name)}\.new-(\d+)-[0-9a-f]+$")
    if not out.parent.is_dir():
        return
    for entry in sorted(out.parent.iterdir()):
        m = pattern.match(entry.name)
        if m is None or not entry.is_dir() or _alive(int(m.group(1))):
            continue
        size = sum(f.stat().st_size for f in entry.rglob("*") if f.is_file())
        shutil.rmtree(entry, ignore_errors=True)
        log.warning(
            "removed %s (%.1f MB), left by a simulate into %s that was stopped",
            entry,
            size / 1e6,
            out,
        )


def _alive(pid: int) -> bool:
    import os

    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # another user's process: alive
    return True


def write_dataset(
    session: Session, out_dir: str | os.PathLike, *, overwrite: bool = False, progress: bool = False
) -> Path:
    """Write a session as a dataset directory in the reader format (see module docstring).

    The directory is written under a temporary name and renamed into place, so a
    half-written dataset never appears; an existing non-empty directory is only
    replaced with ``overwrite=True``.

    Args:
        session: the session (e.g. ``get_tour("loop").full()`` or ``open_sim(...)``).
        out_dir: the dataset directory to create.
        overwrite: replace an existing non-empty directory.
        progress: show a tqdm progress bar.

    Returns:
        The dataset directory.

    Raises:
        InputError: ``out_dir`` exists, is not empty, and ``overwrite`` is False.
    """
    from ratslam_graph.atomic import Manifest, make_dirs, swap_in, unique_name

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(
            f"{out} exists and is not a directory; choose another {option('--out', 'out_dir')}"
        )
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise InputError(
                f"{out} exists and is not empty; choose another {option('--out', 'out_dir')} "
                f"or pass {option('--overwrite', 'overwrite=True')}"
            )
        # --overwrite replaces only a directory this project wrote (its manifest)
        Manifest(out).check_overwrite("overwrite it")
    make_dirs(out.parent)
    _remove_stale_temps(out)
    tmp = unique_name(out, "new")
    tmp.mkdir()
    try:
        (tmp / "frames").mkdir()
        import cv2  # only writing frames needs it

        n = len(session)
        scans: dict[str, list[np.ndarray]] = {k: [] for k in session.lasers}
        it = range(n)
        if progress:
            from tqdm import tqdm

            it = tqdm(it, desc=f"{session.tour}/{session.name}", unit="frame")
        for k in it:
            if not cv2.imwrite(str(tmp / "frames" / f"{k:06d}.png"), session.render(k)):
                raise OSError(f"could not write frame {k} under {tmp}")
            for name, r in session.scans(k).items():
                scans[name].append(r)
        odo = np.column_stack([session.times, session.odometry[:, 0], session.odometry[:, 1]])
        np.savetxt(
            tmp / "odometry.csv",
            odo,
            delimiter=",",
            header="t,vtrans,vrot",
            comments="",
            fmt="%.9g",
        )
        np.savetxt(
            tmp / "groundtruth.csv",
            session.groundtruth(),
            delimiter=",",
            header="t,x,y,theta",
            comments="",
            fmt="%.9g",
        )
        if scans:
            stacked: dict[str, Any] = {k: np.stack(v) for k, v in scans.items()}
            np.savez_compressed(tmp / "scans.npz", **stacked)
        meta = {
            "format": "torchratslam-dataset",
            "version": FORMAT_VERSION,
            "source": "torchratslam.sim",
            "tour": session.tour,
            "session": session.name,
            "n_frames": n,
            **session.info,
            "frames": "frames/{:06d}.png",
            "camera_hz": float(1.0 / np.median(session.odometry[1:, 2])) if n > 1 else None,
            "camera": _camera_meta(session),
            "lasers": {
                k: {
                    "n_beams": v.n_beams,
                    "fov_deg": v.fov_deg,
                    "max_range": v.max_range,
                    "mount_angle_deg": v.mount_angle_deg,
                }
                for k, v in session.lasers.items()
            },
            "kidnaps": [int(i) for i in np.flatnonzero(session.odometry[1:, 2] == 0) + 1],
        }
        (tmp / "meta.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
        Manifest(tmp).add(p.name for p in tmp.iterdir())
        swap_in(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
