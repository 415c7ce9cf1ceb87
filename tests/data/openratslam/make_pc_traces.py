"""Regenerate the pose-cell traces in this folder from OpenRatSLAM's own PosecellNetwork.

usage: python tests/data/openratslam/make_pc_traces.py PC_REPLAY [NAME ...]

PC_REPLAY: the ``pc_replay`` binary built by ``shared/tools/openratslam/build.sh``
(OpenRatSLAM's unmodified ``posecell_network.cpp`` driven by a CSV). For every trace
below: the project's simulator renders the tour, torchratslam's local view turns the
frames into (template id, relative angle) per frame (identical to OpenRatSLAM's local
view on these tours), the odometry comes from the tour (optionally scaled, to make fast
turns and moves across the wrap), ``pc_replay`` runs OpenRatSLAM's pose cells on that
sequence, and ``NAME.csv`` gets the inputs and OpenRatSLAM's outputs per frame,
``NAME.txt`` the OpenRatSLAM config. Not run by the tests (they only read the CSVs).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

from torchratslam.config import load_config
from torchratslam.pipeline import RatSLAM
from torchratslam.readers import open_data

HERE = Path(__file__).resolve().parent

PC_KEYS = (
    "pc_dim_xy",
    "pc_dim_th",
    "pc_w_e_dim",
    "pc_w_i_dim",
    "pc_w_e_var",
    "pc_w_i_var",
    "pc_global_inhib",
    "vt_active_decay",
    "pc_vt_inject_energy",
    "pc_cell_x_size",
    "exp_delta_pc_threshold",
    "pc_vt_restore",
)

#: name: (tour spec, config preset, frames, pose-cell overrides, vtrans scale, vrot scale)
TRACES = {
    # 11 x 11 cells of 1.5 cm: the packet crosses the x/y wrap all the time
    "irat_like": ("sim:irat_like", "irat", 400, {}, 1.0, 1.0),
    # OpenRatSLAM's default 21 x 21 x 36 network on the loop tour
    "loop_default": (
        "sim:loop",
        "lab_tour",
        400,
        {
            "pc_dim_xy": 21,
            "pc_dim_th": 36,
            "pc_cell_x_size": 0.25,
            "pc_vt_inject_energy": 0.15,
            "exp_delta_pc_threshold": 2.0,
        },
        1.0,
        1.0,
    ),
    # fast turns (5x the tour's turn rate: up to several theta cells a step, across the
    # theta wrap) and moves across the x/y wrap on a small network
    "fast_turns": (
        "sim:lab_tour",
        "lab_tour",
        300,
        {
            "pc_dim_xy": 15,
            "pc_dim_th": 36,
            "pc_cell_x_size": 0.1,
            "pc_vt_inject_energy": 0.3,
            "exp_delta_pc_threshold": 2.0,
        },
        1.0,
        5.0,
    ),
}


def templates(spec: str, preset: str, frames: int) -> tuple[np.ndarray, ...]:
    """(t, vtrans, vrot, template id, relative angle) per frame from torchratslam's
    local view (float64)."""
    cfg = load_config(preset)
    data = list(open_data(spec).frames())[:frames]
    slam = RatSLAM(cfg, dtype=torch.float64)
    ids, rads = [], []
    slam.run(
        data,
        progress=False,
        callback=lambda r: (
            ids.append(int(r.view.template_id)),
            rads.append(float(r.view.relative_rad)),
        ),
    )
    t = np.array([float(f.t) for f in data])
    vt = np.array([float(f.vtrans) for f in data])
    vr = np.array([float(f.vrot) for f in data])
    return t, vt, vr, np.array(ids), np.array(rads)


def _read(path: Path) -> dict[str, np.ndarray]:
    with open(path) as f:
        head = f.readline().strip().split(",")
    a = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {c: [float(x) for x in a[:, i]] for i, c in enumerate(head)}


def main() -> None:
    exe = sys.argv[1]
    names = sys.argv[2:] or list(TRACES)
    for name in names:
        spec, preset, frames, over, s_tr, s_rot = TRACES[name]
        t, vt, vr, ids, rads = templates(spec, preset, frames)
        cfg = load_config(preset, **over).pose_cells
        txt = HERE / f"{name}.txt"
        # OpenRatSLAM reads the kernel variances as int
        vals = {k: getattr(cfg, k) for k in PC_KEYS}
        for k in ("pc_w_e_var", "pc_w_i_var"):
            assert float(vals[k]).is_integer(), f"OpenRatSLAM needs an integer {k}"
            vals[k] = int(vals[k])
        txt.write_text("[ratslam]\n" + "".join(f"{k}={v!r}\n" for k, v in vals.items()))
        dt = np.diff(t, prepend=t[0])
        with tempfile.TemporaryDirectory() as tmp:
            steps = Path(tmp) / "input.csv"
            with open(steps, "w") as f:
                f.write("frame,vt_id,vt_rad,vtrans,vrot,dt\n")
                for k in range(len(t)):
                    f.write(
                        f"{k},{ids[k]},{float(rads[k])!r},{float(vt[k] * s_tr)!r},"
                        f"{float(vr[k] * s_rot)!r},{float(dt[k])!r}\n"
                    )
            subprocess.run([exe, str(txt), str(steps), tmp], check=True)
            out = _read(Path(tmp) / "steps.csv")
            inp = _read(steps)
        with open(HERE / f"{name}.csv", "w") as f:
            f.write("frame,vt_id,vt_rad,vtrans,vrot,dt,pc_x,pc_y,pc_th,action,current_exp_id\n")
            for k in range(len(t)):
                i = {c: v[k] for c, v in inp.items()}
                o = {c: v[k] for c, v in out.items()}
                f.write(
                    f"{int(i['frame'])},{int(i['vt_id'])},{i['vt_rad']!r},{i['vtrans']!r},"
                    f"{i['vrot']!r},{i['dt']!r},{o['pc_x']!r},{o['pc_y']!r},{o['pc_th']!r},"
                    f"{int(o['action'])},{int(o['current_exp_id'])}\n"
                )
        print(
            name,
            "templates",
            ids.max() + 1,
            "actions",
            np.bincount(np.array(out["action"], dtype=int)),
        )


if __name__ == "__main__":
    main()
