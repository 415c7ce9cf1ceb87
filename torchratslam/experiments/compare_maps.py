"""Comparing two saved maps as the multisession paper does (Figs. 10, 14, 16, 18): ICP
in the paper's convention and the project's, the rigid transform, ATE against ground
truth when there is one, and the overlay figure. ``torchratslam compare-maps`` is the
command-line front end.

Conventions, LibICP's: map A is the *template* (the paper's single-session map), the
map that **moves**; map B is the *model* (the paper's multisession map), fixed, the one
the nearest neighbours are searched in. ``icp.libicp_mse_m2`` is the paper's figure
(LibICP residual from the identity, mean squared nearest-neighbour distance, m^2; the
authors' Lab Tour saves give their 0.00883269); ``icp.libicp_best_mse_m2`` and
``icp.libicp_spread_m2`` come from several start rotations, with a warning when the
identity start stopped in a worse minimum; ``icp.icp_rmse_m`` is the project's RMSE
(m). See :mod:`torchratslam.eval.icp`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ratslam_graph.atomic import atomic_write_text
from ratslam_graph.out_checks import check_out_file
from torchratslam.errors import InputError
from torchratslam.eval.groundtruth import check_groundtruth_covers
from torchratslam.eval.icp import compare_icp, libicp_starts
from torchratslam.eval.metrics import ATE_ALIGNMENT
from torchratslam.maps.io import load_state, map_format
from torchratslam.viz.plots import draw_icp_overlay, save_figure

__all__ = ["ROLES", "compare_maps", "load_groundtruth", "map_ate", "summary_text", "write_json"]

ROLES = (
    "A (the single-session map, LibICP's template) is moved onto B (the multisession map, "
    "LibICP's model, fixed)"
)


def load_groundtruth(spec: str | Path) -> np.ndarray:
    """Ground truth ``(T, 4)`` rows ``[t, x, y, theta]`` from a CSV (columns ``t, x, y,
    theta``) or a dataset spec (``sim:virtual_tour``, a dataset directory, ...).

    Raises:
        InputError: nothing readable, or the dataset has no ground truth.
    """
    from torchratslam.readers.datasets import open_data, read_groundtruth_csv

    p = Path(str(spec))
    if p.is_file() and p.suffix.lower() in (".csv", ".txt"):
        return read_groundtruth_csv(p)
    gt = open_data(spec).groundtruth()
    if gt is None or not len(gt):
        raise InputError(f"{spec} has no ground truth")
    return np.asarray(gt, np.float64)


def _run_data(path: Path) -> str | None:
    """The dataset a ``torchratslam run`` OUT directory was made from (its metrics.json)."""
    for d in (path, path.parent):
        f = d / "metrics.json"
        if f.is_file():
            try:
                data = json.loads(f.read_text()).get("data")
            except (ValueError, AttributeError):
                return None
            return data if isinstance(data, str) else None
    return None


ATE_OVER = "experiences at their creation times"
"""What compare-maps' ATE compares with the ground truth (a run's ATE compares the
experience current after each frame, at the frame's time: another figure)."""


def map_ate(state: Any, gt: np.ndarray | None) -> tuple[float | None, str, int]:
    """ATE (m) of the experiences' positions against ``gt`` at their creation times,
    after an SE(2) alignment, over the experiences the ground truth's times cover;
    ``(None, why, n)`` when it cannot be computed. ``n``: the experiences with ground
    truth."""
    from torchratslam.eval.metrics import MIN_ATE_POSES, ate_at_times

    if gt is None:
        return None, "no ground truth", 0
    if state.n_experiences < MIN_ATE_POSES:
        return None, "fewer than 3 experiences (an ATE after a rigid alignment needs 3)", 0
    if np.ptp(state.exp_t) == 0:
        return None, "the map has no experience creation times (reference format)", 0
    ate, n = ate_at_times(state.exp_pose[:, :2], state.exp_t, gt)
    if ate is None:
        return None, f"{n} experiences lie inside the ground truth's times; an ATE needs 3", n
    return ate, "ok", n


def compare_maps(
    a: str | Path,
    b: str | Path,
    *,
    config: Any = None,
    groundtruth: str | Path | None = None,
    figure: str | Path | None = None,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Compare map A with map B (any supported format): A moved onto B.

    Args:
        a: the template map (moved), e.g. the single-session map.
        b: the model map (fixed), e.g. the multisession map.
        config: a ``RatSLAMConfig`` or flat dict (shapes reference-format templates).
        groundtruth: a ground-truth CSV or dataset spec; default: the dataset a
            ``torchratslam run`` OUT directory names in its metrics.json, if any.
        figure: where to write the overlay figure (PNG); None writes none. Never one of
            the maps or a file another command wrote; an existing file only with
            ``overwrite``.
        overwrite: replace an existing ``figure``.

    Returns:
        JSON-able: ``roles``, ``a`` and ``b`` (path, format, counts, ``ate_rmse_m``),
        ``icp`` (:func:`torchratslam.eval.icp.compare_icp`), ``groundtruth``, ``figure``.
    """
    check_out_file(figure, inputs=(a, b), flag=("--figure", "figure"), overwrite=overwrite)
    pa, pb = Path(a), Path(b)
    sa, sb = load_state(pa, config), load_state(pb, config)
    for p, s in ((pa, sa), (pb, sb)):
        if s.n_experiences == 0:
            raise InputError(f"{p}: the map has no experiences to compare")
    # each map is judged against its own run's ground truth (or the one given for both)
    given = load_groundtruth(str(groundtruth)) if groundtruth is not None else None
    sources: dict[str, str | None] = {}
    out: dict[str, Any] = {"roles": ROLES}
    for key, p, s in (("a", pa, sa), ("b", pb, sb)):
        src = str(groundtruth) if groundtruth is not None else _run_data(p)
        gt = given if groundtruth is not None else (_try_gt(src) if src is not None else None)
        sources[key] = src if gt is not None else None
        if gt is not None and s.n_experiences > 1 and np.ptp(s.exp_t) > 0:
            check_groundtruth_covers(s.exp_t, s.exp_pose, gt, source=str(src), what=str(p))
        ate, why, n_gt = map_ate(s, gt)
        out[key] = {"path": str(p), "format": map_format(p), **s.summary(), "ate_rmse_m": ate}
        out[key]["groundtruth"] = sources[key]
        if gt is not None:
            out[key].update(ate_alignment=ATE_ALIGNMENT, ate_over=ATE_OVER, ate_poses=n_gt)
        if ate is None:
            out[key]["ate_note"] = (
                "no ground truth of its own (not a run's OUT): give --groundtruth"
                if gt is None and groundtruth is None
                else why
            )
    gt_src = sources["a"] or sources["b"]
    starts = libicp_starts(sa.exp_pose, sb.exp_pose)
    out["icp"] = compare_icp(sa.exp_pose, sb.exp_pose, starts=starts)
    out["icp"]["units"] = {
        "libicp_mse_m2": "m^2",
        "libicp_best_mse_m2": "m^2",
        "libicp_spread_m2": "m^2",
        "icp_rmse_m": "m",
        "icp_rmse_swapped_m": "m",
    }
    out["groundtruth"] = gt_src
    out["figure"] = None
    if figure is not None:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        lib = starts.identity
        fig, ax = plt.subplots(figsize=(5.5, 5))
        draw_icp_overlay(
            ax,
            sb.exp_pose,
            lib.aligned,
            fixed_label=f"B: {_label(pb)} (fixed)",
            moved_label=f"A: {_label(pa)} (ICP-aligned)",
            mse_m2=lib.residual_m2,
        )
        fp = Path(figure)
        fp.parent.mkdir(parents=True, exist_ok=True)
        fig.tight_layout()
        save_figure(fig, fp, dpi=110, tight=False)
        out["figure"] = str(fp)
    return out


def _label(p: Path) -> str:
    """A short name for a map directory (``run1/state`` rather than ``state``)."""
    return f"{p.parent.name}/{p.name}" if p.name == "state" else p.name


def _try_gt(spec: str) -> np.ndarray | None:
    """Ground truth of a run's dataset, or None when it has none or cannot be opened."""
    try:
        return load_groundtruth(spec)
    except (InputError, OSError):
        return None


def summary_text(report: dict[str, Any]) -> str:
    """The report as a few lines for the terminal."""
    ic = report["icp"]
    t = ic["transform"]
    lines = [f"roles: {report['roles']}"]
    for key in ("a", "b"):
        r = report[key]
        ate = "-" if r["ate_rmse_m"] is None else f"{r['ate_rmse_m']:.4g} m"
        if r["ate_rmse_m"] is not None:
            ate += (
                f" ({r['ate_alignment']}-aligned, {r['ate_over']}: {r['ate_poses']} of "
                f"{r['experiences']} with ground truth)"
            )
        lines.append(
            f"{key.upper()}: {r['path']} ({r['format']}): {r['templates']} templates, "
            f"{r['experiences']} experiences, {r['links']} links; ATE {ate}"
        )
    n_starts = len(ic["libicp_starts"])
    lines += [
        f"ICP, the paper's figure (LibICP residual from the identity, A moved onto B): "
        f"{ic['libicp_mse_m2']:.6g} m^2 after {ic['libicp_iterations']} iterations",
        f"ICP from {n_starts} start rotations of A: best {ic['libicp_best_mse_m2']:.6g} m^2 "
        f"(start {ic['libicp_best_start_deg']:.0f} deg), spread {ic['libicp_spread_m2']:.4g} "
        f"m^2" + ("" if ic["libicp_starts_agree"] else " (the starts end in different minima)"),
        f"ICP RMSE, the project's figure: {ic['icp_rmse_m']:.6g} m (A moved onto B), "
        f"{ic['icp_rmse_swapped_m']:.6g} m (B moved onto A)",
        f"rigid transform of A: dth {t['dth_rad']:.6g} rad, t ({t['tx_m']:.6g}, {t['ty_m']:.6g}) m",
    ]
    if ic.get("libicp_warning"):
        lines.append(f"warning: {ic['libicp_warning']}")
    if report.get("figure"):
        lines.append(f"figure: {report['figure']}")
    return "\n".join(lines)


def write_json(report: dict[str, Any], path: str | Path, *, overwrite: bool = False) -> Path:
    """The report as JSON at ``path`` (parent folders made), written atomically; an
    existing file is replaced only with ``overwrite`` (never another command's file or
    one of the compared maps)."""
    check_out_file(
        path,
        inputs=(report["a"]["path"], report["b"]["path"]),
        flag=("--json", "json"),
        overwrite=overwrite,
    )
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, json.dumps(report, indent=2) + "\n")
    return out
