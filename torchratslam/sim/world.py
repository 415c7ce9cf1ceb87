"""Floor plans for the simulator: textured wall segments in a 2.5D world.

A :class:`World` is a set of vertical wall segments on a flat floor. Every segment has
a height and its own texture strip, a ``(TEX_ROWS, n)`` patch of grey values in [0, 1]
running along the wall (``TEX_RES`` columns per metre, row 0 at the floor). All strips
live side by side in one atlas array so the renderer can look up every visible pixel
with one fancy-indexing operation.

Textures are made of panels 0.8 m to 2.5 m wide, each of a random kind (vertical
stripes, horizontal bands, blocks, gradients, smooth noise, posters) with its own
brightness and contrast, so places are distinguishable; everything is drawn from a
seeded generator and is reproducible.

The ``"smooth"`` style (:data:`STYLES`, used by the virtual tour) draws the same kinds
at a much lower spatial frequency along the wall: panels 3 m to 7 m wide that blend
into each other over 0.6 m, stripes as sinusoids of 2.5 m to 6 m period, blocks 1.5 m
to 3 m wide, noise on a 1.2 m to 2.5 m lattice, and no dark frames. The structure that
tells places apart is mostly vertical (bands, brightness, gradients), so turning by a
few degrees changes a view little while different places still look different, like
the smooth imagery of the multisession paper's virtual world.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from torchratslam.errors import InputError

__all__ = ["STYLES", "TEX_RES", "TEX_ROWS", "World", "WorldBuilder", "make_texture"]

TEX_RES = 16.0
"""Texture columns per metre of wall."""
TEX_ROWS = 32
"""Texture rows over a wall's height."""

_KINDS = ("vstripes", "hbands", "blocks", "gradient", "noise", "poster")
STYLES = ("default", "smooth")
"""Texture styles: ``default`` (panels 0.8-2.5 m, sharp detail) and ``smooth`` (low
spatial frequency along the wall)."""


def _smooth_noise(
    rng: np.random.Generator, rows: int, cols: int, cell: int, cell_cols: int | None = None
) -> np.ndarray:
    """Bilinearly upsampled uniform noise with a lattice of ``cell`` pixels (``cell_cols``
    along the columns, default ``cell``)."""
    cc = cell if cell_cols is None else cell_cols
    gr, gc = rows // cell + 2, cols // cc + 2
    grid = rng.random((gr, gc))
    r = np.arange(rows) / cell
    c = np.arange(cols) / cc
    r0, c0 = np.floor(r).astype(int), np.floor(c).astype(int)
    fr, fc = (r - r0)[:, None], (c - c0)[None, :]
    g00 = grid[r0[:, None], c0[None, :]]
    g01 = grid[r0[:, None], c0[None, :] + 1]
    g10 = grid[r0[:, None] + 1, c0[None, :]]
    g11 = grid[r0[:, None] + 1, c0[None, :] + 1]
    return (g00 * (1 - fr) + g10 * fr) * (1 - fc) + (g01 * (1 - fr) + g11 * fr) * fc


def _panel_smooth(
    rng: np.random.Generator, kind: str, rows: int, cols: int, scale: float = 1.0
) -> np.ndarray:
    """One panel of a ``smooth``-style texture, values in [0, 1] (low frequency along u;
    every length along the wall multiplied by ``scale``)."""
    v = (np.arange(rows)[:, None] + 0.5) / rows  # 0 at the floor, 1 at the top
    u = (np.arange(cols)[None, :] + 0.5) / (TEX_RES * scale)  # metres / scale along the panel
    if kind == "vstripes":  # a sinusoid along the wall
        period = rng.uniform(2.5, 6.0)
        phase = rng.uniform(0, 2 * np.pi)
        pat = 0.5 + 0.5 * np.sin(2 * np.pi * u / period + phase) * np.ones_like(v)
    elif kind == "hbands":
        n = int(rng.integers(2, 6))
        edges = np.sort(rng.uniform(0.1, 0.9, n - 1))
        levels = rng.uniform(0, 1, n)
        pat = levels[np.searchsorted(edges, v)] * np.ones_like(u)
    elif kind == "blocks":
        bu, bv = rng.uniform(1.5, 3.0), rng.uniform(0.25, 0.5)
        iu = np.floor(u / bu).astype(int)
        iv = np.floor(v / bv).astype(int)
        levels = rng.uniform(0, 1, (iv.max() + 1, iu.max() + 1))
        pat = levels[iv, iu]
    elif kind == "gradient":
        a, b = rng.uniform(0, 1, 2)
        t = v if rng.random() < 0.5 else u / max(u.max(), 1e-9)
        pat = (a + (b - a) * t) * np.ones((rows, cols))
    elif kind == "noise":  # smooth noise: coarse along the wall, finer vertically
        cell_u = max(1, round(rng.uniform(1.2, 2.5) * scale * TEX_RES))
        pat = _smooth_noise(rng, rows, cols, int(rng.integers(6, 12)), cell_u)
    else:  # poster: a wide rectangle on a plain background
        pat = np.full((rows, cols), rng.uniform(0, 1))
        w = max(1, int(cols * rng.uniform(0.4, 0.8)))
        h = max(1, int(rows * rng.uniform(0.25, 0.5)))
        c0 = int(rng.integers(0, cols - w + 1))
        r0 = int(rng.integers(rows // 4, max(rows // 4 + 1, rows - h - rows // 8)))
        pat[r0 : r0 + h, c0 : c0 + w] = rng.uniform(0, 1)
    base = rng.uniform(0.2, 0.8)
    contrast = rng.uniform(0.5, 0.9)
    return np.clip(base + contrast * (pat - pat.mean()), 0.0, 1.0)


def _panel(rng: np.random.Generator, kind: str, rows: int, cols: int) -> np.ndarray:
    """One panel of a wall texture, values in [0, 1]."""
    v = (np.arange(rows)[:, None] + 0.5) / rows  # 0 at the floor, 1 at the top
    u = (np.arange(cols)[None, :] + 0.5) / TEX_RES  # metres along the panel
    if kind == "vstripes":
        period = rng.uniform(0.3, 1.2)
        duty = rng.uniform(0.3, 0.7)
        phase = rng.uniform(0, 1)
        pat = (((u / period + phase) % 1.0) < duty).astype(float) * np.ones_like(v)
    elif kind == "hbands":
        n = int(rng.integers(2, 6))
        edges = np.sort(rng.uniform(0, 1, n - 1))
        levels = rng.uniform(0, 1, n)
        pat = levels[np.searchsorted(edges, v)] * np.ones_like(u)
    elif kind == "blocks":
        bu, bv = rng.uniform(0.3, 0.8), rng.uniform(0.2, 0.5)
        iu = np.floor(u / bu).astype(int)
        iv = np.floor(v / bv).astype(int)
        levels = rng.uniform(0, 1, (iv.max() + 1, iu.max() + 1))
        pat = levels[iv, iu]
    elif kind == "gradient":
        a, b = rng.uniform(0, 1, 2)
        t = v if rng.random() < 0.5 else u / max(u.max(), 1e-9)
        pat = (a + (b - a) * t) * np.ones((rows, cols))
    elif kind == "noise":
        pat = _smooth_noise(rng, rows, cols, int(rng.integers(3, 8)))
    else:  # poster: a rectangle on a plain background
        pat = np.full((rows, cols), rng.uniform(0, 1))
        w = max(1, int(cols * rng.uniform(0.3, 0.7)))
        h = max(1, int(rows * rng.uniform(0.25, 0.5)))
        c0 = int(rng.integers(0, cols - w + 1))
        r0 = int(rng.integers(rows // 4, max(rows // 4 + 1, rows - h - rows // 8)))
        pat[r0 : r0 + h, c0 : c0 + w] = rng.uniform(0, 1)
    base = rng.uniform(0.25, 0.75)
    contrast = rng.uniform(0.4, 0.9)
    return np.clip(base + contrast * (pat - pat.mean()), 0.0, 1.0)


def make_texture(
    rng: np.random.Generator,
    length_m: float,
    *,
    rows: int = TEX_ROWS,
    kind: str | None = None,
    style: str = "default",
    scale: float = 1.0,
) -> np.ndarray:
    """A texture strip for a wall of the given length.

    Args:
        rng: the generator to draw from (seeded by the caller).
        length_m: wall length in metres.
        rows: texture rows over the wall height.
        kind: one panel kind for the whole strip ("flat" gives a uniform 1.0), or None
            for random panels (``default``: 0.8-2.5 m wide separated by dark frames;
            ``smooth``: 3-7 m wide, blended into each other over 0.6 m).
        style: ``"default"`` or ``"smooth"`` (see the module docstring).
        scale: ``smooth`` only: every feature length along the wall multiplied by this
            (e.g. 2 for far walls, so they change as slowly with the view angle).

    Returns:
        ``(rows, max(1, round(length_m * TEX_RES)))`` float32 array in [0, 1].
    """
    if style not in STYLES:
        raise InputError(f"unknown texture style {style!r} (valid: {', '.join(STYLES)})")
    cols = max(1, round(length_m * TEX_RES))
    if kind == "flat":
        return np.ones((rows, cols), np.float32)
    if kind is not None:
        if kind not in _KINDS:
            raise InputError(f"unknown texture kind {kind!r} (valid: flat, {', '.join(_KINDS)})")
        if style == "smooth":
            return _panel_smooth(rng, kind, rows, cols, scale).astype(np.float32)
        return _panel(rng, kind, rows, cols).astype(np.float32)
    if style == "smooth":
        return _smooth_strip(rng, rows, cols, scale)
    out = np.empty((rows, cols), np.float32)
    c = 0
    while c < cols:
        w = min(cols - c, max(4, round(rng.uniform(0.8, 2.5) * TEX_RES)))
        out[:, c : c + w] = _panel(rng, _KINDS[int(rng.integers(len(_KINDS)))], rows, w)
        out[:, c] *= 0.3  # a dark frame between panels
        c += w
    return out


def _smooth_strip(rng: np.random.Generator, rows: int, cols: int, scale: float) -> np.ndarray:
    """Random ``smooth`` panels 3-7 m wide, each blended into the next over 0.6 m (both
    times ``scale``)."""
    blend = max(1, round(0.6 * scale * TEX_RES))
    widths: list[int] = []
    while sum(widths) < cols:
        widths.append(max(4, round(rng.uniform(3.0, 7.0) * scale * TEX_RES)))
    out = np.empty((rows, sum(widths) + blend), np.float32)
    c = 0
    for w in widths:
        kind = _KINDS[int(rng.integers(len(_KINDS)))]
        p = _panel_smooth(rng, kind, rows, w + blend, scale)
        if c == 0:
            out[:, : w + blend] = p
        else:  # cross-fade over the first ``blend`` columns of the new panel
            a = np.linspace(0.0, 1.0, blend + 2)[1:-1][None, :]
            out[:, c : c + blend] = (1 - a) * out[:, c : c + blend] + a * p[:, :blend]
            out[:, c + blend : c + w + blend] = p[:, blend:]
        c += w
    return out[:, :cols]


@dataclass(frozen=True)
class World:
    """A 2.5D world: vertical textured wall segments on a flat floor.

    Attributes:
        segments: ``(S, 4)`` float64 ``[x0, y0, x1, y1]`` in metres.
        heights: ``(S,)`` wall heights (m).
        tex_start: ``(S,)`` int64 first atlas column of each segment's strip.
        tex_cols: ``(S,)`` int64 number of atlas columns of each strip.
        atlas: ``(TEX_ROWS, C)`` float32 grey values in [0, 1].
        floor: floor grey level near the robot, in [0, 1].
        ceiling: ceiling / sky grey level, in [0, 1].
        kinds: ``(S,)`` tag per segment ("wall", "box", "obstacle") for plots.
        name: a label.
        tex_res: texture columns per metre of wall.
    """

    segments: np.ndarray
    heights: np.ndarray
    tex_start: np.ndarray
    tex_cols: np.ndarray
    atlas: np.ndarray
    floor: float = 0.35
    ceiling: float = 0.8
    kinds: tuple[str, ...] = ()
    name: str = "world"
    tex_res: float = TEX_RES
    lengths: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        seg = np.asarray(self.segments, np.float64).reshape(-1, 4)
        object.__setattr__(self, "segments", seg)
        d = seg[:, 2:] - seg[:, :2]
        object.__setattr__(self, "lengths", np.hypot(d[:, 0], d[:, 1]))

    def __len__(self) -> int:
        return len(self.segments)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of all segments."""
        s = self.segments
        xs, ys = np.r_[s[:, 0], s[:, 2]], np.r_[s[:, 1], s[:, 3]]
        return float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max())

    def scaled(self, factor: float) -> World:
        """The same world with every length multiplied by ``factor`` (textures follow)."""
        return replace(
            self,
            segments=self.segments * factor,
            heights=self.heights * factor,
            tex_res=self.tex_res / factor,
        )

    def extended(self, extra: World | None) -> World:
        """This world plus the segments of ``extra`` (for moving obstacles)."""
        if extra is None or len(extra) == 0:
            return self
        off = self.atlas.shape[1]
        return replace(
            self,
            segments=np.concatenate([self.segments, extra.segments]),
            heights=np.concatenate([self.heights, extra.heights]),
            tex_start=np.concatenate([self.tex_start, extra.tex_start + off]),
            tex_cols=np.concatenate([self.tex_cols, extra.tex_cols]),
            atlas=np.concatenate([self.atlas, extra.atlas], axis=1),
            kinds=self.kinds + extra.kinds,
        )

    def plot(
        self, ax: Any, *, color: str = "k", obstacle_color: str = "0.5", lw: float = 1.5
    ) -> Any:
        """Draw the floor plan on a matplotlib axes (walls black, boxes grey)."""
        from matplotlib.collections import LineCollection

        s = self.segments.reshape(-1, 2, 2)
        cols = [color if k == "wall" else obstacle_color for k in self.kinds] or color
        ax.add_collection(LineCollection(s, colors=cols, linewidths=lw))  # type: ignore[arg-type]
        xmin, ymin, xmax, ymax = self.bounds
        pad = 0.05 * max(xmax - xmin, ymax - ymin)
        ax.set_xlim(xmin - pad, xmax + pad)
        ax.set_ylim(ymin - pad, ymax + pad)
        ax.set_aspect("equal")
        return ax


class WorldBuilder:
    """Collects textured segments, boxes and polygons, then builds a :class:`World`.

    Args:
        seed: seed of the texture generator.
        wall_height: default wall height (m).
        style: texture style of the random textures (:data:`STYLES`).
    """

    def __init__(self, seed: int = 0, wall_height: float = 2.0, *, style: str = "default") -> None:
        if style not in STYLES:
            raise InputError(f"unknown texture style {style!r} (valid: {', '.join(STYLES)})")
        self.rng = np.random.default_rng(seed)
        self.wall_height = float(wall_height)
        self.style = style
        self._segs: list[tuple[float, float, float, float]] = []
        self._heights: list[float] = []
        self._tex: list[np.ndarray] = []
        self._kinds: list[str] = []

    def segment(
        self,
        p: tuple[float, float],
        q: tuple[float, float],
        *,
        height: float | None = None,
        texture: np.ndarray | str | None = None,
        kind: str = "wall",
        scale: float = 1.0,
    ) -> WorldBuilder:
        """Add one wall from ``p`` to ``q`` with a texture (an array, a kind, or random;
        ``scale`` multiplies the feature sizes of ``smooth`` textures)."""
        length = float(np.hypot(q[0] - p[0], q[1] - p[1]))
        if length <= 0:
            raise InputError(f"wall segment {p} -> {q} has zero length; give distinct ends")
        if not isinstance(texture, np.ndarray):
            texture = make_texture(self.rng, length, kind=texture, style=self.style, scale=scale)
        self._segs.append((p[0], p[1], q[0], q[1]))
        self._heights.append(self.wall_height if height is None else float(height))
        self._tex.append(np.asarray(texture, np.float32))
        self._kinds.append(kind)
        return self

    def polyline(
        self,
        points: list[tuple[float, float]],
        *,
        closed: bool = True,
        height: float | None = None,
        texture: str | None = None,
        kind: str = "wall",
        scale: float = 1.0,
    ) -> WorldBuilder:
        """Add walls along a polyline (closed by default), one texture strip per side."""
        pts = list(points) + ([points[0]] if closed else [])
        for a, b in itertools.pairwise(pts):
            self.segment(a, b, height=height, texture=texture, kind=kind, scale=scale)
        return self

    def box(
        self,
        cx: float,
        cy: float,
        w: float,
        h: float,
        *,
        height: float | None = None,
        texture: str | None = None,
        kind: str = "box",
        scale: float = 1.0,
    ) -> WorldBuilder:
        """Add an axis-aligned box centred at ``(cx, cy)`` of size ``w`` x ``h``."""
        x0, x1, y0, y1 = cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2
        return self.polyline(
            [(x0, y0), (x1, y0), (x1, y1), (x0, y1)],
            height=height,
            texture=texture,
            kind=kind,
            scale=scale,
        )

    def build(self, *, floor: float = 0.35, ceiling: float = 0.8, name: str = "world") -> World:
        """The finished world."""
        if not self._segs:
            raise InputError("a world needs at least one wall segment")
        cols = np.array([t.shape[1] for t in self._tex], np.int64)
        start = np.concatenate([[0], np.cumsum(cols)[:-1]]).astype(np.int64)
        return World(
            segments=np.array(self._segs, np.float64),
            heights=np.array(self._heights, np.float64),
            tex_start=start,
            tex_cols=cols,
            atlas=np.concatenate(self._tex, axis=1),
            floor=floor,
            ceiling=ceiling,
            kinds=tuple(self._kinds),
            name=name,
        )
