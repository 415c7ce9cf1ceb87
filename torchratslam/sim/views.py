"""Synthetic panoramas along a route, for local-view experiments without a rendered world.

Each place's panorama is a smooth random texture (spatially correlated like a blurred
image, contrast ~0.15) over a shared sky-to-floor gradient; places blend linearly
between knots every ``knot`` route units, so consecutive views differ little and far
ones a lot. Used by ``benchmarks/bench_local_view.py`` and the local-view notebook.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["ViewRoute", "smooth"]


def smooth(x: torch.Tensor, sy: float, sx: float) -> torch.Tensor:
    """Gaussian blur: circular along X, replicated along Y.

    Shape:
        x: ``(N, Y, X)``; returns the same shape.
    """

    def kernel(s: float) -> tuple[torch.Tensor, int]:
        r = int(3 * s) + 1
        g = torch.exp(-(torch.arange(-r, r + 1, dtype=x.dtype) ** 2) / (2 * s * s))
        return g / g.sum(), r

    gx, rx = kernel(sx)
    gy, ry = kernel(sy)
    n, y, w = x.shape
    x = torch.cat([x[..., -rx:], x, x[..., :rx]], -1)
    x = F.conv1d(x.reshape(-1, 1, x.shape[-1]), gx[None, None]).reshape(n, y, w)
    x = F.pad(x.transpose(1, 2).reshape(-1, 1, y), (ry, ry), mode="replicate")
    return F.conv1d(x, gy[None, None]).reshape(n, w, y).transpose(1, 2)


class ViewRoute:
    """Places along a route; ``views(p)`` renders the panoramas at positions ``p``.

    Args:
        length: route length (units).
        y, x: panorama rows and columns.
        knot: distance between independent places.
        seed: the textures' seed.
    """

    def __init__(self, length: float, y: int, x: int, *, knot: float = 4.0, seed: int = 0):
        g = torch.Generator().manual_seed(seed)
        self.knot = knot
        base = smooth(torch.randn(int(length / knot) + 3, y, x, generator=g), y / 8, x / 32)
        self.base = base / base.std() * 0.15
        self.grad = torch.linspace(0.75, 0.3, y)[:, None]

    def views(self, p: torch.Tensor) -> torch.Tensor:
        """Panoramas in ``[0, 1]`` at route positions ``p``.

        Shape:
            p: ``(N,)``; returns ``(N, Y, X)`` float32.
        """
        p = torch.as_tensor(p, dtype=torch.float32)
        j = (p / self.knot).floor().long()
        a = (p / self.knot - j)[:, None, None]
        return ((1 - a) * self.base[j] + a * self.base[j + 1] + self.grad).clamp(0, 1)
