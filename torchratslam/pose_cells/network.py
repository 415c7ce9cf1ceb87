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

Behaviours (``PoseCellParams`` keys; the defaults are OpenRatSLAM's, exactly; the
project's own choices are named values, see ``docs/pose-cells.md`` for what each changes):

* ``pc_decode``: ``"openratslam"`` decodes the centre as ``find_best`` does (phasors at
  ``(i + 1) 2 pi / n``, minus one cell: a centre on a cell comes out just below it, and
  the injection's truncation then picks the cell below); ``"exact"`` uses ``2 pi i / n``.
* ``vt_inject_rule``: ``"openratslam"`` injects for every known template while fewer than
  10 exist (the unsigned ``size - 10`` wraps), then never for the 10 most recent;
  ``"last_10"`` never for the 10 most recent (the algorithm notes' rule).
* ``pc_axis``: ``"openratslam"`` moves theta layer ``k`` along ``(sin, cos)(k 2 pi / TH)``
  in ``(x, y)``; ``"math"`` along ``(cos, sin)``.
* ``pc_wrap``: ``"openratslam"`` drops the activity that crosses the x/y wrap from two
  edge cells of a layer (OpenRatSLAM's wrap-back loops start at 1); ``"preserve_mass"``
  wraps all of it.
* ``pc_multi_cell``: ``False`` moves by OpenRatSLAM's four-neighbour weights (exact up to
  one cell per step, extrapolating beyond); ``True`` moves by an integer roll plus a
  bilinear fraction, any distance.

Two ways to run one step, giving the same actions (and, in float64, centres within
rounding): one network (``B == 1``) on the CPU runs in numpy on the packet's crop
(``method="auto"`` or ``"numpy"``), a batch or a GPU runs the torch methods above.

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
from ratslam_graph.errors import ConfigError, InputError, MapFormatError
from ratslam_graph.geometry import pc_distance
from ratslam_graph.messages import Action, ActionKind
from torchratslam.messages import ViewMatch
from torchratslam.registry import POSE_CELLS

__all__ = [
    "METHODS",
    "PoseCellNetwork",
    "PoseCells",
    "gaussian_kernel_1d",
    "pc_distance",
]

METHODS = ("auto", "numpy", "crop", "separable", "conv3d")
"""Ways to compute the excitation/inhibition (see the module docstring); ``"auto"``
runs one CPU network in numpy (``"numpy"``) and otherwise picks ``"crop"`` when a
typical packet's box is at most ``crop_fraction`` of the network, else ``"separable"``."""

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


def _quadrant_table() -> np.ndarray:
    """How OpenRatSLAM's path integration maps onto the global ``(y, x)`` axes.

    ``path_integration`` rotates layer ``k`` by ``q = floor(dir 2 / pi)`` quarter turns
    (``rot90_square``: ``new[r][c] = old[n - 1 - c][r]``, numpy's ``rot90(., -1)``), moves
    it by ``a = v sin(dir90)`` cells along its columns (``+i``) and ``b = v cos(dir90)``
    along its rows (``+j``) and turns it back. Row ``q`` of the table, found by applying
    those rotations to index grids, holds (all in the global frame, ``(dy, dx)`` or a
    cell as ``(y_is_last, x_is_last)``): the direction of ``+i``, of ``+j``, the cell
    whose ``+i`` move crosses the wrap and is dropped (rotated ``(0, n - 1)``), the cell
    whose ``+j`` move is dropped (rotated ``(n - 1, 0)``), and the corner both would
    have reached (rotated ``(0, 0)``).

    Returns:
        ``(4, 5, 2)`` int64.
    """
    n = 5
    gy, gx = np.mgrid[0:n, 0:n]
    out = np.zeros((4, 5, 2), dtype=np.int64)
    c = n // 2
    for q in range(4):  # four quarter turns, not cells
        ry, rx = np.rot90(gy, -q), np.rot90(gx, -q)
        out[q, 0] = (ry[c, c + 1] - ry[c, c], rx[c, c + 1] - rx[c, c])
        out[q, 1] = (ry[c + 1, c] - ry[c, c], rx[c + 1, c] - rx[c, c])
        for row, (r, cc) in zip((2, 3, 4), ((0, n - 1), (n - 1, 0), (0, 0)), strict=True):
            out[q, row] = (ry[r, cc] == n - 1, rx[r, cc] == n - 1)
    return out


_QUADRANTS = _quadrant_table()


def _arc(mask: Any) -> tuple[int, int]:
    """``(start, length)`` of the shortest circular arc holding every True of ``mask``."""
    s, ln = _minimal_arcs(mask[None])
    return int(s[0]), int(ln[0])


def _arc_with(arc: tuple[int, int], p: int, n: int) -> tuple[int, int]:
    """A short circular arc (on a ring of ``n``) holding ``arc`` and the cell ``p``."""
    s, ln = arc
    if ln == 0:
        return p, 1
    if (p - s) % n < ln:
        return arc
    fwd = (p - s) % n + 1  # extend the end up to p
    back = (s + ln - 1 - p) % n + 1  # extend the start down to p
    return (s, fwd) if fwd <= back else (p, back)


def _roll0(a: np.ndarray, s: int) -> np.ndarray:
    """``np.roll(a, s, axis=0)`` by two slices (less overhead)."""
    n = a.shape[0]
    s %= n
    if s == 0:
        return a
    return np.concatenate((a[n - s :], a[: n - s]), axis=0)


class PoseCellNetwork(nn.Module):
    """``B`` independent RatSLAM pose-cell networks (no learnable parameters).

    Args:
        params: pose-cell parameters.
        batch_size: number of independent networks ``B``.
        dtype: float32 (default) or float64.
        device: torch device.
        method: ``"auto"`` (default), ``"numpy"``, ``"crop"``, ``"separable"`` or
            ``"conv3d"`` (module docstring). ``"numpy"``, and ``"auto"`` unless
            ``params.pc_engine == "torch"``, run a single CPU network in numpy; otherwise
            (a batch, a GPU) the torch method ``"auto"`` picks.
        crop_fraction: ``"crop"`` falls back to the whole network (separable) in a step
            whose box holds more than this fraction of the cells; default 0.5 for
            ``B == 1`` (where per-operation overhead dominates) and 0.8 for batches.

    Attributes:
        activity: buffer ``(B, TH, Y, X)``, non-negative, each network summing to 1.
        best: buffer ``(B, 3)`` float64, the packet centre ``(x, y, th)`` decoded at the
            last step (kept float64 by ``.float()``/``.half()``; in ``state_dict()``).
        dims: ``(X, Y, TH)``.

    ``.to(device, dtype)``, ``.double()`` and ``.float()`` move the activity; cached
    matrices and scratch buffers are dropped and rebuilt for the new dtype and device.

    Example:
        >>> net = PoseCellNetwork(PoseCellParams(pc_dim_xy=11))
        >>> c = net.step(0.5, 0.0, 1.0)  # half a cell along theta layer 18's heading
        >>> tuple(c.shape)
        (1, 3)
    """

    activity: torch.Tensor
    best: torch.Tensor

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
        if method == "numpy" and int(batch_size) != 1:
            raise ConfigError(f"method 'numpy' runs one network, got batch_size={batch_size}")
        if dtype not in (torch.float32, torch.float64):
            raise ConfigError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
        self.params = params
        self.batch_size = int(batch_size)
        self.requested_method = method
        self._numpy = int(batch_size) == 1 and (
            method == "numpy" or (method == "auto" and params.pc_engine != "torch")
        )
        if method == "numpy":
            method = "auto"  # the torch method used off the CPU
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
        self.register_buffer(
            "best", torch.zeros(self.batch_size, 3, dtype=torch.float64, device=device)
        )
        self._ring_key: tuple | None = None
        self._ring_cache: list[tuple[np.ndarray, np.ndarray, int]] = []
        # behaviours (module docstring)
        self._swap_axes = params.pc_axis == "math"
        self._one_cell = not params.pc_multi_cell
        self._edge_loss = params.pc_wrap == "openratslam"
        self._cpp_decode = params.pc_decode == "openratslam"
        # numpy path: matrices, gather indices, and the non-zero arcs (start, length) per
        # axis (th, y, x) valid while the buffer's (pointer, version) is _arcs_key
        self._np_mats: dict[tuple[str, int, bool], np.ndarray] = {}
        self._np_index: dict[tuple, Any] = {}  # index arrays and per-crop (coef, index) tuples
        # (a plain dict: nn.Module's __setattr__ costs microseconds per assignment)
        self._np_state: dict[str, Any] = {"arcs": None, "key": None, "crop": (th, xy, xy)}
        self._lookups: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._geo: dict[tuple, dict[str, np.ndarray]] = {}
        self.reset()

    @property
    def last_crop(self) -> tuple[int, int, int]:
        """The box (theta, y, x cells) the last step computed on."""
        return self._np_state["crop"]

    @last_crop.setter
    def last_crop(self, value: tuple[int, ...]) -> None:
        self._np_state["crop"] = tuple(value)

    @property
    def _arcs(self) -> list[tuple[int, int]] | None:
        return self._np_state["arcs"]

    @_arcs.setter
    def _arcs(self, value: list[tuple[int, int]] | None) -> None:
        self._np_state["arcs"] = value

    @property
    def _best(self) -> torch.Tensor:
        return self.best

    @_best.setter
    def _best(self, value: torch.Tensor) -> None:
        self.best = value.to(dtype=torch.float64, device=self.best.device).reshape(
            self.batch_size, 3
        )

    def _clear_caches(self) -> None:
        """Drop everything derived from the activity's dtype, device or contents."""
        self._mats = {}
        self._work = None
        self._work_views = {}
        self._gather_cache = {}
        self._occ = None
        self._np_mats = {}
        self._arcs = None

    def _apply(self, fn: Any, recurse: bool = True) -> PoseCellNetwork:
        best = self.best
        super()._apply(fn, recurse)
        if self.activity.dtype not in (torch.float32, torch.float64):
            raise ConfigError(
                f"pose-cell activity must be float32 or float64, not {self.activity.dtype}"
            )
        # the centre stays float64 (as OpenRatSLAM's doubles) on the activity's device
        self._buffers["best"] = best.to(device=self.activity.device, dtype=torch.float64)
        self._clear_caches()
        return self

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
        self._arcs = None

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
            if self._numpy and self.activity.device.type == "cpu":
                self.step_one(vtrans, vrot, dt)
                return self._best.clone()
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
            if self._numpy and self.activity.device.type == "cpu":
                self._step_numpy(float(trans[0]), float(rot[0]))
                return self._best.clone()  # (not reached with Python floats: step_one)
            if self.method == "crop":
                peak = self._step_crop(trans, rot)
            else:
                peak = self._step_full(trans, rot)
            self._best = self._decode(peak)
        return self._best.clone()

    def step_one(self, vtrans: float, vrot: float, dt: float) -> tuple[float, float, float]:
        """:meth:`step` for one network (``B == 1``) with Python floats in and out: the
        numpy path without tensor wrapping where it applies (what :class:`PoseCells`
        calls every frame).

        Returns:
            The packet centre ``(x, y, th)`` in cells.
        """
        if not (self._numpy and self.activity.device.type == "cpu" and self.batch_size == 1):
            c = self.step(float(vtrans), float(vrot), float(dt))[0].tolist()
            return (c[0], c[1], c[2])
        if not (math.isfinite(vtrans) and math.isfinite(vrot) and math.isfinite(dt)):
            raise InputError(f"odometry must be finite, got vtrans={vtrans}, vrot={vrot}, dt={dt}")
        trans = vtrans * dt / self.params.pc_cell_x_size  # the same arithmetic as step()
        rot = vrot * dt / (2.0 * math.pi / self.dims[2])
        return self._step_numpy(trans, rot)

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

    def _shift_one(
        self, pool: list[torch.Tensor], step: np.ndarray, w: np.ndarray, axis: int
    ) -> None:
        """``pool[0] + w (pool[0] moved by step - pool[0])`` per layer (``step``, ``w``
        ``(B, T)``; ``step`` is +-1): OpenRatSLAM's one-cell weights, extrapolating when
        ``w > 1``. The result becomes ``pool[0]``."""
        a, g0 = pool[0], pool[1]
        n = a.shape[axis]
        dev = a.device
        key = ("one", axis, tuple(a.shape), step.tobytes(), dev)
        index = self._gather_cache.get(key)
        if index is None:
            shape = [1, 1, 1, 1]
            shape[axis] = n
            lead = step.shape + (1,) * (4 - step.ndim)
            idx = np.remainder(np.arange(n).reshape(shape) - step.reshape(lead), n)
            index = torch.from_numpy(idx).to(dev).expand(a.shape)
            if len(self._gather_cache) > 256:
                self._gather_cache = {}
            self._gather_cache[key] = index
        torch.gather(a, axis, index, out=g0)
        wt = torch.from_numpy(w.reshape((*w.shape, 1, 1))).to(device=dev, dtype=a.dtype)
        torch.lerp(a, g0, wt, out=g0)
        pool[0], pool[1] = g0, a

    def _edge_loss_torch(
        self,
        out: torch.Tensor,
        src: torch.Tensor,
        plan: dict[str, np.ndarray],
        starts: tuple[np.ndarray, np.ndarray] | None,
    ) -> None:
        """The batched form of :meth:`_np_edge_loss` (``starts``: the crop's y and x
        starts per network, None for the whole ring)."""
        b, t, ly, lx = out.shape
        n = self.dims[0]
        ends = np.array([0, n - 1])
        pos = []
        for start, length in zip(
            starts if starts is not None else (np.zeros(b, np.int64), np.zeros(b, np.int64)),
            (ly, lx),
            strict=True,
        ):
            p = np.remainder(ends[None, :] - start[:, None], n)  # (B, 2)
            pos.append(np.where(p < length, p, -1))
        if (pos[0] < 0).all() or (pos[1] < 0).all():
            return
        bb = np.repeat(np.arange(b), t).reshape(b, t)
        kk = np.tile(np.arange(t), b).reshape(b, t)
        take = torch.zeros(b, t, dtype=out.dtype, device=out.device)
        for m in range(2):
            yy = np.take_along_axis(pos[0], plan["src"][:, :, m, 0], axis=1)
            xx = np.take_along_axis(pos[1], plan["src"][:, :, m, 1], axis=1)
            ok = (yy >= 0) & (xx >= 0)
            if ok.any():
                ix = tuple(torch.from_numpy(v[ok]).to(out.device) for v in (bb, kk, yy, xx))
                w = torch.from_numpy(plan["lost"][:, :, m][ok]).to(out.device, out.dtype)
                take[torch.from_numpy(bb[ok]), torch.from_numpy(kk[ok])] += w * src[ix]
        cy = np.take_along_axis(pos[0], plan["corner"][:, :, 0], axis=1)
        cx = np.take_along_axis(pos[1], plan["corner"][:, :, 1], axis=1)
        ok = (cy >= 0) & (cx >= 0)
        if ok.any():
            ix = tuple(torch.from_numpy(v[ok]).to(out.device) for v in (bb, kk, cy, cx))
            out.index_put_(ix, -take[ix[0], ix[1]], accumulate=True)

    def _path_integrate(
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
        ``starts_yx``: the crop's global y and x starts (for the edge loss)."""
        if trans.any():
            n_th = self.dims[2]
            k = (th_start[:, None] + np.arange(pool[0].shape[1])[None, :]) % n_th
            if self._one_cell:
                plan = self._translation_plan(trans, k)
                src = pool[0].clone() if self._edge_loss else pool[0]
                self._shift_one(pool, plan["step_x"], plan["w_x"], 3)
                self._shift_one(pool, plan["step_y"], plan["w_y"], 2)
                if self._edge_loss:
                    self._edge_loss_torch(pool[0], src, plan, starts_yx)
            else:
                direction = k * (2.0 * math.pi / n_th) + np.where(trans < 0, math.pi, 0.0)[:, None]
                mag = np.abs(trans)[:, None]
                cx, cy = mag * np.cos(direction), mag * np.sin(direction)
                if not self._swap_axes:  # OpenRatSLAM: layer k along (sin, cos)
                    cx, cy = cy, cx
                self._shift_axis(pool, cx, 3)
                self._shift_axis(pool, cy, 2)
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
        a = self._path_integrate(pool, trans, rot, starts[0], (starts[1], starts[2]))
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
        self._occ_key = (self.activity.data_ptr(), self.activity._version)
        # the most active cell; ties go to the lowest (th, y, x) index as in a full scan
        top = a.amax(dim=1, keepdim=True)
        return torch.where(a == top, flat, n_t * n_y * n_x).amin(dim=1)

    # ------------------------------------------------------- numpy (B == 1)
    def _np_matrix(self, which: str, n: int, circular: bool) -> np.ndarray:
        key = (which, n, circular)
        m = self._np_mats.get(key)
        if m is None:
            kernel = self._ke if which == "e" else self._ki
            dt = np.float64 if self.dtype == torch.float64 else np.float32
            m = np.ascontiguousarray(_ring_matrix(kernel, n, circular).astype(dt))
            self._np_mats[key] = m
        return m

    def _np_conv(self, a: np.ndarray, which: str, circ: tuple[bool, bool, bool]) -> np.ndarray:
        """Separable 3D convolution of ``a`` (T, Y, X) by three matrix products."""
        t, y, x = a.shape
        mx = self._np_matrix(which, x, circ[2])
        my = self._np_matrix(which, y, circ[1])
        mt = self._np_matrix(which, t, circ[0])
        out = (a.reshape(t * y, x) @ mx.T).reshape(t, y, x)
        out = np.matmul(my, out)
        return (mt @ out.reshape(t, y * x)).reshape(t, y, x)

    def _np_arcs(self, act: np.ndarray) -> list[tuple[int, int]]:
        st = self._np_state
        key = (self.activity.data_ptr(), self.activity._version)
        if st["arcs"] is None or st["key"] != key:
            nz: np.ndarray = np.not_equal(act, 0)
            t2 = np.asarray(nz.any(axis=2))
            st["arcs"] = [_arc(t2.any(axis=1)), _arc(t2.any(axis=0)), _arc(nz.any(axis=(0, 1)))]
            st["key"] = key
        return st["arcs"]

    def _np_shift_index(
        self, shape: tuple[int, int, int], axis: int, shifts: np.ndarray
    ) -> np.ndarray:
        """Flat gather index moving layer ``k`` of a ``shape`` array by ``shifts[k]`` cells
        along ``axis`` (1: y, 2: x), wrapping on the array's own length (cached)."""
        key = (shape, axis, shifts.tobytes())
        idx = self._np_index.get(key)
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
            if len(self._np_index) > 512:
                self._np_index = {}
            self._np_index[key] = idx
        return idx

    def _geometry(self, backwards: bool) -> dict[str, np.ndarray]:
        """Per global theta layer, the parts of the path integration that do not depend on
        the distance (cached per direction of travel): ``coef_y``, ``coef_x`` (the move
        per cell of translation), ``step_y``, ``step_x`` (one-cell: the neighbour's
        shift), ``sin``, ``cos`` (of ``dir90``), ``src`` ``(TH, 2, 2)`` and ``corner``
        ``(TH, 2)`` (the edge loss's cells as (y_is_last, x_is_last))."""
        key = (bool(backwards), self._one_cell, self._swap_axes, self.dims[2])
        g = self._geo.get(key)
        if g is not None:
            return g
        n_t = self.dims[2]
        layers = np.arange(n_t)
        add = math.pi if backwards else 0.0
        g = {}
        if not self._one_cell:
            direction = layers * (2.0 * math.pi / n_t) + add
            cx, cy = np.cos(direction), np.sin(direction)
            if not self._swap_axes:  # OpenRatSLAM: (sin, cos)
                cx, cy = cy, cx
            g["coef_y"], g["coef_x"] = cy, cx
        else:  # OpenRatSLAM's path_integration, its own arithmetic
            direction = layers * ((2.0 * math.pi) / n_t) + add
            q = np.floor(direction * 2 / math.pi)
            d90 = direction - q * math.pi / 2
            sin, cos = np.sin(d90), np.cos(d90)  # a = v sin along +i, b = v cos along +j
            tab = _QUADRANTS[np.remainder(q.astype(np.int64), 4)]  # (TH, 5, 2)
            ax = 1 if self._swap_axes else 0  # "math": the mirror across the diagonal
            di, dj = tab[:, 0, :], tab[:, 1, :]
            i_on_y = di[:, ax] != 0  # +i moves along global y (else x)
            sign_i = di[:, ax] + di[:, 1 - ax]  # the non-zero component
            sign_j = dj[:, ax] + dj[:, 1 - ax]
            g["step_y"] = np.where(i_on_y, sign_i, sign_j)
            g["step_x"] = np.where(i_on_y, sign_j, sign_i)
            g["coef_y"] = np.where(i_on_y, sin, cos)
            g["coef_x"] = np.where(i_on_y, cos, sin)
            g["sin"], g["cos"] = sin, cos
            cells = tab[:, 2:, :]
            if self._swap_axes:
                cells = cells[..., ::-1]
            g["src"] = np.ascontiguousarray(cells[:, :2, :])
            g["corner"] = np.ascontiguousarray(cells[:, 2, :])
        self._geo[key] = g
        return g

    def _translation_plan(self, trans: np.ndarray, layers: np.ndarray) -> dict[str, np.ndarray]:
        """Per theta layer, how path integration moves it in (y, x).

        Args:
            trans: ``(B,)`` translation in cells (signed).
            layers: ``(B, T)`` global theta layer of each layer.

        Returns:
            ``shift_y``, ``shift_x`` (integer base shift), ``step_y``, ``step_x`` (the
            neighbour's shift, base +- 1) and ``w_y``, ``w_x`` (the neighbour's weight),
            all ``(B, T)``: ``out = take(base) + w (take(step) - take(base))``. With the
            edge loss, also ``lost`` ``(B, T, 2)`` weights and ``src`` ``(B, T, 2, 2)``,
            ``corner`` ``(B, T, 2)`` cells as (y_is_last, x_is_last).
        """
        back = trans < 0
        g0, g1 = self._geometry(False), self._geometry(True)
        if not back.any() or back.all():
            g = g1 if back.all() else g0
            geo = {k: v[layers] for k, v in g.items()}
        else:
            geo = {}
            for k, v in g0.items():
                sel = back.reshape((-1,) + (1,) * (v.ndim))
                geo[k] = np.where(sel, g1[k][layers], v[layers])
        v = np.abs(trans)[:, None]
        plan: dict[str, np.ndarray] = {}
        if not self._one_cell:
            for name in ("y", "x"):
                c = v * geo["coef_" + name]
                fl = np.floor(c)
                plan["shift_" + name] = fl.astype(np.int64)
                plan["step_" + name] = fl.astype(np.int64) + 1
                plan["w_" + name] = c - fl
            return plan
        zero = np.zeros(layers.shape, dtype=np.int64)
        plan["shift_y"], plan["shift_x"] = zero, zero
        plan["step_y"], plan["step_x"] = geo["step_y"], geo["step_x"]
        plan["w_y"], plan["w_x"] = v * geo["coef_y"], v * geo["coef_x"]
        if self._edge_loss:
            sin, cos = geo["sin"], geo["cos"]
            se = v * sin * (1.0 - v * cos)
            nw = v * cos * (1.0 - v * sin)
            plan["lost"] = np.stack([se, nw], axis=-1)
            plan["src"], plan["corner"] = geo["src"], geo["corner"]
        return plan

    def _np_translate(
        self,
        a: np.ndarray,
        trans: float,
        layers: np.ndarray,
        box_y: tuple[int, int, bool],
        box_x: tuple[int, int, bool],
    ) -> np.ndarray:
        """Move every layer of the crop ``a`` (T, Y, X) along its heading."""
        g = self._geometry(trans < 0)
        v = abs(trans)
        if self._one_cell:  # per crop: the weights per cell of travel and gather indices
            key = (trans < 0, a.shape, int(layers[0]), a.dtype.char)
            crop_geo = self._np_index.get(key)
            if crop_geo is None:
                # the coefficients stay float64: the weight v * coef is rounded to the
                # activity's dtype once, as on the general path (float32 bit for bit)
                crop_geo = (
                    g["coef_x"][layers][:, None, None],
                    g["coef_y"][layers][:, None, None],
                    self._np_shift_index(a.shape, 2, g["step_x"][layers]),
                    self._np_shift_index(a.shape, 1, g["step_y"][layers]),
                )
                self._np_index[key] = crop_geo
            cx, cy, ix, iy = crop_geo
            src = a
            s1 = a.reshape(-1).take(ix).reshape(a.shape)
            a = a + (v * cx).astype(a.dtype, copy=False) * (s1 - a)
            s1 = a.reshape(-1).take(iy).reshape(a.shape)
            a = a + (v * cy).astype(a.dtype, copy=False) * (s1 - a)
            if self._edge_loss:
                self._np_edge_loss(a, src, trans, layers, box_y, box_x)
            return a
        plan: dict[str, np.ndarray] = {}
        for name in ("y", "x"):
            c = v * g["coef_" + name][layers]
            if self._one_cell:
                plan["shift_" + name] = np.zeros(len(layers), dtype=np.int64)
                plan["step_" + name] = g["step_" + name][layers]
                plan["w_" + name] = c
            else:
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
            s0 = a if not base.any() else flat[self._np_shift_index(shape, axis, base)]
            s1 = flat[self._np_shift_index(shape, axis, step)].reshape(shape)
            s0 = s0.reshape(shape)
            a = s0 + w[:, None, None] * (s1 - s0)
        if self._edge_loss:
            self._np_edge_loss(a, src, trans, layers, box_y, box_x)
        return a

    def _np_edge_loss(
        self,
        out: np.ndarray,
        src: np.ndarray,
        trans: float,
        layers: np.ndarray,
        box_y: tuple[int, int, bool],
        box_x: tuple[int, int, bool],
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
        g = self._geometry(trans < 0)
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

    def _np_rotate(self, a: np.ndarray, rot: float) -> np.ndarray:
        """OpenRatSLAM's theta shift of the crop ``a`` by ``rot`` cells (fraction linear)."""
        r = abs(rot)
        fl = math.floor(r)
        w = r - fl
        if w == 0.0:
            w = 1.0  # its "while (weight > 1) weight -= 1" stops at 1
        sign = -1 if rot < 0 else 1
        s1, s2 = sign * fl, sign * math.ceil(r)
        out = _roll0(a, s1) * (1.0 - w)
        out += _roll0(a, s2) * w
        return out

    def _step_numpy(self, trans: float, rot: float) -> tuple[float, float, float]:
        """One step of a single CPU network in numpy, on the packet's crop."""
        p = self.params
        act = self.activity.detach().numpy()[0]
        n_t, n_y, n_x = act.shape
        arcs = self._np_arcs(act)
        move_xy = math.ceil(abs(trans)) + 1 if trans != 0 else 0
        move_th = math.ceil(abs(rot)) + 1 if rot != 0 else 0
        # every cell the excitation does not reach ends at zero (global inhibition), so
        # the crop needs the excitation's reach and the move only
        eh = max(p.pc_w_e_dim // 2, p.pc_w_e_dim - 1 - p.pc_w_e_dim // 2)
        boxes = []
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
        circ = (boxes[0][2], boxes[1][2], boxes[2][2])
        self._np_state["crop"] = (boxes[0][1], boxes[1][1], boxes[2][1])
        shape = (boxes[0][1], boxes[1][1], boxes[2][1])
        flat = ((idx[0][:, None, None] * n_y + idx[1][None, :, None]) * n_x + idx[2]).reshape(-1)
        act_flat = act.reshape(-1)
        crop = act_flat.take(flat).reshape(shape)
        e = self._np_conv(crop, "e", circ)
        a = e - self._np_conv(e, "i", circ)
        a -= p.pc_global_inhib
        np.maximum(a, 0.0, out=a)
        total = a.sum()
        if not total > 0:
            raise InputError(
                "pose-cell activity died out (every cell <= pc_global_inhib); lower "
                "pc_global_inhib or reset()/inject() the network"
            )
        a /= total
        if trans != 0:
            a = self._np_translate(a, trans, idx[0], boxes[1], boxes[2])
        if rot != 0:
            a = self._np_rotate(a, rot)
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
                arcs.append(_arc(mask))
            else:
                on = np.flatnonzero(mask)
                arcs.append(
                    ((start + int(on[0])) % n, int(on[-1] - on[0]) + 1) if on.size else (0, 0)
                )
        self._np_state["arcs"] = arcs
        # the most active cell; ties go to the lowest global (th, y, x) index
        top = a.max()
        hits = np.flatnonzero(a == top)
        _, ly, lx = a.shape
        kt, ky, kx = hits // (ly * lx), (hits // lx) % ly, hits % lx
        cells = (idx[0][kt] * n_y + idx[1][ky]) * n_x + idx[2][kx]
        peak = int(cells.min())
        return self._decode_np(act, peak)

    def _decode_lookups(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """find_best's sin and cos lookups, ``(i + 1) 2 pi / n``, with its arithmetic."""
        lk = self._lookups.get(n)
        if lk is None:
            ang = (np.arange(n, dtype=np.float64) + 1.0) * 2.0 * math.pi / float(n)
            lk = (np.sin(ang), np.cos(ang))
            self._lookups[n] = lk
        return lk

    def _decode_np(self, act: np.ndarray, peak: int) -> tuple[float, float, float]:
        """The centre of one network (``act`` (T, Y, X)) around the flat ``peak``; also
        written to :attr:`best`."""
        n_x, n_y, n_t = self.dims
        pt, py, px = peak // (n_y * n_x), (peak // n_x) % n_y, peak % n_x
        (wx, ex, _), (wy, ey, _), (wt, et, _) = self._rings()
        ix, iy, it = wx[px], wy[py], wt[pt]
        flat = ((it[:, None, None] * n_y + iy[None, :, None]) * n_x + ix).reshape(-1)
        w = len(ix)
        cube = act.reshape(-1).take(flat).reshape(len(it), len(iy), w).astype(np.float64)
        c2 = cube.sum(axis=0)
        sums = (c2.sum(axis=0), c2.sum(axis=1), cube.sum(axis=(1, 2)))
        rings = (ix, iy, it)
        res: list[float] = []
        if self._cpp_decode:
            for sm, ring, n in zip(sums, rings, (n_x, n_y, n_t), strict=True):
                res.append(self._cpp_position(sm, ring, n))
        else:
            for sm, ring, ph, n in zip(sums, rings, (ex, ey, et), (n_x, n_y, n_t), strict=True):
                v = np.angle((sm * ph[ring]).sum())
                pos = float(np.remainder(v * (n / (2.0 * math.pi)), float(n)))
                res.append(pos - n if pos >= n else pos)
        centre = (res[0], res[1], res[2])
        if self.best.device.type == "cpu":
            self.best.numpy()[0] = centre
        else:
            self.best.copy_(torch.tensor([centre], dtype=torch.float64))
        return centre

    def _cpp_position(self, sums: np.ndarray, ring: np.ndarray, n: int) -> float:
        """find_best on one axis: ``atan2`` of the (i + 1) phasor sums (in cell order),
        times ``n / 2 pi``, minus one cell, then wrapped into ``[0, n]``."""
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
            if self._cpp_decode:  # one network at a time: find_best's own summation order
                out[:, col] = [self._cpp_position(sums[i], ring[i], n) for i in range(b)]
                continue
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
        if self._numpy and self.activity.device.type == "cpu":
            act = self.activity.detach().numpy()[0]
            key = (self.activity.data_ptr(), self.activity._version)
            act[it[0], iy[0], ix[0]] += e[0]
            if e[0] != 0 and self._arcs is not None and self._np_state["key"] == key:
                cell = (int(it[0]), int(iy[0]), int(ix[0]))
                self._arcs = [
                    _arc_with(arc, c, n)
                    for arc, c, n in zip(self._arcs, cell, (n_t, n_y, n_x), strict=True)
                ]
            return
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
        # finite, not necessarily non-negative: OpenRatSLAM's path integration (its
        # one-cell weights, pc_multi_cell false) turns cells negative when the packet moves
        # more than one cell in a step, and a map saved in that behaviour must load
        if not bool(torch.isfinite(a).all()):
            raise MapFormatError("pose-cell activity must be finite (a NaN or inf was found)")
        with torch.no_grad():
            self.activity.copy_(a.to(self.dtype))
        self._occ = None


class PoseCells:
    """The RatSLAM pose-cell module (OpenRatSLAM's ``PosecellNetwork`` behaviour).

    It owns one :class:`PoseCellNetwork`, remembers the pose cell where each visual
    template and each experience was learnt, injects energy for familiar views and,
    after each odometry step, decides the experience-map
    :class:`~ratslam_graph.messages.Action`.

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

        A template among the last 10 learnt injects nothing; while fewer than 10 exist,
        every known template injects (``vt_inject_rule="openratslam"``: its unsigned
        ``size - 10`` wraps) or none does (``"last_10"``, the notes' rule). Re-seeing
        the current template raises its decay by ``vt_active_decay``; the energy
        ``pc_vt_inject_energy / 30 * (30 - exp(1.2 decay))`` goes, if positive, to the
        template's cell with theta corrected by the relative angle.
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
        elif vt < n - RECENT_TEMPLATES or (
            p.vt_inject_rule == "openratslam" and n < RECENT_TEMPLATES
        ):  # OpenRatSLAM's unsigned "size - 10" wraps while fewer than 10 exist
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
            The :class:`~ratslam_graph.messages.Action` for the experience map.
        """
        self._best = self.network.step_one(float(vtrans), float(vrot), float(dt))
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
