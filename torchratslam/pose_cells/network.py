"""The RatSLAM pose-cell network: a 3D continuous attractor network in PyTorch.

Two classes:

* :class:`PoseCellNetwork` -- the attractor itself, ``B`` independent networks in one
  ``(B, TH, Y, X)`` buffer (``x`` is the last axis, ``y`` the middle one). One
  :meth:`~PoseCellNetwork.step` is OpenRatSLAM's ``on_odo``: excite, inhibit, global
  inhibition and clamp, normalise, path integration, packet centre.
* :class:`PoseCells` -- the RatSLAM pose-cell *module*: one network plus the
  template/experience bookkeeping of OpenRatSLAM's ``PosecellNetwork`` (where each
  template and each experience was learnt, template decay, energy injection) and the
  action rule that tells the experience map what to do. Registered as ``"ratslam"`` in
  :data:`torchratslam.registry.POSE_CELLS`.

How the dynamics are computed (all give the same numbers up to rounding; ``make bench``
compares them):

* ``"conv3d"``: one circular 3D convolution per kernel (the textbook form).
* ``"separable"``: the Gaussian kernel with one variance on all axes is a product of
  three 1D kernels, so each 3D convolution is three 1D circular convolutions; each is a
  matrix product with a small circulant matrix (faster on CPU than ``conv1d``).
* ``"crop"``: the activity is one packet and exactly zero elsewhere, so
  only a box around the non-zero cells (per axis the shortest wrapped arc that holds
  them) plus a halo (excitation + inhibition reach + path-integration shift) can change.
  The step runs on that box with zero-padded (Toeplitz) 1D kernels and writes it back.
  This is exact because every cell outside the box is zero before and after the step;
  an axis whose box would not be smaller than the ring is processed whole (circular).
  Several packets far apart (after an injection) simply make the box the whole ring.
* ``"auto"`` (the default) picks ``"crop"`` when a typical packet's box is a small part
  of the network (large networks, batches), else ``"separable"``.

Deviations from OpenRatSLAM (deliberate):

* Path integration supports shifts of more than one cell per step (integer part as a
  roll, fractional part bilinear); up to one cell it equals OpenRatSLAM's four-neighbour
  weighting.
* Templates among the last 10 learnt never inject energy, also while fewer than 10
  exist (OpenRatSLAM's unsigned ``size - 10`` wraps then and injects anyway); this
  follows the algorithm notes ("except one of the last 10").
* The packet centre is decoded with angles ``2 pi i / dim`` (OpenRatSLAM uses
  ``i + 1`` and subtracts one cell afterwards: the same value).

Kept from OpenRatSLAM: the Gaussian weights use the configured "variance" as the
standard deviation (``exp(-d^2 / (2 var^2))``), and an action is only decided when a
view template and odometry have both arrived since the last decision.
"""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from torchratslam.config import PoseCellParams
from torchratslam.graph.errors import ConfigError, InputError, MapFormatError
from torchratslam.graph.geometry import pc_distance
from torchratslam.graph.messages import Action, ActionKind
from torchratslam.messages import ViewMatch
from torchratslam.registry import POSE_CELLS

__all__ = [
    "METHODS",
    "PoseCellNetwork",
    "PoseCells",
    "gaussian_kernel_1d",
    "pc_distance",
]

METHODS = ("auto", "crop", "separable", "conv3d")
"""Ways to compute the excitation/inhibition (see the module docstring); ``"auto"``
picks ``"crop"`` when a typical packet's box is at most ``crop_fraction`` of the
network, else ``"separable"``."""

TYPICAL_PACKET = (9, 7, 7)
"""Non-zero extent (theta, y, x cells) of a settled packet with the default kernels,
used by ``method="auto"`` to guess whether cropping pays."""

RECENT_TEMPLATES = 10
"""Templates among the last this many learnt do not inject energy."""


def gaussian_kernel_1d(dim: int, var: float) -> np.ndarray:
    """OpenRatSLAM's 1D Gaussian weights, normalised to sum 1.

    The weight at offset ``d = i - dim // 2`` (``i = 0 .. dim-1``) is proportional to
    ``exp(-d**2 / (2 var**2))``: OpenRatSLAM's ``norm2d`` uses the configured
    "variance" as the standard deviation, and so does this project. The 3D kernel is
    the outer product of three of these.

    Args:
        dim: kernel side (``pc_w_e_dim`` or ``pc_w_i_dim``).
        var: the configured variance (``pc_w_e_var`` or ``pc_w_i_var``).

    Returns:
        ``(dim,)`` float64 weights.
    """
    d = np.arange(dim, dtype=np.float64) - dim // 2
    w = np.exp(-(d * d) / (2.0 * var * var))
    return w / w.sum()


def _ring_matrix(kernel: np.ndarray, n: int, circular: bool) -> np.ndarray:
    """``(n, n)`` matrix M with ``(M @ v)[p] = sum_d kernel[d + h] v[p - d]``.

    ``circular``: indices wrap (a circulant matrix; kernel taps that alias the same
    offset, when the kernel is longer than the ring, add up). Otherwise ``v`` is zero
    outside ``0..n-1`` (a banded Toeplitz matrix).
    """
    h = len(kernel) // 2
    m = np.zeros((n, n), dtype=np.float64)
    p = np.arange(n)
    for i, w in enumerate(kernel):  # kernel taps only (at most pc_w_e_dim), not cells
        q = p - (i - h)
        if circular:
            np.add.at(m, (p, q % n), w)
        else:
            ok = (q >= 0) & (q < n)
            m[p[ok], q[ok]] += w
    return m


def _minimal_arcs(occ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the shortest circular arc holding every True entry.

    Args:
        occ: ``(B, n)`` boolean occupancy of one ring axis.

    Returns:
        ``start (B,)`` and ``length (B,)``; length 0 for an empty row.
    """
    b, n = occ.shape
    occ2 = np.concatenate([occ, occ], axis=1)
    idx = np.where(occ2, np.arange(2 * n), -1)
    prev = np.maximum.accumulate(idx, axis=1)  # last True at or before j
    j = np.arange(n, 2 * n)
    gap = np.where(occ, j - prev[:, n - 1 : 2 * n - 1] - 1, -1)  # empty run before each True
    best = gap.argmax(axis=1)
    big = gap[np.arange(b), best]
    length = np.where(occ.any(axis=1), n - big, 0)
    return best.astype(np.int64), length.astype(np.int64)


def _as_batch(value: Any, batch: int, name: str, dtype: Any = np.float64) -> np.ndarray:
    """A scalar or ``(batch,)`` value as a ``(batch,)`` numpy array."""
    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().numpy()
    arr = np.asarray(value, dtype=dtype)
    if arr.ndim == 0:
        return np.full(batch, arr, dtype=dtype)
    if arr.shape != (batch,):
        raise InputError(f"{name} must be a scalar or have shape ({batch},), got {arr.shape}")
    return arr


class PoseCellNetwork(nn.Module):
    """``B`` independent RatSLAM pose-cell networks (no learnable parameters).

    Args:
        params: pose-cell parameters.
        batch_size: number of independent networks ``B``.
        dtype: float32 (default) or float64.
        device: torch device.
        method: ``"auto"`` (default), ``"crop"``, ``"separable"`` or ``"conv3d"``
            (module docstring).
        crop_fraction: ``"crop"`` falls back to the whole network (separable) in a step
            whose box holds more than this fraction of the cells; default 0.5 for
            ``B == 1`` (where per-operation overhead dominates) and 0.8 for batches.

    Attributes:
        activity: buffer ``(B, TH, Y, X)``, non-negative, each network summing to 1.
        dims: ``(X, Y, TH)``.

    Example:
        >>> net = PoseCellNetwork(PoseCellParams(pc_dim_xy=11))
        >>> c = net.step(0.5, 0.0, 1.0)  # half a cell along theta layer 18's heading
        >>> tuple(c.shape)
        (1, 3)
    """

    activity: torch.Tensor

    def __init__(
        self,
        params: PoseCellParams,
        batch_size: int = 1,
        *,
        dtype: torch.dtype = torch.float32,
        device: Any = None,
        method: str = "auto",
        crop_fraction: float | None = None,
    ) -> None:
        super().__init__()
        if not isinstance(params, PoseCellParams):
            raise ConfigError(f"PoseCellNetwork needs PoseCellParams, got {type(params).__name__}")
        if int(batch_size) < 1:
            raise ConfigError(f"batch_size must be >= 1, got {batch_size}")
        if method not in METHODS:
            raise ConfigError(f"unknown pose-cell method {method!r} (valid: {', '.join(METHODS)})")
        if dtype not in (torch.float32, torch.float64):
            raise ConfigError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
        self.params = params
        self.batch_size = int(batch_size)
        self.requested_method = method
        if crop_fraction is None:  # one network is overhead-bound, a batch compute-bound
            crop_fraction = 0.5 if int(batch_size) == 1 else 0.8
        self.crop_fraction = float(crop_fraction)
        xy, th = params.pc_dim_xy, params.pc_dim_th
        self.dims = (xy, xy, th)
        self._ke = gaussian_kernel_1d(params.pc_w_e_dim, params.pc_w_e_var)
        self._ki = gaussian_kernel_1d(params.pc_w_i_dim, params.pc_w_i_var)
        # cells the dynamics can reach: excitation, then inhibition of the excited activity
        self._reach = params.pc_w_e_dim // 2 + params.pc_w_i_dim // 2
        if method == "auto":
            box = [
                min(e + 2 * (self._reach + 2), n)
                for e, n in zip(TYPICAL_PACKET, (th, xy, xy), strict=True)
            ]
            small = box[0] * box[1] * box[2] <= self.crop_fraction * th * xy * xy
            method = "crop" if small else "separable"
        self.method = method
        self.register_buffer(
            "activity", torch.zeros(self.batch_size, th, xy, xy, dtype=dtype, device=device)
        )
        self._mats: dict[tuple[str, int, bool], torch.Tensor] = {}
        self._work: torch.Tensor | None = None
        self._work_views: dict[tuple, list[torch.Tensor]] = {}
        self._gather_cache: dict[tuple, torch.Tensor] = {}
        self._occ: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._occ_key: tuple[int, int] | None = None
        self.last_crop: tuple[int, int, int] = (th, xy, xy)
        self._best = torch.zeros(self.batch_size, 3, dtype=torch.float64)
        self._ring_key: tuple | None = None
        self._ring_cache: list[tuple[np.ndarray, np.ndarray, int]] = []
        self.reset()

    # ------------------------------------------------------------------ state
    @property
    def dtype(self) -> torch.dtype:
        return self.activity.dtype

    @property
    def device(self) -> torch.device:
        return self.activity.device

    def reset(self) -> None:
        """Activity 1 at cell ``floor(dim / 2)`` on every axis, in every network."""
        x, y, th = (d // 2 for d in self.dims)
        with torch.no_grad():
            self.activity.zero_()
            self.activity[:, th, y, x] = 1.0
        self._best = torch.tensor([[x, y, th]], dtype=torch.float64).repeat(self.batch_size, 1)
        self._occ = None

    def centre(self, recompute: bool = False) -> torch.Tensor:
        """The packet centre ``(x, y, th)`` in cells (float64), one row per network.

        Args:
            recompute: decode it from the current activity now. By default the value
                decoded at the end of the last :meth:`step` is returned (OpenRatSLAM's
                ``best_x/y/th``: injections move it only at the next step); before any
                step it is the start cell.

        Returns:
            ``(B, 3)`` float64 tensor.
        """
        if recompute:
            with torch.no_grad():
                peak = torch.argmax(self.activity.reshape(self.batch_size, -1), dim=1)
                self._best = self._decode(peak)
        return self._best.clone()

    # -------------------------------------------------------------- kernels
    def _matrix(self, which: str, n: int, circular: bool) -> torch.Tensor:
        key = (which, n, circular)
        m = self._mats.get(key)
        if m is None:
            kernel = self._ke if which == "e" else self._ki
            m = torch.as_tensor(
                _ring_matrix(kernel, n, circular), dtype=self.dtype, device=self.device
            )
            self._mats[key] = m
        return m

    def _conv_sep(self, a: torch.Tensor, which: str, circ: tuple[bool, bool, bool]) -> torch.Tensor:
        """Separable 3D convolution of ``a`` (B, T, Y, X); ``circ`` per axis (th, y, x)."""
        b, t, y, x = a.shape
        mt = self._matrix(which, t, circ[0])
        my = self._matrix(which, y, circ[1])
        mx = self._matrix(which, x, circ[2])
        out = a @ mx.T
        out = my @ out
        out = (mt @ out.reshape(b, t, y * x)).reshape(b, t, y, x)
        return out

    def _conv3d(self, a: torch.Tensor, which: str) -> torch.Tensor:
        dim = self.params.pc_w_e_dim if which == "e" else self.params.pc_w_i_dim
        k1 = torch.as_tensor(
            self._ke if which == "e" else self._ki, dtype=self.dtype, device=self.device
        )
        k3 = (k1[:, None, None] * k1[None, :, None] * k1[None, None, :])[None, None]
        h = dim // 2
        lo, hi = h, dim - 1 - h  # taps before/after the centre
        if max(lo, hi) > min(a.shape[1:]):
            raise ConfigError(
                f"method 'conv3d' needs kernel halves <= the network dims {self.dims}; "
                "use method 'separable' or 'crop'"
            )
        # F.conv3d is a correlation: flip the kernel so this is OpenRatSLAM's scatter.
        k3 = torch.flip(k3, dims=(2, 3, 4))
        pad = (hi, lo, hi, lo, hi, lo)  # flipped kernel: the larger side pads first
        v = a.unsqueeze(1)
        v = torch.nn.functional.pad(v, pad, mode="circular")
        return torch.nn.functional.conv3d(v, k3).squeeze(1)

    def excite(self, activity: torch.Tensor) -> torch.Tensor:
        """Circular convolution with the normalised excitatory kernel (no state change).

        Shape:
            activity: ``(B, TH, Y, X)``; returns the same shape.
        """
        if self.method == "conv3d":
            return self._conv3d(activity, "e")
        return self._conv_sep(activity, "e", (True, True, True))

    def inhibit(self, excited: torch.Tensor) -> torch.Tensor:
        """``excited`` minus its circular convolution with the inhibitory kernel.

        Shape:
            excited: ``(B, TH, Y, X)``; returns the same shape.
        """
        if self.method == "conv3d":
            return excited - self._conv3d(excited, "i")
        return excited - self._conv_sep(excited, "i", (True, True, True))

    def path_integrate(self, activity: torch.Tensor, trans: Any, rot: Any) -> torch.Tensor:
        """Path integration alone (no state change): every theta layer ``k`` moves
        ``trans`` cells along heading ``k 2 pi / TH`` (backwards when negative), bilinear
        with wrap; then the layers move ``rot`` cells in theta (linear interpolation).

        Args:
            activity: the activity to move.
            trans: translation in cells (``vtrans * dt / pc_cell_x_size``).
            rot: rotation in theta cells (``vrot * dt / (2 pi / TH)``).

        Shape:
            activity: ``(B, TH, Y, X)``; trans, rot: scalars or ``(B,)``.
        """
        b = activity.shape[0]
        t = _as_batch(trans, b, "trans")
        r = _as_batch(rot, b, "rot")
        with torch.no_grad():
            pool = [activity.clone(), torch.empty_like(activity), torch.empty_like(activity)]
            return self._path_integrate(pool, t, r, np.zeros(b, dtype=np.int64)).clone()

    # ----------------------------------------------------------------- step
    def step(self, vtrans: Any, vrot: Any, dt: Any = 1.0) -> torch.Tensor:
        """One OpenRatSLAM ``on_odo``: dynamics, path integration, packet centre.

        Args:
            vtrans: forward speed (m/s); a scalar or one per network.
            vrot: turn rate (rad/s, counter-clockwise); a scalar or one per network.
            dt: time step (s); a scalar or one per network.

        Shape:
            vtrans, vrot, dt: scalars or ``(B,)``.

        Returns:
            The packet centres ``(B, 3)`` (x, y, th cells, float64).

        Raises:
            InputError: odometry of the wrong shape or not finite, or activity that died
                out (every cell at or below ``pc_global_inhib``).
        """
        b = self.batch_size
        if b == 1 and type(vtrans) is float and type(vrot) is float and type(dt) is float:
            vt, vr, d = np.array([vtrans]), np.array([vrot]), np.array([dt])  # fast path
            finite = math.isfinite(vtrans) and math.isfinite(vrot) and math.isfinite(dt)
        else:
            vt = _as_batch(vtrans, b, "vtrans")
            vr = _as_batch(vrot, b, "vrot")
            d = _as_batch(dt, b, "dt")
            finite = np.isfinite(vt).all() and np.isfinite(vr).all() and np.isfinite(d).all()
        if not finite:
            raise InputError(f"odometry must be finite, got vtrans={vtrans}, vrot={vrot}, dt={dt}")
        trans = vt * d / self.params.pc_cell_x_size  # cells along each layer's heading
        rot = vr * d / (2.0 * math.pi / self.dims[2])  # theta cells
        with torch.no_grad():
            if self.method == "crop":
                peak = self._step_crop(trans, rot)
            else:
                peak = self._step_full(trans, rot)
            self._best = self._decode(peak)
        return self._best.clone()

    def _step_full(self, trans: np.ndarray, rot: np.ndarray) -> torch.Tensor | np.ndarray:
        if self.method == "conv3d":
            a = self._finish_dynamics(self.inhibit(self.excite(self.activity)))
            pool = [a, torch.empty_like(a), torch.empty_like(a)]
        else:
            pool = self._dynamics(self.activity, (True, True, True))
        a = self._path_integrate(pool, trans, rot, np.zeros(self.batch_size, dtype=np.int64))
        self.activity.copy_(a)
        self._occ = None
        self.last_crop = cast(tuple[int, int, int], tuple(self.activity.shape[1:]))
        return self._argmax()

    def _argmax(self) -> torch.Tensor | np.ndarray:
        """Flat index of the most active cell of each network (first on ties)."""
        act = self.activity.detach().reshape(self.batch_size, -1)
        if act.device.type == "cpu":  # numpy's argmax has less per-call overhead
            return act.numpy().argmax(axis=1)
        return torch.argmax(act, dim=1)

    def _workspace(self, shape: tuple[int, ...], count: int) -> list[torch.Tensor]:
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

    def _dynamics(self, a: torch.Tensor, circ: tuple[bool, bool, bool]) -> list[torch.Tensor]:
        """Excite, inhibit, global inhibition, clamp, normalise ``a`` (B, T, Y, X) with
        the separable kernels; ``circ`` per axis (th, y, x) says whether it wraps.

        Returns:
            Four workspace tensors of ``a``'s shape, the first holding the result.
        """
        b, t, y, x = a.shape
        out, s1, s2, e = self._workspace((b, t, y, x), 4)
        for which, src, dst in (("e", a, e), ("i", e, out)):
            mt = self._matrix(which, t, circ[0])
            my = self._matrix(which, y, circ[1])
            mx = self._matrix(which, x, circ[2])
            torch.matmul(src, mx.T, out=s1)
            torch.matmul(my, s1, out=s2)
            torch.matmul(mt, s2.view(b, t, y * x), out=dst.view(b, t, y * x))
        torch.sub(e, out, out=out)
        out.sub_(self.params.pc_global_inhib).clamp_min_(0.0)
        total = out.sum(dim=(1, 2, 3), keepdim=True)
        if not bool((total > 0).all()):
            raise InputError(
                "pose-cell activity died out (every cell <= pc_global_inhib); lower "
                "pc_global_inhib or reset()/inject() the network"
            )
        out.div_(total)
        return [out, s1, s2, e]

    def _finish_dynamics(self, a: torch.Tensor) -> torch.Tensor:
        a = torch.clamp_min(a - self.params.pc_global_inhib, 0.0)
        total = a.sum(dim=(1, 2, 3), keepdim=True)
        if not bool((total > 0).all()):
            raise InputError(
                "pose-cell activity died out (every cell <= pc_global_inhib); lower "
                "pc_global_inhib or reset()/inject() the network"
            )
        return a / total

    def _shift_axis(self, pool: list[torch.Tensor], shift: np.ndarray, axis: int) -> None:
        """Move the content of ``pool[0]`` by ``shift`` cells along ``axis``, wrapping on
        the tensor's own length: integer part by a gather, fraction by linear weights.
        The result becomes ``pool[0]`` (the other entries are scratch of the same shape).

        ``shift`` is ``(B,)`` (theta) or ``(B, T)`` (one shift per theta layer).
        """
        a, g0 = pool[0], pool[1]
        n = a.shape[axis]
        fl = np.floor(shift)
        frac = shift - fl
        shape = [1, 1, 1, 1]
        shape[axis] = n
        lead = shift.shape + (1,) * (4 - shift.ndim)
        ints = fl.astype(np.int64)
        dev = a.device
        if (ints == ints.flat[0]).all():  # one integer shift for everything: a roll
            g0.copy_(torch.roll(a, int(ints.flat[0]), dims=axis))
        else:  # the integer parts repeat from step to step: cache their gather index
            key = (axis, tuple(a.shape), ints.tobytes(), ints.shape, dev)
            index = self._gather_cache.get(key)
            if index is None:
                idx = np.remainder(np.arange(n).reshape(shape) - ints.reshape(lead), n)
                index = torch.from_numpy(idx).to(dev).expand(a.shape)
                if len(self._gather_cache) > 256:
                    self._gather_cache = {}
                self._gather_cache[key] = index
            torch.gather(a, axis, index, out=g0)
        if frac.any():
            w = torch.from_numpy(frac.reshape(lead)).to(device=dev, dtype=a.dtype)
            torch.lerp(g0, torch.roll(g0, 1, dims=axis), w, out=g0)
        pool[0], pool[1] = g0, a

    def _path_integrate(
        self, pool: list[torch.Tensor], trans: np.ndarray, rot: np.ndarray, th_start: np.ndarray
    ) -> torch.Tensor:
        """Translate every theta layer (layer ``k`` of ``pool[0]`` is global layer
        ``th_start + k``) along its heading by ``trans`` cells (negative: backwards),
        then shift theta by ``rot`` cells. Returns the result (one of ``pool``)."""
        if trans.any():
            n_th = self.dims[2]
            k = (th_start[:, None] + np.arange(pool[0].shape[1])[None, :]) % n_th
            direction = k * (2.0 * math.pi / n_th) + np.where(trans < 0, math.pi, 0.0)[:, None]
            mag = np.abs(trans)[:, None]
            self._shift_axis(pool, mag * np.cos(direction), 3)
            self._shift_axis(pool, mag * np.sin(direction), 2)
        if rot.any():
            self._shift_axis(pool, rot, 1)
        return pool[0]

    def _occupancy(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Which theta / y / x indices hold non-zero activity, ``(B, n)`` each (cached
        between steps while nobody else writes into the buffer)."""
        key = (self.activity.data_ptr(), self.activity._version)
        if self._occ is None or self._occ_key != key:
            nz: Any = (self.activity != 0).cpu().numpy()
            self._occ = (nz.any(axis=(2, 3)), nz.any(axis=(1, 3)), nz.any(axis=(1, 2)))
            self._occ_key = key
        return self._occ

    def _step_crop(self, trans: np.ndarray, rot: np.ndarray) -> torch.Tensor | np.ndarray:
        b = self.batch_size
        n_x, n_y, n_t = self.dims
        occ = self._occupancy()
        move_xy = math.ceil(float(np.abs(trans).max())) + 1 if trans.any() else 0
        move_th = math.ceil(float(np.abs(rot).max())) + 1 if rot.any() else 0
        margins = (self._reach + move_th, self._reach + move_xy, self._reach + move_xy)
        starts, lengths, circ = [], [], []
        for o, n, m in zip(occ, (n_t, n_y, n_x), margins, strict=True):
            s, ln = _minimal_arcs(o)
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
        lt, ly, lx = lengths
        if lt * ly * lx > self.crop_fraction * n_t * n_y * n_x:
            return self._step_full(trans, rot)
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
        act = self.activity.view(b, -1)
        crop = torch.gather(act, 1, flat).view(b, lt, ly, lx)
        pool = self._dynamics(crop, (circ[0], circ[1], circ[2]))
        a = self._path_integrate(pool, trans, rot, starts[0]).reshape(b, -1)
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
        self._occ_key = (self.activity.data_ptr(), self.activity._version)
        # the most active cell; ties go to the lowest (th, y, x) index as in a full scan
        top = a.amax(dim=1, keepdim=True)
        return torch.where(a == top, flat, n_t * n_y * n_x).amin(dim=1)

    # --------------------------------------------------------------- decode
    def _rings(self) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """Per axis (x, y, th): the wrapped ``+-pc_cells_to_avg`` window of every cell,
        ``(n, 2c + 1)``, the unit phasors ``exp(2 pi i k / n)``, and ``n`` (cached)."""
        c = self.params.pc_cells_to_avg
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

    def _decode(self, peak: torch.Tensor | np.ndarray) -> torch.Tensor:
        """Population-vector centre of the cube of ``+-pc_cells_to_avg`` cells around
        the most active cell (flat index ``peak``, one per network), with wrap."""
        b = self.batch_size
        n_x, n_y, n_t = self.dims
        pk = peak.cpu().numpy() if isinstance(peak, torch.Tensor) else np.asarray(peak)
        pt, py, px = pk // (n_y * n_x), (pk // n_x) % n_y, pk % n_x
        (wx, ex, _), (wy, ey, _), (wt, et, _) = self._rings()
        ix, iy, it = wx[px], wy[py], wt[pt]  # (B, 2c + 1) each
        act: Any = self.activity.detach()
        act = act.numpy() if act.device.type == "cpu" else act.cpu().numpy()
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
            v = np.angle((sums * phasor[ring]).sum(1))
            pos = np.remainder(v * (n / (2.0 * math.pi)), float(n))
            out[:, col] = np.where(pos >= n, pos - n, pos)
        return torch.from_numpy(out)

    # --------------------------------------------------------------- inject
    def inject(self, x: Any, y: Any, th: Any, energy: Any) -> None:
        """Add ``energy`` at cell ``(x, y, th)`` of each network (indices wrap).

        Args:
            x, y, th: integer cell indices; scalars or one per network.
            energy: energy to add; a scalar or one per network (0: no injection).

        Shape:
            x, y, th, energy: scalars or ``(B,)``.
        """
        b = self.batch_size
        n_x, n_y, n_t = self.dims
        ix = np.remainder(_as_batch(x, b, "x", np.int64), n_x)
        iy = np.remainder(_as_batch(y, b, "y", np.int64), n_y)
        it = np.remainder(_as_batch(th, b, "th", np.int64), n_t)
        e = _as_batch(energy, b, "energy")
        if not np.isfinite(e).all():
            raise InputError(f"injected energy must be finite, got {energy}")
        occ = self._occupancy() if self.method == "crop" else None
        dev = self.device
        with torch.no_grad():
            index = tuple(torch.from_numpy(v).to(dev) for v in (np.arange(b), it, iy, ix))
            values = torch.from_numpy(e).to(device=dev, dtype=self.dtype)
            self.activity.index_put_(index, values, accumulate=True)
        if occ is not None:
            on = e != 0
            rows = np.arange(b)[on]
            occ[0][rows, it[on]] = True
            occ[1][rows, iy[on]] = True
            occ[2][rows, ix[on]] = True
            self._occ_key = (self.activity.data_ptr(), self.activity._version)

    def set_activity(self, activity: Any) -> None:
        """Replace the activity (e.g. a loaded or shifted map's), validated.

        Shape:
            activity: ``(B, TH, Y, X)`` or, for ``B == 1``, ``(TH, Y, X)``.
        """
        a = torch.as_tensor(
            np.asarray(activity) if not isinstance(activity, torch.Tensor) else activity
        )
        if a.ndim == 3:
            a = a.unsqueeze(0)
        if tuple(a.shape) != tuple(self.activity.shape):
            raise MapFormatError(
                f"pose-cell activity has shape {tuple(a.shape)}, the network needs "
                f"{tuple(self.activity.shape)} (check pc_dim_xy / pc_dim_th)"
            )
        if not bool(torch.isfinite(a).all()) or bool((a < 0).any()):
            raise MapFormatError("pose-cell activity must be finite and non-negative")
        with torch.no_grad():
            self.activity.copy_(a.to(self.dtype))
        self._occ = None


class PoseCells:
    """The RatSLAM pose-cell module (OpenRatSLAM's ``PosecellNetwork`` behaviour).

    It owns one :class:`PoseCellNetwork`, remembers the pose cell where each visual
    template and each experience was learnt, injects energy for familiar views and,
    after each odometry step, decides the experience-map
    :class:`~torchratslam.graph.messages.Action`.

    Call :meth:`on_view_template` and :meth:`on_odometry` once per frame; as in
    OpenRatSLAM an action is only decided once both have been received since the last
    decision (otherwise :meth:`on_odometry` returns ``NONE``).

    Args:
        params: pose-cell parameters.
        dtype: activity dtype (float32 default, float64 supported).
        device: torch device.
        method: dynamics method of the network (see :class:`PoseCellNetwork`).
    """

    def __init__(
        self,
        params: PoseCellParams | None = None,
        *,
        dtype: torch.dtype = torch.float32,
        device: Any = None,
        method: str = "auto",
    ) -> None:
        self.params = params if params is not None else PoseCellParams()
        self.network = PoseCellNetwork(self.params, 1, dtype=dtype, device=device, method=method)
        self.dims = self.network.dims
        self._clear()

    def _clear(self) -> None:
        self.template_pc = np.zeros((0, 3), dtype=np.float64)
        self.template_decay = np.zeros(0, dtype=np.float64)
        self.exp_pc = np.zeros((0, 3), dtype=np.float64)
        self.exp_template = np.zeros(0, dtype=np.int64)
        self._template_exps: dict[int, list[int]] = {}
        self.current_exp = -1
        self.current_vt = -1
        self.prev_vt = -1
        self.vt_delta_pc_th = 0.0
        self.relative_rad = 0.0
        self._odo_update = False
        self._vt_update = False
        self._best = cast(tuple[float, float, float], tuple(float(d // 2) for d in self.dims))

    def reset(self) -> None:
        """Back to the start: one active cell in the middle, no templates or experiences."""
        self.network.reset()
        self._clear()

    # ------------------------------------------------------------ accessors
    @property
    def centre(self) -> tuple[float, float, float]:
        """Packet centre ``(x, y, th)`` in cells, as decoded at the last odometry step."""
        return self._best

    @property
    def activity(self) -> torch.Tensor:
        """The activity. Shape: ``(TH, Y, X)`` (a view of the network's buffer)."""
        return self.network.activity[0]

    @property
    def n_templates(self) -> int:
        return int(self.template_pc.shape[0])

    @property
    def n_experiences(self) -> int:
        return int(self.exp_pc.shape[0])

    def template_experiences(self, template_id: int) -> list[int]:
        """Experience ids learnt with ``template_id``, in creation order."""
        return list(self._template_exps.get(int(template_id), []))

    # ---------------------------------------------------------------- input
    def on_view_template(self, match: ViewMatch) -> None:
        """Learn a new template at the packet centre, or inject energy for a known one.

        A template among the last 10 learnt injects nothing, also while fewer than 10
        exist (the reference notes' rule; OpenRatSLAM's unsigned arithmetic injects
        then). Re-seeing the current template raises its decay by ``vt_active_decay``;
        the energy ``pc_vt_inject_energy / 30 * (30 - exp(1.2 decay))`` goes, if
        positive, to the template's cell with theta corrected by the relative angle.
        Then every decay relaxes by ``pc_vt_restore`` (not below ``vt_active_decay``).

        Raises:
            InputError: a template id that skips ahead or is negative.
        """
        p = self.params
        vt = int(match.template_id)
        n = self.n_templates
        rad = float(match.relative_rad)
        if vt < 0 or vt > n:
            raise InputError(
                f"view template id {vt} is invalid: {n} templates are known, so the id "
                f"must be in 0..{n} ({n} = a new template)"
            )
        self.relative_rad = rad
        if vt == n:
            self.template_pc = np.concatenate([self.template_pc, np.asarray([self._best])], axis=0)
            self.template_decay = np.append(self.template_decay, p.vt_active_decay)
        elif vt < n - RECENT_TEMPLATES:
            if vt == self.current_vt:
                self.template_decay[vt] += p.vt_active_decay
            energy = p.pc_vt_inject_energy / 30.0 * (30.0 - math.exp(1.2 * self.template_decay[vt]))
            if energy > 0:
                n_th = self.dims[2]
                self.vt_delta_pc_th = rad / (2.0 * math.pi) * n_th
                pc_x, pc_y, pc_th = self.template_pc[vt]
                th = pc_th + self.vt_delta_pc_th
                if th < 0:
                    th += n_th
                if th >= n_th:
                    th -= n_th
                self.network.inject(int(pc_x), int(pc_y), int(th) % n_th, energy)
        self.template_decay = np.maximum(self.template_decay - p.pc_vt_restore, p.vt_active_decay)
        self.prev_vt = self.current_vt
        self.current_vt = vt
        self._vt_update = True

    def on_odometry(self, vtrans: float, vrot: float, dt: float) -> Action:
        """Run one network step with the odometry, then decide the action.

        Args:
            vtrans: forward speed (m/s).
            vrot: turn rate (rad/s).
            dt: interval (s).

        Returns:
            The :class:`~torchratslam.graph.messages.Action` for the experience map.
        """
        c = self.network.step(float(vtrans), float(vrot), float(dt))[0].tolist()
        self._best = (c[0], c[1], c[2])
        self._odo_update = True
        return self._decide()

    # --------------------------------------------------------------- action
    def _delta_pc(self, cells: np.ndarray) -> np.ndarray:
        """Distance of experience cells ``(..., 3)`` from the centre, whose theta is
        corrected by ``-vt_delta_pc_th`` (OpenRatSLAM's ``get_delta_pc``)."""
        n_th = self.dims[2]
        x, y, th = self._best
        th = th - self.vt_delta_pc_th
        if th < 0:
            th += n_th
        if th >= n_th:
            th -= n_th
        return pc_distance(cells, np.array([x, y, th]), self.dims)

    def _create(self) -> Action:
        src = self.current_exp
        new = self.n_experiences
        self.exp_pc = np.concatenate([self.exp_pc, np.asarray([self._best])], axis=0)
        self.exp_template = np.append(self.exp_template, self.current_vt)
        self._template_exps.setdefault(self.current_vt, []).append(new)
        self.current_exp = new
        return Action(ActionKind.CREATE, dest_id=new, src_id=src, relative_rad=self.relative_rad)

    def _decide(self) -> Action:
        if not (self._odo_update and self._vt_update):
            return Action.none()
        self._odo_update = self._vt_update = False
        if self.n_templates == 0:
            return Action.none()
        if self.n_experiences == 0:
            return self._create()
        exps = self._template_exps.get(self.current_vt, [])
        if not exps:
            return self._create()
        threshold = self.params.exp_delta_pc_threshold
        d_current = float(self._delta_pc(self.exp_pc[self.current_exp]))
        if d_current > threshold or self.current_vt != self.prev_vt:
            ids = np.asarray(exps, dtype=np.int64)
            ids = ids[ids != self.current_exp]
            if ids.size:
                d = self._delta_pc(self.exp_pc[ids])
                k = int(np.argmin(d))  # first minimum, as OpenRatSLAM's strict '<'
                if d[k] < threshold:
                    src = self.current_exp
                    self.current_exp = int(ids[k])
                    return Action(
                        ActionKind.LINK,
                        dest_id=self.current_exp,
                        src_id=src,
                        relative_rad=self.relative_rad,
                    )
            return self._create()
        return Action.none()

    # ---------------------------------------------------------------- state
    def get_state(self) -> dict[str, Any]:
        """Everything needed to continue bit-identically (numpy arrays / Python scalars).

        Keys: ``activity`` (TH, Y, X), ``template_pc`` (N, 3), ``template_decay`` (N,),
        ``exp_pc`` (M, 3), ``exp_template`` (M,), ``best`` (3,), ``current_exp``,
        ``current_vt``, ``prev_vt``, ``vt_delta_pc_th``, ``relative_rad``,
        ``odo_update``, ``vt_update``, ``pc_dim_xy``, ``pc_dim_th``.
        """
        return {
            "activity": self.activity.detach().cpu().numpy().copy(),
            "template_pc": self.template_pc.copy(),
            "template_decay": self.template_decay.copy(),
            "exp_pc": self.exp_pc.copy(),
            "exp_template": self.exp_template.copy(),
            "best": np.asarray(self._best, dtype=np.float64),
            "current_exp": int(self.current_exp),
            "current_vt": int(self.current_vt),
            "prev_vt": int(self.prev_vt),
            "vt_delta_pc_th": float(self.vt_delta_pc_th),
            "relative_rad": float(self.relative_rad),
            "odo_update": bool(self._odo_update),
            "vt_update": bool(self._vt_update),
            "pc_dim_xy": int(self.params.pc_dim_xy),
            "pc_dim_th": int(self.params.pc_dim_th),
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`get_state`'s dictionary.

        Missing optional keys take neutral values; an empty ``activity`` (a map
        imported without one) restarts the packet at the current experience's cell,
        or at the start cell when there is none.

        Raises:
            MapFormatError: missing keys, inconsistent shapes, or dims that differ from
                this module's parameters.
        """
        try:
            tpc = np.asarray(state["template_pc"], dtype=np.float64).reshape(-1, 3)
            epc = np.asarray(state["exp_pc"], dtype=np.float64).reshape(-1, 3)
            etpl = np.asarray(state["exp_template"], dtype=np.int64).reshape(-1)
        except KeyError as exc:
            raise MapFormatError(f"pose-cell state lacks {exc.args[0]!r}") from None
        except ValueError as exc:
            raise MapFormatError(f"pose-cell state has a malformed array: {exc}") from None
        decay = np.asarray(
            state.get("template_decay", np.full(len(tpc), self.params.vt_active_decay)),
            dtype=np.float64,
        ).reshape(-1)
        for key, want in (
            ("pc_dim_xy", self.params.pc_dim_xy),
            ("pc_dim_th", self.params.pc_dim_th),
        ):
            if key in state and int(state[key]) != want:
                raise MapFormatError(
                    f"pose-cell state was saved with {key}={state[key]}, this module has {want}; "
                    "load it with the same config"
                )
        if len(decay) != len(tpc) or len(etpl) != len(epc):
            raise MapFormatError(
                f"pose-cell state is inconsistent: {len(tpc)} template cells vs {len(decay)} "
                f"decays, {len(epc)} experience cells vs {len(etpl)} template ids"
            )
        if len(etpl) and (etpl.min() < -1 or etpl.max() >= max(len(tpc), 1)):
            raise MapFormatError("pose-cell state: an experience refers to an unknown template")
        current_exp = int(state.get("current_exp", len(epc) - 1))
        if not -1 <= current_exp < len(epc):
            raise MapFormatError(f"pose-cell state: current_exp {current_exp} out of range")
        activity = np.asarray(state.get("activity", np.zeros((0, 0, 0))))
        self.reset()
        if activity.size:
            self.network.set_activity(activity)
        self.template_pc, self.template_decay = tpc.copy(), decay.copy()
        self.exp_pc, self.exp_template = epc.copy(), etpl.copy()
        self._template_exps = {}
        for i, t in enumerate(etpl.tolist()):  # restore only, not a hot path
            self._template_exps.setdefault(int(t), []).append(i)
        self.current_exp = current_exp
        self.current_vt = int(state.get("current_vt", -1))
        self.prev_vt = int(state.get("prev_vt", -1))
        self.vt_delta_pc_th = float(state.get("vt_delta_pc_th", 0.0))
        self.relative_rad = float(state.get("relative_rad", 0.0))
        self._odo_update = bool(state.get("odo_update", False))
        self._vt_update = bool(state.get("vt_update", False))
        if "best" in state:
            best = np.asarray(state["best"], dtype=np.float64).reshape(3)
            self._best = (float(best[0]), float(best[1]), float(best[2]))
        elif current_exp >= 0:
            ex, ey, eth = (float(v) for v in epc[current_exp])
            self._best = (ex, ey, eth)
        if not activity.size and current_exp >= 0:
            x, y, th = (int(v) % d for v, d in zip(epc[current_exp], self.dims, strict=True))
            self.network.reset()
            with torch.no_grad():
                self.network.activity.zero_()
                self.network.activity[0, th, y, x] = 1.0
            self.network._occ = None
        self.network._best = torch.tensor([self._best], dtype=torch.float64)


POSE_CELLS.register("ratslam", PoseCells)
