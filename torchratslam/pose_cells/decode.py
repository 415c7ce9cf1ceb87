"""Packet-centre decoding: the population vector around the most active cell."""

from __future__ import annotations

import math

import numpy as np

from torchratslam.config import PoseCellParams

__all__ = ["CentreDecoder"]


class CentreDecoder:
    """Decodes the packet centre ``(x, y, th)`` from the cube of ``+-pc_cells_to_avg``
    cells around the most active cell, with wrap (caches its windows and phasors).

    ``pc_decode="openratslam"`` sums as OpenRatSLAM's ``find_best`` (phasors at
    ``(i + 1) 2 pi / n`` in cell order, minus one cell); ``"exact"`` uses ``2 pi i / n``.

    Args:
        params: pose-cell parameters.
    """

    def __init__(self, params: PoseCellParams) -> None:
        self.dims = params.dims
        self.cells_to_avg = params.pc_cells_to_avg
        self.cpp_decode = params.pc_decode == "openratslam"
        self._lookups: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._ring_key: tuple | None = None
        self._ring_cache: list[tuple[np.ndarray, np.ndarray, int]] = []
        self._tables: np.ndarray | None = None

    def rings(self) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """Per axis (x, y, th): the wrapped ``+-pc_cells_to_avg`` window of every cell,
        ``(n, 2c + 1)``, the unit phasors ``exp(2 pi i k / n)``, and ``n`` (cached)."""
        c = self.cells_to_avg
        key = (c, self.dims)
        if self._ring_key != key:
            off = np.arange(-c, c + 1)
            self._ring_cache = []
            for n in self.dims:
                ang = np.arange(n) * (2.0 * math.pi / n)
                ring = np.remainder(np.arange(n)[:, None] + off, n)
                self._ring_cache.append((ring, np.cos(ang) + 1j * np.sin(ang), n))
            self._ring_key = key
        return self._ring_cache

    def _decode_lookups(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """find_best's sin and cos lookups, ``(i + 1) 2 pi / n``, with its arithmetic."""
        lk = self._lookups.get(n)
        if lk is None:
            ang = (np.arange(n, dtype=np.float64) + 1.0) * 2.0 * math.pi / float(n)
            lk = (np.sin(ang), np.cos(ang))
            self._lookups[n] = lk
        return lk

    def find_best_tables(self) -> np.ndarray:
        """find_best's ``sin``, ``cos`` lookups per axis, rows ``sin x, cos x, sin y, cos y,
        sin th, cos th``, each padded with zeros to the longest axis (cached).

        Shape:
            returns ``(6, max(X, Y, TH))`` float64.
        """
        if self._tables is None:
            tab = np.zeros((6, max(self.dims)), dtype=np.float64)
            for ax, n in enumerate(self.dims):
                tab[2 * ax, :n], tab[2 * ax + 1, :n] = self._decode_lookups(n)
            self._tables = tab
        return self._tables

    def cpp_position(self, sums: np.ndarray, ring: np.ndarray, n: int) -> float:
        """find_best on one axis: ``atan2`` of the (i + 1) phasor sums (in cell order),
        times ``n / 2 pi``, minus one cell, then wrapped into ``[0, n]``.

        Shape:
            sums, ring: ``(2c + 1,)``.
        """
        sin_l, cos_l = self._decode_lookups(n)
        start = int(np.argmin(ring))  # the window in cell order: it wraps at most once
        r = np.concatenate((ring[start:], ring[:start])) if start else ring
        w = np.concatenate((sums[start:], sums[:start])) if start else sums
        s1 = float(np.cumsum(sin_l[r] * w)[-1])  # sequential, in cell order, as its loop
        s2 = float(np.cumsum(cos_l[r] * w)[-1])
        x = math.atan2(s1, s2) * n / (2.0 * math.pi) - 1.0
        while x < 0:
            x += n
        while x > n:
            x -= n
        return x

    def decode_batch(self, act: np.ndarray, peak: np.ndarray) -> np.ndarray:
        """The centre of every network around its flat ``peak`` index.

        Shape:
            act: ``(B, TH, Y, X)``; peak: ``(B,)``; returns ``(B, 3)`` float64.
        """
        b = act.shape[0]
        n_x, n_y, n_t = self.dims
        pk = np.asarray(peak)
        pt, py, px = pk // (n_y * n_x), (pk // n_x) % n_y, pk % n_x
        (wx, ex, _), (wy, ey, _), (wt, et, _) = self.rings()
        ix, iy, it = wx[px], wy[py], wt[pt]  # (B, 2c + 1) each
        cube = act[
            np.arange(b)[:, None, None, None],
            it[:, :, None, None],
            iy[:, None, :, None],
            ix[:, None, None, :],
        ].astype(np.float64)
        out = np.empty((b, 3), dtype=np.float64)
        for col, (sums, ring, phasor, n) in enumerate(
            (
                (cube.sum(axis=(1, 2)), ix, ex, n_x),
                (cube.sum(axis=(1, 3)), iy, ey, n_y),
                (cube.sum(axis=(2, 3)), it, et, n_t),
            )
        ):
            if self.cpp_decode:  # one network at a time: find_best's own summation order
                out[:, col] = [self.cpp_position(sums[i], ring[i], n) for i in range(b)]
                continue
            v = np.angle((sums * phasor[ring]).sum(1))
            pos = np.remainder(v * (n / (2.0 * math.pi)), float(n))
            out[:, col] = np.where(pos >= n, pos - n, pos)
        return out

    def decode_one(self, act: np.ndarray, peak: int) -> tuple[float, float, float]:
        """The centre of one network around the flat ``peak`` index (find_best compiled,
        :func:`~torchratslam.pose_cells._step.find_best`, with ``pc_decode="openratslam"``).

        Shape:
            act: ``(TH, Y, X)``.
        """
        if self.cpp_decode:
            from torchratslam.pose_cells._step import find_best

            return find_best(act, int(peak), self.cells_to_avg, self.find_best_tables())
        n_x, n_y, n_t = self.dims
        pt, py, px = peak // (n_y * n_x), (peak // n_x) % n_y, peak % n_x
        (wx, ex, _), (wy, ey, _), (wt, et, _) = self.rings()
        ix, iy, it = wx[px], wy[py], wt[pt]
        flat = ((it[:, None, None] * n_y + iy[None, :, None]) * n_x + ix).reshape(-1)
        w = len(ix)
        cube = act.reshape(-1).take(flat).reshape(len(it), len(iy), w).astype(np.float64)
        c2 = cube.sum(axis=0)
        sums = (c2.sum(axis=0), c2.sum(axis=1), cube.sum(axis=(1, 2)))
        rings = (ix, iy, it)
        res: list[float] = []
        for sm, ring, ph, n in zip(sums, rings, (ex, ey, et), (n_x, n_y, n_t), strict=True):
            v = np.angle((sm * ph[ring]).sum())
            pos = float(np.remainder(v * (n / (2.0 * math.pi)), float(n)))
            res.append(pos - n if pos >= n else pos)
        return (res[0], res[1], res[2])
