"""The crop engine: torch steps computed on a box around the packet.

The activity is one packet and exactly zero elsewhere, so only a box around the
non-zero cells (per axis the shortest wrapped arc that holds them) plus a halo
(excitation + inhibition reach + path-integration shift) can change. The step runs on
that box with zero-padded (Toeplitz) 1D kernels and writes it back. This is exact
because every cell outside the box is zero before and after the step; an axis whose box
would not be smaller than the ring is processed whole (circular). Several packets far
apart (after an injection) simply make the box the whole ring.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.errors import InputError
from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells.torch_engine import TorchEngine

__all__ = ["CropEngine"]

Occupancy = tuple[np.ndarray, np.ndarray, np.ndarray]


class CropEngine(TorchEngine):
    """:class:`~torchratslam.pose_cells.torch_engine.TorchEngine` on the packet's box.

    It also caches which theta / y / x indices hold activity, keyed by the buffer's
    ``(data_ptr, _version)`` so that a write by anyone else is noticed.

    Args:
        params: pose-cell parameters.
        dtype: the activity's dtype.
        device: the activity's device.
        crop_fraction: a step whose box holds more than this fraction of the cells
            runs on the whole network (separable).
    """

    def __init__(
        self, params: PoseCellParams, dtype: torch.dtype, device: Any, crop_fraction: float
    ) -> None:
        super().__init__(params, "crop", dtype, device)
        self.crop_fraction = crop_fraction
        # cells the dynamics can reach: excitation, then inhibition of the excited activity
        self.reach = params.pc_w_e_dim // 2 + params.pc_w_i_dim // 2
        self._occ: Occupancy | None = None
        self._occ_key: tuple[int, int] | None = None

    def invalidate(self) -> None:
        self._occ = None

    def occupancy(self, activity: torch.Tensor) -> Occupancy:
        """Which theta / y / x indices hold non-zero activity, ``(B, n)`` each (cached
        between steps while nobody else writes into the buffer)."""
        key = (activity.data_ptr(), activity._version)
        if self._occ is None or self._occ_key != key:
            nz: Any = (activity != 0).cpu().numpy()
            self._occ = (nz.any(axis=(2, 3)), nz.any(axis=(1, 3)), nz.any(axis=(1, 2)))
            self._occ_key = key
        return self._occ

    def _box(
        self, occ: Occupancy, trans: np.ndarray, rot: np.ndarray
    ) -> tuple[list[np.ndarray], list[int], list[bool]]:
        """Per axis (th, y, x): the box's start per network, its length, and whether it
        is the whole ring."""
        b = occ[0].shape[0]
        n_x, n_y, n_t = self.dims
        move_xy = math.ceil(float(np.abs(trans).max())) + 1 if trans.any() else 0
        move_th = math.ceil(float(np.abs(rot).max())) + 1 if rot.any() else 0
        margins = (self.reach + move_th, self.reach + move_xy, self.reach + move_xy)
        starts, lengths, circ = [], [], []
        for o, n, m in zip(occ, (n_t, n_y, n_x), margins, strict=True):
            s, ln = F.minimal_arcs(o)
            if (ln == 0).any():
                raise InputError(
                    "pose-cell activity is all zero; reset() or inject() before stepping"
                )
            length = int(ln.max()) + 2 * m
            if length >= n:
                starts.append(np.zeros(b, dtype=np.int64))
                lengths.append(n)
                circ.append(True)
            else:
                starts.append(s - m)
                lengths.append(length)
                circ.append(False)
        return starts, lengths, circ

    def step(
        self, activity: torch.Tensor, trans: np.ndarray, rot: np.ndarray
    ) -> torch.Tensor | np.ndarray:
        """:meth:`TorchEngine.step` on the packet's box (the whole network when the box
        holds more than ``crop_fraction`` of the cells).

        Shape:
            activity: ``(B, TH, Y, X)``; trans, rot: ``(B,)``; returns ``(B,)``.
        """
        b = activity.shape[0]
        n_x, n_y, n_t = self.dims
        starts, lengths, circ = self._box(self.occupancy(activity), trans, rot)
        lt, ly, lx = lengths
        if lt * ly * lx > self.crop_fraction * n_t * n_y * n_x:
            return super().step(activity, trans, rot)
        self.last_crop = (lt, ly, lx)
        idx = [
            np.remainder(s[:, None] + np.arange(ln)[None, :], n)
            for s, ln, n in zip(starts, lengths, (n_t, n_y, n_x), strict=True)
        ]
        it, iy, ix = idx
        flat_np = (
            it[:, :, None, None] * (n_y * n_x) + iy[:, None, :, None] * n_x + ix[:, None, None, :]
        )
        flat = torch.from_numpy(flat_np.reshape(b, -1)).to(self.device)
        act = activity.view(b, -1)
        crop = torch.gather(act, 1, flat).view(b, lt, ly, lx)
        pool = self.dynamics(crop, (circ[0], circ[1], circ[2]))
        a = self.path_integrate(pool, trans, rot, starts[0], (starts[1], starts[2]))
        a = a.reshape(b, -1)
        act.scatter_(1, flat, a)
        # the new occupancy, from the crop (every other cell is zero)
        nz: Any = (a != 0).cpu().numpy().reshape(b, lt, ly, lx)
        nz_t = nz.any(axis=3)
        new_occ = []
        for axis_i, (o_crop, n) in enumerate(
            zip(
                (nz_t.any(axis=2), nz_t.any(axis=1), nz.any(axis=(1, 2))),
                (n_t, n_y, n_x),
                strict=True,
            )
        ):
            o = np.zeros((b, n), dtype=bool)
            np.put_along_axis(o, idx[axis_i], o_crop, axis=1)
            new_occ.append(o)
        self._occ = (new_occ[0], new_occ[1], new_occ[2])
        self._occ_key = (activity.data_ptr(), activity._version)
        # the most active cell; ties go to the lowest (th, y, x) index as in a full scan
        top = a.amax(dim=1, keepdim=True)
        return torch.where(a == top, flat, n_t * n_y * n_x).amin(dim=1)

    def inject(
        self,
        activity: torch.Tensor,
        th: np.ndarray,
        y: np.ndarray,
        x: np.ndarray,
        energy: np.ndarray,
    ) -> None:
        """:meth:`TorchEngine.inject`, keeping the occupancy cache up to date.

        Shape:
            activity: ``(B, TH, Y, X)``; th, y, x, energy: ``(B,)``.
        """
        occ = self.occupancy(activity)
        super().inject(activity, th, y, x, energy)
        on = energy != 0
        rows = np.arange(activity.shape[0])[on]
        occ[0][rows, th[on]] = True
        occ[1][rows, y[on]] = True
        occ[2][rows, x[on]] = True
        self._occ_key = (activity.data_ptr(), activity._version)
