"""``torchratslam merge``: offline merge of two saved maps (multisession paper, Alg. 1).

The partial map's current (last) template is matched against the loaded map's
templates with the local view's matcher; if the best match is under
``vt_match_threshold`` the maps are merged (``torchratslam.maps.merge.merge_maps``) and the
result is written to ``--out``, in the native format or the reference implementation's
text format. Either input may be a native map, a run's OUT directory, or a
reference-format directory.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from torchratslam.config import load_config
from torchratslam.errors import GraphError


def register(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "merge",
        help="merge two saved maps offline (the partial map's last template must match)",
        description=(__doc__ or "").replace("``", ""),
        epilog="example:\n  torchratslam merge --config virtual_tour --loaded out/s1/state "
        "--partial out/s2/state --out out/merged --relax",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--config",
        required=True,
        help="config both maps were made with, e.g. --config virtual_tour",
    )
    p.add_argument(
        "--loaded",
        required=True,
        help="the stored map (its frame is kept), e.g. --loaded out/s1/state",
    )
    p.add_argument(
        "--partial", required=True, help="the map to merge into it, e.g. --partial out/s2/state"
    )
    p.add_argument(
        "--out", required=True, help="output directory for the merged map, e.g. --out out/merged"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a map already in OUT (never --loaded or --partial), e.g. --overwrite",
    )
    p.add_argument(
        "--format",
        choices=("native", "reference"),
        default="native",
        help="output format (default: native), e.g. --format reference",
    )
    p.add_argument(
        "--no-pc-shift",
        action="store_true",
        help="skip the pose-cell association shift (the paper's Fig. 12 ablation), "
        "e.g. --no-pc-shift",
    )
    p.add_argument(
        "--exp-pc-shift",
        choices=("experiences", "templates"),
        default="experiences",
        help="shift of the partial experiences' pose-cell coordinates: by the matched "
        "experiences' difference (default, the authors' code) or by the templates' (the "
        "paper's single shift), e.g. --exp-pc-shift templates",
    )
    p.add_argument(
        "--match-exp",
        choices=("first", "nearest"),
        default="first",
        help="loaded experience merged at: the matched template's first (default, the "
        "authors' code) or the one nearest in pose cells, e.g. --match-exp nearest",
    )
    p.add_argument(
        "--relax",
        action="store_true",
        help="relax the merged map once (exp_loops passes, exp_backend), e.g. --relax",
    )
    p.set_defaults(func=main)
    return p


def match_last_template(loaded: Any, partial: Any, config: Any) -> tuple[int, float, float]:
    """Best loaded template (with an experience) for the partial map's last template.

    Returns:
        ``(template id, relative view angle rad, error)``.

    Raises:
        GraphError: the partial map is empty or no loaded template is under
            ``vt_match_threshold``.
    """
    import torch

    from torchratslam.local_view.view import LocalView
    from torchratslam.maps.merge import pick_experience

    if partial.n_templates == 0 or loaded.n_templates == 0:
        raise GraphError("both maps need at least one template to be merged")
    lv = LocalView(config.local_view, dtype=torch.float64)
    has_exp = np.zeros(loaded.n_templates, bool)
    has_exp[loaded.exp_template[loaded.exp_template >= 0]] = True
    ids = np.flatnonzero(has_exp)
    if ids.size == 0:
        raise GraphError("the loaded map has no experience to merge at")
    lv.add_templates(torch.as_tensor(np.asarray(loaded.templates[ids], np.float64)))
    tid, offset, err = lv.match(torch.as_tensor(np.asarray(partial.templates[-1], np.float64)))
    thr = config.local_view.vt_match_threshold
    if tid < 0 or err > thr:
        raise GraphError(
            f"the partial map's last template matches no loaded template (best error {err:.4f} "
            f"> vt_match_threshold {thr}); these maps do not meet at the partial map's end"
        )
    tid = int(ids[tid])
    if pick_experience(loaded, tid) < 0:  # pragma: no cover - excluded above
        raise GraphError(f"loaded template {tid} has no experience")
    return tid, float(lv.relative_rad(int(offset))), float(err)


def check_out(out: Path, inputs: dict[str, str], overwrite: bool) -> None:
    """Refuse an OUT that is (or holds, or lies in) an input map, and a non-empty OUT
    without ``overwrite``: a merge never rewrites its inputs nor a finished run's state.

    Raises:
        InputError: naming the flag.
    """
    from torchratslam.errors import InputError
    from torchratslam.maps.native import resolve_native

    def the_map(value: str) -> Path:  # a run's OUT and its state/ are the same map
        p = Path(value)
        found = resolve_native(p) if p.is_dir() else None
        return (found or p).resolve()

    paths = {flag: the_map(value) for flag, value in inputs.items()}
    if len(set(paths.values())) < len(paths):
        raise InputError(
            f"{' and '.join(inputs)} are the same map ({next(iter(inputs.values()))}); merging "
            "a map with itself would only double it: give two different maps"
        )
    target = out.resolve()
    for flag, value in inputs.items():
        src = Path(value).resolve()
        if target == src or src in target.parents or target in src.parents:
            raise InputError(
                f"--out {out} is the map given as {flag} {value}; a merge never rewrites "
                "its inputs: choose another --out"
            )
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory; choose another path")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise InputError(
            f"--out {out} is not empty (it holds {next(iter(sorted(out.iterdir()))).name}); "
            "choose another --out, or replace it with --overwrite"
        )


def main(args: argparse.Namespace) -> int:
    from torchratslam.maps.io import load_state
    from torchratslam.maps.merge import merge_maps
    from torchratslam.maps.native import save_map
    from torchratslam.maps.reference_format import write_reference
    from torchratslam.maps.running import apply_experience_map

    check_out(Path(args.out), {"--loaded": args.loaded, "--partial": args.partial}, args.overwrite)
    config = load_config(args.config)
    loaded = load_state(args.loaded, config)
    partial = load_state(args.partial, config)
    tid, rel, err = match_last_template(loaded, partial, config)
    res = merge_maps(
        loaded,
        partial,
        tid,
        relative_rad=rel,
        shift_pose_cells=not args.no_pc_shift,
        exp_pc_shift=args.exp_pc_shift,
        match_exp=args.match_exp,
    )
    merged = res.state
    if args.relax:
        merged = apply_experience_map(merged, config)
    if args.format == "reference":
        write_reference(merged, args.out)
    else:
        save_map(merged, args.out)
    summary = {
        "out": str(args.out),
        "format": args.format,
        "loaded_template": tid,
        "match_error": err,
        "loaded_exp": res.info["loaded_exp"],
        "pc_shift": res.info["pc_shift"],
        "transform": res.info["transform"],
        **merged.summary(),
    }
    print(json.dumps(summary, indent=1))
    return 0
