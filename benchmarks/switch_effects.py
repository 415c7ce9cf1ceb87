"""What each behaviour switch changes, measured against OpenRatSLAM's golden traces.

usage: python -m benchmarks.switch_effects [NAME ...]   (default: every trace set)

For each trace set of ``tests/data/openratslam`` (the frames re-rendered by the
simulator, the odometry the C++ read), torchratslam runs in float64 with the
"openratslam" profile, then with each behaviour switch of :data:`SWITCHES` flipped alone
to its other value, then with the "torchratslam" (recommended) profile and with every
switch flipped at once. Columns:
frames whose action differs from the C++'s, the first such frame, experiences and links,
ATE over frames >= 1 (m; the final pose of each frame's experience against the
simulator's ground truth, rigid alignment), and the largest distance between the final
map and the C++'s when every action agrees. No C++ build is needed (the traces hold its
output). docs/openratslam-fidelity.md quotes this table.
"""

from __future__ import annotations

import sys

import numpy as np

#: Every behaviour switch at its value other than OpenRatSLAM's (the keys of
#: :data:`torchratslam.config.RECOMMENDED` and the choices measured and left out of it).
SWITCHES: dict[str, object] = {
    "pc_decode": "exact",
    "vt_inject_rule": "last_10",
    "pc_axis": "math",
    "pc_wrap": "preserve_mass",
    "pc_multi_cell": True,
    "pc_engine": "torch",
    "skip_first_odometry": False,
    "action_angle": "view",
    "exp_relax": "every_frame",
    "exp_first_at_origin": True,
    "exp_link_time": "per_link",
    "exp_relax_order": "colour",
}


def _rows() -> list[tuple[str, dict]]:
    rows: list[tuple[str, dict]] = [("openratslam profile", {"behaviour": "openratslam"})]
    for key, value in SWITCHES.items():
        change = {"behaviour": "openratslam", key: value}
        label = f"{key}={value}"
        if key == "pc_multi_cell":  # only defined with the mass-preserving wrap
            change["pc_wrap"] = "preserve_mass"
            label += " (+ pc_wrap=preserve_mass)"
        rows.append((label, change))
    rows.append(("torchratslam profile", {"behaviour": "torchratslam"}))
    rows.append(("every switch flipped", {"behaviour": "openratslam", **SWITCHES}))
    return rows


def effects(name: str) -> list[dict]:
    """One dict per row of :func:`_rows` for trace set ``name``."""
    import torch

    sys.path.insert(0, "tests/torchratslam")
    import test_openratslam_traces as T  # type: ignore[import-not-found]  # the traces' loaders

    from torchratslam.config import load_config
    from torchratslam.eval.metrics import ate_rmse
    from torchratslam.pipeline import RatSLAM
    from torchratslam.sim import open_sim

    torch.set_num_threads(1)
    tr = T.trace(name)
    f = tr["f"]
    frames = T.frames(name)
    gt = np.asarray(open_sim(tr["meta"]["spec"]).poses)[: len(frames), :2]
    cpp = tr["exps"][:, 1:3]
    out = []
    for label, change in _rows():
        slam = RatSLAM(load_config(tr["config"], **change), dtype=torch.float64)
        steps: list = []
        slam.run(frames, progress=False, callback=steps.append)
        acts = np.array([int(r.action.kind) for r in steps])
        diff = np.nonzero(acts != f["action"])[0]
        traj = slam.trajectory()
        ok = np.isfinite(traj[:, 3]) & (traj[:, 0] >= 1)
        poses = np.asarray(slam.experience_map.poses)
        same = diff.size == 0 and len(poses) == len(cpp)
        out.append(
            {
                "row": label,
                "actions_differing": int(diff.size),
                "first": int(diff[0]) if diff.size else None,
                "experiences": len(poses),
                "links": int(slam.experience_map.num_links),
                "ate": float(ate_rmse(traj[ok, 3:5], gt[traj[ok, 0].astype(int)])),
                "max_dxy": float(np.hypot(*(poses[:, :2] - cpp).T).max()) if same else None,
            }
        )
    return out


def main() -> None:
    names = sys.argv[1:] or ["loop", "turns", "templates"]
    for name in names:
        print(f"### {name}\n")
        print(
            "| run (float64) | actions differing (first) | experiences / links | ATE m | "
            "max distance to the C++ map m |"
        )
        print("|---|---|---|---|---|")
        for r in effects(name):
            first = f" ({r['first']})" if r["first"] is not None else ""
            dxy = f"{r['max_dxy']:.1e}" if r["max_dxy"] is not None else "-"
            print(
                f"| {r['row']} | {r['actions_differing']}{first} | {r['experiences']} / "
                f"{r['links']} | {r['ate']:.3f} | {dxy} |"
            )
        print(flush=True)


if __name__ == "__main__":
    main()
