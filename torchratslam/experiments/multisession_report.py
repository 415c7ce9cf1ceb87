"""The multisession experiment's report as Markdown tables (what the demo prints and
the README shows)."""

from __future__ import annotations

from typing import Any

__all__ = ["ATE_NOTE", "fmt_value", "report_markdown"]

ATE_NOTE = (
    "ATE: each experience's final position against the ground truth at its creation time, "
    "after an SE(2) alignment (rotation and translation by least squares, no scale), over "
    "the experiences the ground truth covers ('ATE over'); undefined under 3. A run's ATE "
    "(`torchratslam run`) compares the experience current after each frame instead, so "
    "the two figures differ for one map."
)


def fmt_value(v: Any, spec: str = ".4g") -> str:
    """``v`` formatted with ``spec``, "-" for None."""
    return "-" if v is None else format(v, spec)


def _runs_table(report: dict[str, Any]) -> list[str]:
    last = report["sessions"][-1]
    rows = [
        ("single session, continuous (the paper's single mapping session)", report["single"]),
        (
            "single session, sessions concatenated (kidnapped between them)",
            report["single_concatenated"],
        ),
        (f"single session, {last} alone", report["single_last_session"]),
        ("multisession", report["multi"]),
    ]
    if report.get("single_kind") == "concatenated":  # a tour without roads between sessions
        rows = [(name, r) for name, r in rows if r is not report["single_concatenated"]]
    if "ablation_no_pc_shift" in report:
        rows.append(("multisession, no pose-cell shift", report["ablation_no_pc_shift"]))
    lines = [
        f"### {report['tour']}: {len(report['sessions'])} sessions, {report['frames']} frames "
        f"({report['frames_continuous']} in the continuous run)",
        "",
        "| run | templates | experiences | links | ATE (m) | ATE over | maps at end |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in rows:
        over = r.get("ate_poses")
        lines.append(
            f"| {name} | {r['templates']} | {r['experiences']} | {r['links']} | "
            f"{fmt_value(r['ate_rmse_m'])} | {'-' if over is None else over} | "
            f"{r.get('maps', 1)} |"
        )
    lines += ["", ATE_NOTE]
    return lines


def _summary_lines(report: dict[str, Any]) -> list[str]:
    last = report["sessions"][-1]
    return [
        "",
        f"- ICP, the paper's figure (LibICP residual: mean squared nearest-neighbour "
        f"distance, the single-session map moved onto the multisession map): "
        f"{fmt_value(report.get('icp_libicp_mse_m2'))} m^2; the paper reports "
        f"{fmt_value(report.get('paper_icp_mse_m2'))} m^2",
        f"- ICP RMSE (the project's figure, not the paper's) multisession vs single-session "
        f"(continuous) map: "
        f"{fmt_value(report['icp_rmse'])} m "
        f"({fmt_value(report['icp_rmse_relative'])} of the tour's "
        f"{report['tour_extent_m']:.1f} m extent); vs the concatenated run: "
        f"{fmt_value(report['icp_rmse_concatenated'])} m; vs {last} alone: "
        f"{fmt_value(report['icp_rmse_last_session'])} m",
        "- experiences, multi vs single (continuous): "
        + fmt_value(report["experiences_difference_relative"], "+.1%")
        + ", vs concatenated: "
        + fmt_value(report["experiences_difference_relative_concatenated"], "+.1%")
        + f", vs {last} alone: "
        + fmt_value(report["experiences_difference_relative_last_session"], "+.1%"),
        "- merges: "
        + (
            ", ".join(
                f"{m['session']} frame {m['frame']} with {m['map']}" for m in report["merges"]
            )
            or "none"
        ),
    ]


def _backend_lines(report: dict[str, Any]) -> list[str]:
    if "backends" not in report:
        return []
    lines = [
        "",
        "| backend (whole multisession run) | graph error | ATE (m) | "
        "relaxation time (s) | experiences |",
        "|---|---|---|---|---|",
    ]
    for name, b in report["backends"].items():
        lines.append(
            f"| {name} | {fmt_value(b['error'])} | {fmt_value(b['ate_rmse_m'])} | "
            f"{fmt_value(b['time_s'], '.3f')} | {b['experiences']} |"
        )
    lines += [
        "",
        "ATE as in the first table (SE(2)-aligned, each experience at its creation time).",
    ]
    if "backends_final_map" in report:
        lines += [
            "",
            "relaxing the final multisession map's graph once more:",
            "",
            "| backend | initial error | error after | ATE (m) | time (s) |",
            "|---|---|---|---|---|",
        ]
        for name, r in report["backends_final_map"].items():
            lines.append(
                f"| {name} | {fmt_value(r['initial_error'])} | {fmt_value(r['error'])} | "
                f"{fmt_value(r['ate_rmse_m'])} | {fmt_value(r['time_s'], '.3f')} |"
            )
    return lines


def report_markdown(report: dict[str, Any]) -> str:
    """The report as Markdown tables (what the demo prints and the README shows)."""
    lines = _runs_table(report) + _summary_lines(report) + _backend_lines(report)
    return "\n".join(lines) + "\n"
