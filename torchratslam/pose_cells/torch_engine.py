"""The torch engine: ``B`` pose-cell networks stepped on the whole network, any device.

``"separable"`` convolves with three 1D ring matrices per kernel (faster on CPU than
``conv1d``); ``"conv3d"`` runs one circular 3D convolution per kernel (the textbook
form). Both wrap on every axis.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells.decode import CentreDecoder
from torchratslam.pose_cells.motion import MotionTables

__all__ = ["TorchEngine"]

Circ = tuple[bool, bool, bool]


class TorchEngine:
    """Steps ``(B, TH, Y, X)`` activity with torch on the whole network.

    It holds no activity: every call takes the network's buffer. It caches the ring
    matrices, a scratch allocation and gather indices for its ``dtype`` and ``device``
    (:meth:`retarget` drops them).

    Args:
        params: pose-cell parameters.
        method: ``"separable"`` or ``"conv3d"`` (``"crop"``: see
            :class:`~torchratslam.pose_cells.crop_engine.CropEngine`).
        dtype: the activity's dtype.
        device: the activity's device.
    """

    def __init__(
        self, params: PoseCellParams, method: str, dtype: torch.dtype, device: Any
    ) -> None:
        n_x, n_y, th = params.dims
        self.params = params
        self.method = method
        self.dims = (n_x, n_y, th)
        self.dtype = dtype
        self.device = torch.device(device) if device is not None else torch.device("cpu")
        self.kernels = {
            "e": F.gaussian_kernel_1d(params.pc_w_e_dim, params.pc_w_e_var),
            "i": F.gaussian_kernel_1d(params.pc_w_i_dim, params.pc_w_i_var),
        }
        self.motion = MotionTables(params)
        self.decoder = CentreDecoder(params)
        self.last_crop: tuple[int, int, int] = (th, n_y, n_x)
        """The box (theta, y, x cells) the last step computed on."""
        self._mats: dict[tuple[str, int, bool], torch.Tensor] = {}
        self._work: torch.Tensor | None = None
        self._work_views: dict[tuple, list[torch.Tensor]] = {}
        self._gather_cache: dict[tuple, torch.Tensor] = {}

    # ------------------------------------------------------------ caches
    def retarget(self, dtype: torch.dtype, device: torch.device) -> None:
        """Follow the activity to a new dtype or device: drop every cache."""
        self.dtype, self.device = dtype, device
        self._mats = {}
        self._work = None
        self._work_views = {}
        self._gather_cache = {}
        self.invalidate()

    def invalidate(self) -> None:
        """Forget what was derived from the activity's contents (it was replaced)."""

    def matrix(self, which: str, n: int, circular: bool) -> torch.Tensor:
        """The ``(n, n)`` ring matrix of kernel ``which`` (``"e"`` or ``"i"``), cached."""
        key = (which, n, circular)
        m = self._mats.get(key)
        if m is None:
            m = torch.as_tensor(
                F.ring_matrix(self.kernels[which], n, circular),
                dtype=self.dtype,
                device=self.device,
            )
            self._mats[key] = m
        return m

    def matrices(
        self, which: str, shape: tuple[int, ...], circ: Circ
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(mt, my, mx)`` for a ``(B, T, Y, X)`` tensor; ``circ`` per axis (th, y, x)."""
        _, t, y, x = shape
        return (
            self.matrix(which, t, circ[0]),
            self.matrix(which, y, circ[1]),
            self.matrix(which, x, circ[2]),
        )

    def workspace(self, shape: tuple[int, ...], count: int) -> list[torch.Tensor]:
        """``count`` scratch tensors of ``shape``, carved from one reused allocation
        (a large step would otherwise allocate, and page-fault, a dozen big tensors).
        The views are cached per ``(shape, count)`` while the allocation stays."""
        key = (shape, count)
        views = self._work_views.get(key)
        if views is not None:
            return list(views)
        n = int(np.prod(shape))
        if self._work is None or self._work.numel() < n * count:
            self._work = torch.empty(n * count, dtype=self.dtype, device=self.device)
            self._work_views = {}
        views = [self._work[i * n : (i + 1) * n].view(shape) for i in range(count)]
        if len(self._work_views) > 64:  # crop shapes vary: keep the cache small
            self._work_views = {}
        self._work_views[key] = views
        return list(views)

    # ----------------------------------------------------------- dynamics
    def excite(self, activity: torch.Tensor) -> torch.Tensor:
        """Circular convolution with the excitatory kernel.

        Shape:
            activity: ``(B, TH, Y, X)``; returns the same shape.
        """
        if self.method == "conv3d":
            return F.circular_conv3d(activity, self.kernels["e"])
        mt, my, mx = self.matrices("e", tuple(activity.shape), (True, True, True))
        return F.separable_conv3d(activity, mt, my, mx)

    def inhibit(self, excited: torch.Tensor) -> torch.Tensor:
        """``excited`` minus its circular convolution with the inhibitory kernel.

        Shape:
            excited: ``(B, TH, Y, X)``; returns the same shape.
        """
        if self.method == "conv3d":
            return excited - F.circular_conv3d(excited, self.kernels["i"])
        mt, my, mx = self.matrices("i", tuple(excited.shape), (True, True, True))
        return excited - F.separable_conv3d(excited, mt, my, mx)

    def dynamics(self, a: torch.Tensor, circ: Circ) -> list[torch.Tensor]:
        """Excite, inhibit, global inhibition, clamp, normalise ``a`` with the separable
        kernels; ``circ`` per axis (th, y, x) says whether it wraps.

        Returns:
            Four workspace tensors of ``a``'s shape, the first holding the result.

        Shape:
            a: ``(B, T, Y, X)``.
        """
        shape = tuple(a.shape)
        return F.separable_dynamics_(
            a,
            self.matrices("e", shape, circ),
            self.matrices("i", shape, circ),
            self.params.pc_global_inhib,
            self.workspace(shape, 4),
        )

    def path_integrate(
        self,
        pool: list[torch.Tensor],
        trans: np.ndarray,
        rot: np.ndarray,
        th_start: np.ndarray,
        starts_yx: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> torch.Tensor:
        """Translate every theta layer (layer ``k`` of ``pool[0]`` is global layer
        ``th_start + k``) along its heading by ``trans`` cells (negative: backwards),
        then shift theta by ``rot`` cells. Returns the result (one of ``pool``).

        Args:
            pool: the activity and two scratch tensors of its shape.
            trans, rot: translation and rotation in cells, one per network.
            th_start: global theta layer of each network's first layer.
            starts_yx: the crop's global y and x starts (for the edge loss).

        Shape:
            pool: ``(B, T, Y, X)`` each; trans, rot, th_start: ``(B,)``.
        """
        mo = self.motion
        if trans.any():
            n_th = self.dims[2]
            k = (th_start[:, None] + np.arange(pool[0].shape[1])[None, :]) % n_th
            if mo.one_cell:
                plan = mo.translation_plan(trans, k)
                src = pool[0].clone() if mo.edge_loss else pool[0]
                F.shift_one_(pool, plan["step_x"], plan["w_x"], 3, self._gather_cache)
                F.shift_one_(pool, plan["step_y"], plan["w_y"], 2, self._gather_cache)
                if mo.edge_loss:
                    F.edge_loss_(pool[0], src, plan, starts_yx, (self.dims[1], self.dims[0]))
            else:
                direction = k * (2.0 * math.pi / n_th) + np.where(trans < 0, math.pi, 0.0)[:, None]
                mag = np.abs(trans)[:, None]
                cx, cy = mag * np.cos(direction), mag * np.sin(direction)
                if not mo.swap_axes:  # OpenRatSLAM: layer k along (sin, cos)
                    cx, cy = cy, cx
                F.shift_axis_(pool, cx, 3, self._gather_cache)
                F.shift_axis_(pool, cy, 2, self._gather_cache)
        if rot.any():
            F.shift_axis_(pool, rot, 1, self._gather_cache)
        return pool[0]

    # --------------------------------------------------------------- step
    def step(
        self, activity: torch.Tensor, trans: np.ndarray, rot: np.ndarray
    ) -> torch.Tensor | np.ndarray:
        """One step of every network in place: dynamics, then path integration.

        Args:
            activity: the network's buffer (written).
            trans, rot: translation and rotation in cells, one per network.

        Returns:
            The flat index of each network's most active cell.

        Shape:
            activity: ``(B, TH, Y, X)``; trans, rot: ``(B,)``; returns ``(B,)``.
        """
        if self.method == "conv3d":
            a = F.normalise(
                F.global_inhibition(
                    self.inhibit(self.excite(activity)), self.params.pc_global_inhib
                )
            )
            pool = [a, torch.empty_like(a), torch.empty_like(a)]
        else:
            pool = self.dynamics(activity, (True, True, True))
        b = activity.shape[0]
        a = self.path_integrate(pool, trans, rot, np.zeros(b, dtype=np.int64))
        activity.copy_(a)
        self.invalidate()
        t, y, x = activity.shape[1:]
        self.last_crop = (t, y, x)
        return F.peak_index(activity)

    def inject(
        self,
        activity: torch.Tensor,
        th: np.ndarray,
        y: np.ndarray,
        x: np.ndarray,
        energy: np.ndarray,
    ) -> None:
        """Add ``energy`` at the (wrapped) cells, one per network.

        Shape:
            activity: ``(B, TH, Y, X)``; th, y, x, energy: ``(B,)``.
        """
        F.inject_(activity, th, y, x, energy)

    def decode(self, activity: torch.Tensor, peak: torch.Tensor | np.ndarray) -> torch.Tensor:
        """Population-vector centre of the cube of ``+-pc_cells_to_avg`` cells around
        each network's flat ``peak``, with wrap.

        Shape:
            activity: ``(B, TH, Y, X)``; peak: ``(B,)``; returns ``(B, 3)`` float64 (CPU).
        """
        pk = peak.cpu().numpy() if isinstance(peak, torch.Tensor) else np.asarray(peak)
        act: Any = activity.detach()
        act = act.numpy() if act.device.type == "cpu" else act.cpu().numpy()
        return torch.from_numpy(self.decoder.decode_batch(act, pk))
