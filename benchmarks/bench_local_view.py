"""Local view cells: ms per frame versus number of templates (``make bench``).

Data: views along a synthetic route. Each place's panorama is a smooth random texture
(spatially correlated like a blurred image, contrast ~0.15) over a shared sky-to-floor
gradient; places blend linearly between knots every 4 route units, so consecutive
templates differ by ~0.04 MAD (about ``vt_match_threshold``) and far ones by ~0.13.
A *familiar* frame is a point between stored templates, turned by a random number of
columns, plus pixel noise; a *novel* frame is a place beyond the mapped part of the
route. Times are for the decision ``process()`` takes (``match`` with the threshold),
single thread, median over frames; the bank is fixed (no learning) so its size is exact.
"no pruning" is the same exact search with the lower bounds switched off.

The ``loop`` case runs ``process()`` on 1781 256x64 uint8 frames of a route driven
twice (learning on the first lap, recognising on the second), the analogue of the C++
reference's 4.25 ms per frame measured on a 1781-frame panoramic loop at 271 templates.
"""

from __future__ import annotations

import math
import os
import statistics
import time

import numpy as np
import torch

from torchratslam.config import LocalViewParams
from torchratslam.local_view.view import LocalView
from torchratslam.sim.views import ViewRoute as Route

CPP_MS = 4.25  # OpenRatSLAM, 1781-frame panoramic loop, 271 templates of 64x16


def _frames(route: Route, n: int, m: int, panoramic: bool, seed: int = 1):
    g = torch.Generator().manual_seed(seed)
    half = m // 2
    pos = torch.cat(
        [
            (torch.randint(0, n, (half,), generator=g) + torch.rand(half, generator=g) - 0.5).clamp(
                0, n - 1
            ),
            n + 8 + torch.rand(m - half, generator=g) * n * 0.5,
        ]
    )
    views = route.views(pos)
    x = views.shape[-1]
    shifts = torch.randint(0, x, (m,), generator=g) if panoramic else torch.randint(-2, 3, (m,))
    views = torch.stack([torch.roll(v, -int(k), -1) for v, k in zip(views, shifts)])
    views = (views + 0.01 * torch.randn(views.shape, generator=g)).clamp(0, 1)
    return views, ["familiar"] * half + ["novel"] * (m - half)


def _time(fn, *args, **kwargs) -> float:
    t0 = time.perf_counter()
    fn(*args, **kwargs)
    return (time.perf_counter() - t0) * 1e3


def bank_case(panoramic: bool, n: int, frames: int, brute_frames: int) -> dict:
    y, x = (16, 64) if panoramic else (20, 60)
    params = LocalViewParams(
        template_x_size=x, template_y_size=y, vt_panoramic=panoramic, vt_shift_match=4,
        vt_step_match=1, vt_match_threshold=0.05,
    )  # fmt: skip
    route = Route(2 * n + 40, y, x)
    lv = LocalView(params)
    for s in range(0, n, 4096):
        lv.add_templates(route.views(torch.arange(s, min(n, s + 4096))))
    views, kinds = _frames(route, n, frames, panoramic)
    thr = params.vt_match_threshold
    times: dict[str, list[float]] = {"familiar": [], "novel": []}
    for v, kind in zip(views, kinds):
        times[kind].append(_time(lv.match, v, threshold=thr))
    out = {
        "mode": f"{x}x{y} {'panoramic, 64 offsets' if panoramic else 'normal, +-4 offsets'}",
        "n": n,
        "familiar": statistics.median(times["familiar"]),
        "novel": statistics.median(times["novel"]),
        "all": statistics.median(times["familiar"] + times["novel"]),
        "bytes": lv.bank.bytes_per_template(),
    }
    if brute_frames:
        lv.prune = False
        out["brute"] = statistics.median(_time(lv.match, v) for v in views[:brute_frames])
    return out


def loop_case(frames: int = 1781) -> dict:
    """``process()`` on a panoramic route driven twice, from 256x64 uint8 images."""
    params = LocalViewParams(
        template_x_size=64, template_y_size=16, vt_panoramic=True, vt_step_match=1,
        vt_match_threshold=0.03,
    )  # fmt: skip
    length = 180.0
    route = Route(length + 10, 16, 64, seed=3)
    g = torch.Generator().manual_seed(4)
    i = torch.arange(frames, dtype=torch.float32)
    pos = (i * 2 * length / frames) % length
    turn = torch.round(6 * torch.sin(i / 40)).long()
    views = route.views(pos)
    views = torch.stack([torch.roll(v, -int(k), -1) for v, k in zip(views, turn)])
    views = (views + 0.005 * torch.randn(views.shape, generator=g)).clamp(0, 1)
    images = (np.kron(views.numpy(), np.ones((4, 4), np.float32)) * 255).astype(np.uint8)
    lv = LocalView(params)
    times = [_time(lv.process, img) for img in images]
    pre = statistics.median(_time(lv.preprocess, img) for img in images[:200])
    return {
        "templates": len(lv),
        "mean": statistics.fmean(times),
        "median": statistics.median(times),
        "preprocess": pre,
    }


def main() -> None:
    torch.set_num_threads(1)
    quick = bool(os.environ.get("BENCH_QUICK"))
    sizes = (100, 1000) if quick else (100, 1000, 5000, 20000)
    frames = 20 if quick else 60
    print("single thread; decision time of process() (match with vt_match_threshold=0.05)")
    print("median ms per frame over familiar and novel frames (half each)\n")
    print("| templates | mode | familiar ms | novel ms | all ms | no pruning ms | bytes/template |")
    print("|---:|---|---:|---:|---:|---:|---:|")
    for panoramic in (True, False):
        for n in (271, *sizes) if panoramic else sizes:
            r = bank_case(panoramic, n, frames, 6 if n <= 5000 else 0)
            brute = f"{r['brute']:.2f}" if "brute" in r else "-"
            print(
                f"| {n} | {r['mode']} | {r['familiar']:.2f} | {r['novel']:.2f} | {r['all']:.2f} "
                f"| {brute} | {r['bytes']} |",
                flush=True,
            )
    loop = loop_case(600 if quick else 1781)
    speedup = CPP_MS / loop["mean"] if loop["mean"] > 0 else math.inf
    print(
        f"\nloop: process() on {600 if quick else 1781} 256x64 uint8 panoramic frames "
        f"(64x16 templates, all offsets): {loop['templates']} templates learnt, "
        f"mean {loop['mean']:.2f} ms/frame (median {loop['median']:.2f}; preprocessing "
        f"{loop['preprocess']:.2f}); C++ reference {CPP_MS} ms/frame at 271 templates: "
        f"{speedup:.1f}x"
    )


if __name__ == "__main__":
    main()
