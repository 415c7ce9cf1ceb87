"""The numpy engine: one CPU network (``B == 1``) stepped in numpy on the packet's crop.

The same box as :mod:`~torchratslam.pose_cells.crop_engine`, without tensor wrapping
(one network is overhead-bound), and OpenRatSLAM's own arithmetic for path integration.
Every cell the excitation does not reach ends at zero (global inhibition), so the crop
needs the excitation's reach and the move only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.errors import InputError
from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells.decode import CentreDecoder
from torchratslam.pose_cells.motion import MotionTables

__all__ = ["NumpyEngine"]

Box = tuple[int, int, bool]


class NumpyEngine:
    """Steps one network's ``(1, TH, Y, X)`` CPU buffer in place with numpy.

    It caches the ring matrices (in the activity's dtype), gather indices, and the
    non-zero arcs ``(start, length)`` per axis (th, y, x), valid while the buffer's
    ``(data_ptr, _version)`` is unchanged.

    Args:
        params: pose-cell parameters.
        dtype: the activity's dtype.
    """

    def __init__(self, params: PoseCellParams, dtype: torch.dtype) -> None:
        xy, th = params.pc_dim_xy, params.pc_dim_th
        self.params = params
        self.dims = (xy, xy, th)
        self.dtype = dtype
        self.kernels = {
            "e": F.gaussian_kernel_1d(params.pc_w_e_dim, params.pc_w_e_var),
            "i": F.gaussian_kernel_1d(params.pc_w_i_dim, params.pc_w_i_var),
        }
        self.motion = MotionTables(params)
        self.decoder = CentreDecoder(params)
        self.last_crop: tuple[int, int, int] = (th, xy, xy)
        """The box (theta, y, x cells) the last step computed on."""
        self._taps: dict[str, np.ndarray] = {}
        self._index: dict[tuple, Any] = {}  # index arrays and per-crop (coef, index) tuples
        self._arcs: list[tuple[int, int]] | None = None
        self._arcs_key: tuple[int, int] | None = None

    # ------------------------------------------------------------ caches
    def retarget(self, dtype: torch.dtype) -> None:
        """Follow the activity to a new dtype: drop every cache."""
        self.dtype = dtype
        self._taps = {}
        self.invalidate()

    def invalidate(self) -> None:
        """Forget what was derived from the activity's contents (it was replaced)."""
        self._arcs = None

    def _conv(self, a: np.ndarray, which: str, circ: tuple[bool, bool, bool]) -> np.ndarray:
        """Separable 3D convolution of ``a`` (T, Y, X), the taps summed in a fixed order
        in ``a``'s dtype (:mod:`~torchratslam.pose_cells._taps`: no BLAS call, so the
        same bits on every CPU)."""
        from torchratslam.pose_cells._taps import conv3

        w = self._taps.get(which)
        if w is None or w.dtype != a.dtype:
            w = self._taps[which] = self.kernels[which].astype(a.dtype)
        return conv3(np.ascontiguousarray(a), w, circ[0], circ[1], circ[2])

    def _arcs_of(self, activity: torch.Tensor, act: np.ndarray) -> list[tuple[int, int]]:
        key = (activity.data_ptr(), activity._version)
        if self._arcs is None or self._arcs_key != key:
            nz: np.ndarray = np.not_equal(act, 0)
            t2 = np.asarray(nz.any(axis=2))
            self._arcs = [F.arc(t2.any(axis=1)), F.arc(t2.any(axis=0)), F.arc(nz.any(axis=(0, 1)))]
            self._arcs_key = key
        return self._arcs

    def _shift_index(self, shape: tuple[int, ...], axis: int, shifts: np.ndarray) -> np.ndarray:
        """Flat gather index moving layer ``k`` of a ``shape`` array by ``shifts[k]`` cells
        along ``axis`` (1: y, 2: x), wrapping on the array's own length (cached)."""
        key = (shape, axis, shifts.tobytes())
        idx = self._index.get(key)
        if idx is None:
            t, y, x = shape
            k = np.arange(t)[:, None, None]
            j = np.arange(y)[None, :, None]
            i = np.arange(x)[None, None, :]
            if axis == 2:
                i = np.remainder(i - shifts[:, None, None], x)
            else:
                j = np.remainder(j - shifts[:, None, None], y)
            idx = ((k * y + j) * x + i).reshape(-1)
            if len(self._index) > 512:
                self._index = {}
            self._index[key] = idx
        return idx

    # ---------------------------------------------------- path integration
    def _translate(
        self, a: np.ndarray, trans: float, layers: np.ndarray, box_y: Box, box_x: Box
    ) -> np.ndarray:
        """Move every layer of the crop ``a`` (T, Y, X) along its heading."""
        mo = self.motion
        g = mo.geometry(trans < 0)
        v = abs(trans)
        if mo.one_cell:  # per crop: the weights per cell of travel and gather indices
            key = (trans < 0, a.shape, int(layers[0]), a.dtype.char)
            crop_geo = self._index.get(key)
            if crop_geo is None:
                # the coefficients stay float64: the weight v * coef is rounded to the
                # activity's dtype once, as on the general path (float32 bit for bit)
                crop_geo = (
                    g["coef_x"][layers][:, None, None],
                    g["coef_y"][layers][:, None, None],
                    self._shift_index(a.shape, 2, g["step_x"][layers]),
                    self._shift_index(a.shape, 1, g["step_y"][layers]),
                )
                self._index[key] = crop_geo
            cx, cy, ix, iy = crop_geo
            src = a
            s1 = a.reshape(-1).take(ix).reshape(a.shape)
            a = a + (v * cx).astype(a.dtype, copy=False) * (s1 - a)
            s1 = a.reshape(-1).take(iy).reshape(a.shape)
            a = a + (v * cy).astype(a.dtype, copy=False) * (s1 - a)
            if mo.edge_loss:
                self._edge_loss(a, src, trans, layers, box_y, box_x)
            return a
        plan: dict[str, np.ndarray] = {}
        for name in ("y", "x"):
            c = v * g["coef_" + name][layers]
            fl = np.floor(c)
            plan["shift_" + name] = fl.astype(np.int64)
            plan["step_" + name] = plan["shift_" + name] + 1
            plan["w_" + name] = c - fl
        shape = a.shape
        src = a
        for axis, name in ((2, "x"), (1, "y")):
            base, step = plan["shift_" + name], plan["step_" + name]
            w = plan["w_" + name].astype(a.dtype, copy=False)
            flat = a.reshape(-1)
            s0 = a if not base.any() else flat[self._shift_index(shape, axis, base)]
            s1 = flat[self._shift_index(shape, axis, step)].reshape(shape)
            s0 = s0.reshape(shape)
            a = s0 + w[:, None, None] * (s1 - s0)
        if mo.edge_loss:
            self._edge_loss(a, src, trans, layers, box_y, box_x)
        return a

    def _edge_loss(
        self,
        out: np.ndarray,
        src: np.ndarray,
        trans: float,
        layers: np.ndarray,
        box_y: Box,
        box_x: Box,
    ) -> None:
        """Take from ``out`` what OpenRatSLAM drops at the wrap: the moves of two corner
        cells of each layer (of ``src``, before the move) across the edge."""
        (sy, ly, _), (sx, lx, _) = box_y, box_x
        n = self.dims[0]
        # local position of global cell 0 and n - 1 on each axis (-1: outside the crop)
        py = [(0 - sy) % n, (n - 1 - sy) % n]
        px = [(0 - sx) % n, (n - 1 - sx) % n]
        py = [p if p < ly else -1 for p in py]
        px = [p if p < lx else -1 for p in px]
        if max(py) < 0 or max(px) < 0:
            return  # no corner of the ring inside the crop
        yy = [p for p in py if p >= 0]
        xx = [p for p in px if p >= 0]
        if not src[:, yy][:, :, xx].any():
            return  # every corner cell is empty: nothing crosses there
        g = self.motion.geometry(trans < 0)
        v = abs(trans)
        sin, cos = g["sin"][layers], g["cos"][layers]
        lost = np.stack([v * sin * (1.0 - v * cos), v * cos * (1.0 - v * sin)], axis=1)
        src_cells, corner = g["src"][layers], g["corner"][layers]  # (T, 2, 2), (T, 2)
        pos_y, pos_x = np.array(py), np.array(px)
        k = np.arange(out.shape[0])
        cy, cx = pos_y[corner[:, 0]], pos_x[corner[:, 1]]
        take = np.zeros(out.shape[0], dtype=out.dtype)
        for m in range(2):  # the two dropped moves
            sy_, sx_ = pos_y[src_cells[:, m, 0]], pos_x[src_cells[:, m, 1]]
            ok = (sy_ >= 0) & (sx_ >= 0)
            take[ok] += lost[ok, m] * src[k[ok], sy_[ok], sx_[ok]]
        ok = (cy >= 0) & (cx >= 0) & (take != 0)
        np.subtract.at(out, (k[ok], cy[ok], cx[ok]), take[ok])

    # --------------------------------------------------------------- step
    def _boxes(
        self, arcs: list[tuple[int, int]], trans: float, rot: float
    ) -> tuple[list[Box], list[np.ndarray]]:
        """Per axis (th, y, x): the crop ``(start, length, whole ring)`` and its cells."""
        p = self.params
        n_x, n_y, n_t = self.dims
        move_xy = math.ceil(abs(trans)) + 1 if trans != 0 else 0
        move_th = math.ceil(abs(rot)) + 1 if rot != 0 else 0
        eh = max(p.pc_w_e_dim // 2, p.pc_w_e_dim - 1 - p.pc_w_e_dim // 2)
        boxes: list[Box] = []
        for (start, ln), n, m in zip(
            arcs, (n_t, n_y, n_x), (eh + move_th, eh + move_xy, eh + move_xy), strict=True
        ):
            if ln == 0:
                raise InputError(
                    "pose-cell activity is all zero; reset() or inject() before stepping"
                )
            if ln + 2 * m >= n:
                boxes.append((0, n, True))
            else:
                boxes.append(((start - m) % n, ln + 2 * m, False))
        idx = [
            np.remainder(np.arange(s, s + ln), n)
            for (s, ln, _), n in zip(boxes, (n_t, n_y, n_x), strict=True)
        ]
        return boxes, idx

    def step(self, activity: torch.Tensor, trans: float, rot: float) -> tuple[float, float, float]:
        """One step of the network in place, on the packet's crop.

        Args:
            activity: the network's CPU buffer (written).
            trans: translation in cells along each layer's heading.
            rot: rotation in theta cells.

        Returns:
            The packet centre ``(x, y, th)`` in cells.

        Raises:
            InputError: activity that is all zero or died out.

        Shape:
            activity: ``(1, TH, Y, X)``.
        """
        p = self.params
        act = activity.detach().numpy()[0]
        n_t, n_y, n_x = act.shape
        boxes, idx = self._boxes(self._arcs_of(activity, act), trans, rot)
        circ = (boxes[0][2], boxes[1][2], boxes[2][2])
        shape = (boxes[0][1], boxes[1][1], boxes[2][1])
        self.last_crop = shape
        flat = ((idx[0][:, None, None] * n_y + idx[1][None, :, None]) * n_x + idx[2]).reshape(-1)
        act_flat = act.reshape(-1)
        crop = act_flat.take(flat).reshape(shape)
        e = self._conv(crop, "e", circ)
        a = e - self._conv(e, "i", circ)
        a -= p.pc_global_inhib
        np.maximum(a, 0.0, out=a)
        total = a.sum()
        if not total > 0:
            raise InputError(F.DIED_OUT)
        a /= total
        if trans != 0:
            a = self._translate(a, trans, idx[0], boxes[1], boxes[2])
        if rot != 0:
            a = F.rotate_theta(a, rot)
        act_flat[flat] = a.reshape(-1)
        # the new non-zero arcs, from the crop (every other cell is zero)
        nz: np.ndarray = np.not_equal(a, 0)
        t2 = np.asarray(nz.any(axis=2))
        arcs = []
        for mask, (start, _ln, whole), n in zip(
            (t2.any(axis=1), t2.any(axis=0), nz.any(axis=(0, 1))),
            boxes,
            (n_t, n_y, n_x),
            strict=True,
        ):
            if whole:
                arcs.append(F.arc(mask))
            else:
                on = np.flatnonzero(mask)
                arcs.append(
                    ((start + int(on[0])) % n, int(on[-1] - on[0]) + 1) if on.size else (0, 0)
                )
        self._arcs = arcs
        # the most active cell; ties go to the lowest global (th, y, x) index
        top = a.max()
        hits = np.flatnonzero(a == top)
        _, ly, lx = a.shape
        kt, ky, kx = hits // (ly * lx), (hits // lx) % ly, hits % lx
        cells = (idx[0][kt] * n_y + idx[1][ky]) * n_x + idx[2][kx]
        return self.decoder.decode_one(act, int(cells.min()))

    def inject(self, activity: torch.Tensor, th: Any, y: Any, x: Any, energy: Any) -> None:
        """Add ``energy`` at the (wrapped) cell ``(th, y, x)``, keeping the arcs cache.

        Args:
            activity: the network's CPU buffer (written).
            th, y, x: the cell (numpy or Python integers).
            energy: a numpy float64 scalar: the sum rounds as float64, then to the
                activity's dtype.

        Shape:
            activity: ``(1, TH, Y, X)``.
        """
        act = activity.detach().numpy()[0]
        key = (activity.data_ptr(), activity._version)
        act[th, y, x] += energy
        if energy != 0 and self._arcs is not None and self._arcs_key == key:
            n_x, n_y, n_t = self.dims
            cell = (int(th), int(y), int(x))
            self._arcs = [
                F.arc_with(span, c, n)
                for span, c, n in zip(self._arcs, cell, (n_t, n_y, n_x), strict=True)
            ]
