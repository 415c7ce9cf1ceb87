"""The RatSLAM pose-cell network: a 3D continuous attractor network in PyTorch.

:class:`PoseCellNetwork` holds ``B`` independent networks in one ``(B, TH, Y, X)``
buffer (``x`` is the last axis, ``y`` the middle one). One
:meth:`~PoseCellNetwork.step` is OpenRatSLAM's ``on_odo``: excite, inhibit, global
inhibition and clamp, normalise, path integration, packet centre. The math is in
:mod:`~torchratslam.pose_cells.functional`; the network keeps the state in buffers and
hands each step to an engine. The RatSLAM stage around one network (templates,
experiences, actions) is :class:`~torchratslam.pose_cells.stage.PoseCells`.

How the dynamics are computed (all give the same numbers up to rounding; ``make bench``
compares them):

* ``"conv3d"``: one circular 3D convolution per kernel (the textbook form).
* ``"separable"``: the Gaussian kernel with one variance on all axes is a product of
  three 1D kernels, so each 3D convolution is three 1D circular convolutions; each is a
  matrix product with a small circulant matrix (faster on CPU than ``conv1d``).
  Both run in :class:`~torchratslam.pose_cells.torch_engine.TorchEngine`.
* ``"crop"``: only a box around the packet plus a halo can change, so the step runs on
  that box (:class:`~torchratslam.pose_cells.crop_engine.CropEngine`).
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
(``method="auto"`` or ``"numpy"``,
:class:`~torchratslam.pose_cells.numpy_engine.NumpyEngine`), a batch or a GPU runs the
torch methods above.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import nn

from torchratslam.config import PoseCellParams
from torchratslam.errors import ConfigError, InputError, MapFormatError
from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells.crop_engine import CropEngine
from torchratslam.pose_cells.numpy_engine import NumpyEngine
from torchratslam.pose_cells.torch_engine import TorchEngine
from torchratslam.shapes import check_shape

__all__ = ["METHODS", "TYPICAL_PACKET", "PoseCellNetwork"]

METHODS = ("auto", "numpy", "crop", "separable", "conv3d")
"""Ways to compute the excitation/inhibition (see the module docstring); ``"auto"``
runs one CPU network in numpy (``"numpy"``) and otherwise picks ``"crop"`` when a
typical packet's box is at most ``crop_fraction`` of the network, else ``"separable"``."""

TYPICAL_PACKET = (9, 7, 7)
"""Non-zero extent (theta, y, x cells) of a settled packet with the default kernels,
used by ``method="auto"`` to guess whether cropping pays."""


def _torch_method(params: PoseCellParams, method: str, crop_fraction: float) -> str:
    """The torch method ``method`` stands for (``"auto"``: crop when a typical packet's
    box is at most ``crop_fraction`` of the network)."""
    if method != "auto":
        return method
    n_x, n_y, th = params.dims
    # cells the dynamics can reach: excitation, then inhibition of the excited activity
    reach = params.pc_w_e_dim // 2 + params.pc_w_i_dim // 2
    box = [min(e + 2 * (reach + 2), n) for e, n in zip(TYPICAL_PACKET, (th, n_y, n_x), strict=True)]
    small = box[0] * box[1] * box[2] <= crop_fraction * th * n_y * n_x
    return "crop" if small else "separable"


class PoseCellNetwork(nn.Module):
    """``B`` independent RatSLAM pose-cell networks (no learnable parameters).

    Args:
        params: pose-cell parameters.
        batch_size: number of independent networks ``B``.
        dtype: float64 (default: OpenRatSLAM's ``double``) or float32.
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
        method: the torch method (``"crop"``, ``"separable"`` or ``"conv3d"``) run for a
            batch or off the CPU.

    ``.to(device, dtype)``, ``.double()`` and ``.float()`` move the activity; the
    engines drop their cached matrices and scratch buffers and rebuild them for the new
    dtype and device.

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
        dtype: torch.dtype = torch.float64,
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
        if crop_fraction is None:  # one network is overhead-bound, a batch compute-bound
            crop_fraction = 0.5 if int(batch_size) == 1 else 0.8
        self.crop_fraction = float(crop_fraction)
        # "numpy" off the CPU: the torch method "auto" picks
        self.method = _torch_method(
            params, "auto" if method == "numpy" else method, self.crop_fraction
        )
        n_x, n_y, th = params.dims
        self.dims = (n_x, n_y, th)
        self.register_buffer(
            "activity", torch.zeros(self.batch_size, th, n_y, n_x, dtype=dtype, device=device)
        )
        self.register_buffer(
            "best", torch.zeros(self.batch_size, 3, dtype=torch.float64, device=device)
        )
        dev = self.activity.device
        self._torch: TorchEngine = (
            CropEngine(params, dtype, dev, self.crop_fraction)
            if self.method == "crop"
            else TorchEngine(params, self.method, dtype, dev)
        )
        self._np_engine = NumpyEngine(params, dtype)
        self.reset()

    @property
    def uses_numpy(self) -> bool:
        """Whether a step runs in numpy (one network on the CPU, method ``"numpy"`` or
        ``"auto"``) rather than the torch :attr:`method`."""
        return self._numpy and self.activity.device.type == "cpu"

    @property
    def last_crop(self) -> tuple[int, int, int]:
        """The box (theta, y, x cells) the last step computed on."""
        return (self._np_engine if self.uses_numpy else self._torch).last_crop

    def _set_best(self, value: torch.Tensor) -> None:
        self.best = value.to(dtype=torch.float64, device=self.best.device).reshape(
            self.batch_size, 3
        )

    def _store_centre(self, centre: tuple[float, float, float]) -> None:
        """Write one network's centre into :attr:`best` (on the CPU through a numpy view
        of the buffer, made again when the buffer is replaced)."""
        best = self._buffers["best"]
        assert best is not None
        view = self.__dict__.get("_best_view")
        if view is None or view[0] is not best:
            view = (best, best.numpy() if best.device.type == "cpu" else None)
            self.__dict__["_best_view"] = view
        if view[1] is not None:
            view[1][0] = centre
        else:
            best.copy_(torch.tensor([centre], dtype=torch.float64))

    def _invalidate(self) -> None:
        """The activity was replaced: the engines forget what they derived from it."""
        self._torch.invalidate()
        self._np_engine.invalidate()

    def _apply(self, fn: Any, recurse: bool = True) -> PoseCellNetwork:
        best = self.best
        super()._apply(fn, recurse)
        if self.activity.dtype not in (torch.float32, torch.float64):
            raise ConfigError(
                f"pose-cell activity must be float32 or float64, not {self.activity.dtype}"
            )
        # the centre stays float64 (as OpenRatSLAM's doubles) on the activity's device
        self._buffers["best"] = best.to(device=self.activity.device, dtype=torch.float64)
        self._torch.retarget(self.activity.dtype, self.activity.device)
        self._np_engine.retarget(self.activity.dtype)
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
        self.place_packet(x, y, th)

    def place_packet(self, x: int, y: int, th: int) -> None:
        """Activity 1 at cell ``(x, y, th)`` (indices wrap) and 0 elsewhere, in every
        network; the centre (:attr:`best`) becomes that cell."""
        x, y, th = (int(v) % d for v, d in zip((x, y, th), self.dims, strict=True))
        with torch.no_grad():
            self.activity.zero_()
            self.activity[:, th, y, x] = 1.0
        self._set_best(torch.tensor([[x, y, th]], dtype=torch.float64).repeat(self.batch_size, 1))
        self._invalidate()

    def set_centre(self, centre: Any) -> None:
        """Replace the decoded centre :attr:`best` (e.g. a restored module's).

        Shape:
            centre: ``(3,)`` (every network) or ``(B, 3)``, ``(x, y, th)`` cells.
        """
        c = torch.as_tensor(np.asarray(centre, dtype=np.float64))
        if c.ndim == 1:
            check_shape(c, (3,), name="centre")
            c = c[None].repeat(self.batch_size, 1)
        check_shape(c, (self.batch_size, 3), name="centre")
        self._set_best(c)

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
                self._set_best(self._torch.decode(self.activity, peak))
        return self.best.clone()

    # --------------------------------------------------------------- dynamics
    def excite(self, activity: torch.Tensor) -> torch.Tensor:
        """Circular convolution with the normalised excitatory kernel (no state change).

        Shape:
            activity: ``(B, TH, Y, X)``; returns the same shape.
        """
        check_shape(activity, "B TH Y X", name="activity")
        return self._torch.excite(activity)

    def inhibit(self, excited: torch.Tensor) -> torch.Tensor:
        """``excited`` minus its circular convolution with the inhibitory kernel.

        Shape:
            excited: ``(B, TH, Y, X)``; returns the same shape.
        """
        check_shape(excited, "B TH Y X", name="excited")
        return self._torch.inhibit(excited)

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
        b = check_shape(activity, "B TH Y X", name="activity")["B"]
        t = F.as_batch(trans, b, "trans")
        r = F.as_batch(rot, b, "rot")
        with torch.no_grad():
            pool = [activity.clone(), torch.empty_like(activity), torch.empty_like(activity)]
            return self._torch.path_integrate(pool, t, r, np.zeros(b, dtype=np.int64)).clone()

    # ------------------------------------------------------------------- step
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
                return self.best.clone()
            vt, vr, d = np.array([vtrans]), np.array([vrot]), np.array([dt])  # fast path
            finite = math.isfinite(vtrans) and math.isfinite(vrot) and math.isfinite(dt)
        else:
            vt = F.as_batch(vtrans, b, "vtrans")
            vr = F.as_batch(vrot, b, "vrot")
            d = F.as_batch(dt, b, "dt")
            finite = np.isfinite(vt).all() and np.isfinite(vr).all() and np.isfinite(d).all()
        if not finite:
            raise InputError(f"odometry must be finite, got vtrans={vtrans}, vrot={vrot}, dt={dt}")
        trans = vt * d / self.params.pc_cell_x_size  # cells along each layer's heading
        rot = vr * d / (2.0 * math.pi / self.dims[2])  # theta cells
        with torch.no_grad():
            if self._numpy and self.activity.device.type == "cpu":
                centre = self._np_engine.step(self.activity, float(trans[0]), float(rot[0]))
                self._store_centre(centre)
                return self.best.clone()  # (not reached with Python floats: step_one)
            peak = self._torch.step(self.activity, trans, rot)
            self._set_best(self._torch.decode(self.activity, peak))
        return self.best.clone()

    def step_one(self, vtrans: float, vrot: float, dt: float) -> tuple[float, float, float]:
        """:meth:`step` for one network (``B == 1``) with Python floats in and out: the
        numpy path without tensor wrapping where it applies (what
        :class:`~torchratslam.pose_cells.stage.PoseCells` calls every frame).

        Returns:
            The packet centre ``(x, y, th)`` in cells.
        """
        activity = self._buffers["activity"]
        assert activity is not None
        if not (self._numpy and activity.device.type == "cpu" and self.batch_size == 1):
            c = self.step(float(vtrans), float(vrot), float(dt))[0].tolist()
            return (c[0], c[1], c[2])
        if not (math.isfinite(vtrans) and math.isfinite(vrot) and math.isfinite(dt)):
            raise InputError(f"odometry must be finite, got vtrans={vtrans}, vrot={vrot}, dt={dt}")
        trans = vtrans * dt / self.params.pc_cell_x_size  # the same arithmetic as step()
        rot = vrot * dt / (2.0 * math.pi / self.dims[2])
        centre = self._np_engine.step(activity, trans, rot)
        self._store_centre(centre)
        return centre

    # ----------------------------------------------------------------- inject
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
        act = self._buffers["activity"]
        assert act is not None
        if (
            self._numpy
            and type(x) is int
            and type(y) is int
            and type(th) is int
            and type(energy) is float
            and act.device.type == "cpu"
        ):  # one network, Python numbers (what PoseCells passes every frame): no arrays
            if not math.isfinite(energy):
                raise InputError(f"injected energy must be finite, got {energy}")
            # a float64 scalar, as the arrays' path passes: the sum rounds as float64
            self._np_engine.inject(act, th % n_t, y % n_y, x % n_x, np.float64(energy))
            return
        ix = np.remainder(F.as_batch(x, b, "x", np.int64), n_x)
        iy = np.remainder(F.as_batch(y, b, "y", np.int64), n_y)
        it = np.remainder(F.as_batch(th, b, "th", np.int64), n_t)
        e = F.as_batch(energy, b, "energy")
        if not np.isfinite(e).all():
            raise InputError(f"injected energy must be finite, got {energy}")
        if self._numpy and self.activity.device.type == "cpu":
            self._np_engine.inject(self.activity, it[0], iy[0], ix[0], e[0])
            return
        self._torch.inject(self.activity, it, iy, ix, e)

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
                f"{tuple(self.activity.shape)} (check pc_dim_xy / pc_dim_x / pc_dim_y / pc_dim_th)"
            )
        # finite, not necessarily non-negative: OpenRatSLAM's path integration (its
        # one-cell weights, pc_multi_cell false) turns cells negative when the packet moves
        # more than one cell in a step, and a map saved in that behaviour must load
        if not bool(torch.isfinite(a).all()):
            raise MapFormatError("pose-cell activity must be finite (a NaN or inf was found)")
        with torch.no_grad():
            self.activity.copy_(a.to(self.dtype))
        self._invalidate()
