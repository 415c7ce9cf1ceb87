"""The numpy engine: one CPU network (``B == 1``) stepped on the packet's crop.

The same box as :mod:`~torchratslam.pose_cells.crop_engine`, without tensor wrapping
(one network is overhead-bound), and OpenRatSLAM's own arithmetic for path integration.
Every cell the excitation does not reach ends at zero (global inhibition), so the crop
needs the excitation's reach and the move only. The step on the crop is one compiled call
(:func:`~torchratslam.pose_cells._step.step_crop`) with numpy's arithmetic, bit for bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from torchratslam.config import PoseCellParams
from torchratslam.errors import InputError
from torchratslam.pose_cells import functional as F
from torchratslam.pose_cells._layout import ALL_ZERO
from torchratslam.pose_cells.decode import CentreDecoder
from torchratslam.pose_cells.motion import MotionTables

__all__ = ["NumpyEngine"]


class NumpyEngine:
    """Steps one network's ``(1, TH, Y, X)`` CPU buffer in place.

    It caches the kernels' taps (in the activity's dtype), the per-layer path-integration
    tables, and the non-zero arcs ``(start, length)`` per axis (th, y, x), valid while the buffer's
    ``(data_ptr, _version)`` is unchanged.

    Args:
        params: pose-cell parameters.
        dtype: the activity's dtype.
    """

    def __init__(self, params: PoseCellParams, dtype: torch.dtype) -> None:
        n_x, n_y, th = params.dims
        self.params = params
        self.dims = (n_x, n_y, th)
        self.dtype = dtype
        self.kernels = {
            "e": F.gaussian_kernel_1d(params.pc_w_e_dim, params.pc_w_e_var),
            "i": F.gaussian_kernel_1d(params.pc_w_i_dim, params.pc_w_i_var),
        }
        self.motion = MotionTables(params)
        self.decoder = CentreDecoder(params)
        # the non-zero arcs (start, length) per axis (th, y, x), then the last box
        self._span = np.zeros(9, dtype=np.int64)
        self._span[6:] = (th, n_y, n_x)
        self._span_key: tuple[int, int] | None = None  # the arcs' (data_ptr, _version)
        self._taps: dict[str, tuple[np.ndarray, np.ndarray, Any]] = {}
        self._geo_tables: dict[bool, tuple[np.ndarray, ...]] = {}  # per direction of travel
        self._both: tuple[np.ndarray, ...] | None = None  # both directions stacked
        self._no_lookups = np.zeros((0, 0), dtype=np.float64)
        self._view: tuple[torch.Tensor, int, np.ndarray] | None = None
        self._eh = max(params.pc_w_e_dim // 2, params.pc_w_e_dim - 1 - params.pc_w_e_dim // 2)

    @property
    def last_crop(self) -> tuple[int, int, int]:
        """The box (theta, y, x cells) the last step computed on."""
        t, y, x = self._span[6:].tolist()
        return (t, y, x)

    # ------------------------------------------------------------ caches
    def retarget(self, dtype: torch.dtype) -> None:
        """Follow the activity to a new dtype: drop every cache."""
        self.dtype = dtype
        self._taps = {}
        self.invalidate()

    def invalidate(self) -> None:
        """Forget what was derived from the activity's contents (it was replaced)."""
        self._span_key = None
        self._view = None

    def _act_view(self, activity: torch.Tensor) -> np.ndarray:
        """The first network of ``activity`` as a numpy view, made again when the buffer
        (the tensor or its memory) is another one.

        Shape:
            activity: ``(1, TH, Y, X)``; returns ``(TH, Y, X)``.
        """
        view = self._view
        if view is None or view[0] is not activity or view[1] != activity.data_ptr():
            view = self._view = (activity, activity.data_ptr(), activity.detach().numpy()[0])
        return view[2]

    def span_of(self, activity: torch.Tensor, act: np.ndarray) -> np.ndarray:
        """The non-zero arcs ``(start, length)`` per axis (th, y, x) of ``act`` (the numpy
        view of ``activity``), then the last box: the engine's own array, made again
        when the buffer's ``(data_ptr, _version)`` changed.

        Shape:
            returns ``(9,)`` int64.
        """
        key = (activity.data_ptr(), activity._version)
        if self._span_key != key:
            nz: np.ndarray = np.not_equal(act, 0)
            t2 = np.asarray(nz.any(axis=2))
            arcs = (F.arc(t2.any(axis=1)), F.arc(t2.any(axis=0)), F.arc(nz.any(axis=(0, 1))))
            self._span[:6] = [v for arc in arcs for v in arc]
            self._span_key = key
        return self._span

    # ------------------------------------------------------------ tables
    def _tables(self, backwards: bool) -> tuple[np.ndarray, ...]:
        """Per direction of travel, the kernel's per-layer tables: ``coef`` and ``steps``
        ``(2, TH)`` (y, x), ``edge`` ``(2, TH)`` (sin, cos; ``(0, 0)`` without the edge
        loss), ``cells`` ``(TH, 3, 2)`` (its two source cells and their corner)."""
        tab = self._geo_tables.get(backwards)
        if tab is None:
            mo = self.motion
            g = mo.geometry(backwards)
            n_t = self.dims[2]
            coef = np.ascontiguousarray(np.stack([g["coef_y"], g["coef_x"]]), dtype=np.float64)
            if mo.one_cell:
                steps = np.stack([g["step_y"], g["step_x"]]).astype(np.int64)
            else:
                steps = np.zeros((2, n_t), dtype=np.int64)
            edge = np.zeros((0, 0), dtype=np.float64)
            cells = np.zeros((n_t, 3, 2), dtype=np.int64)
            if mo.edge_loss and mo.one_cell:
                edge = np.ascontiguousarray(np.stack([g["sin"], g["cos"]]), dtype=np.float64)
                cells[:, :2] = g["src"]
                cells[:, 2] = g["corner"]
            tab = self._geo_tables[backwards] = (coef, steps, edge, cells)
        return tab

    def _tables_both(self) -> tuple[np.ndarray, ...]:
        """:meth:`_tables` for both directions of travel stacked (forwards first)."""
        if self._both is None:
            fwd, back = self._tables(False), self._tables(True)
            self._both = tuple(
                np.ascontiguousarray(np.stack([f, b])) for f, b in zip(fwd, back, strict=True)
            )
        return self._both

    def kernel_args(self, dtype: np.dtype) -> tuple[Any, ...]:
        """What :func:`~torchratslam.pose_cells._frame.step_span` takes after ``act``,
        ``span``, ``trans`` and ``rot`` (the activity's dtype ``dtype``): the
        excitation's reach, the taps, the global inhibition, the path integration's
        tables, find_best's tables and ``pc_cells_to_avg``."""
        w_e, w_i, inhib = self._weights(dtype)
        coef, steps, edge, cells = self._tables_both()
        dec = self.decoder
        lookups = dec.find_best_tables() if dec.cpp_decode else self._no_lookups
        one_cell = self.motion.one_cell
        return (
            self._eh,
            w_e,
            w_i,
            inhib,
            coef,
            steps,
            one_cell,
            edge,
            cells,
            lookups,
            dec.cells_to_avg,
        )

    def _weights(self, dtype: np.dtype) -> tuple[np.ndarray, np.ndarray, Any]:
        """The excitatory and inhibitory taps and ``pc_global_inhib`` in ``dtype``."""
        w = self._taps.get(dtype.char)
        if w is None:
            w = self._taps[dtype.char] = (
                self.kernels["e"].astype(dtype),
                self.kernels["i"].astype(dtype),
                dtype.type(self.params.pc_global_inhib),
            )
        return w

    # --------------------------------------------------------------- step
    def step(self, activity: torch.Tensor, trans: float, rot: float) -> tuple[float, float, float]:
        """One step of the network in place, on the packet's crop (one compiled call,
        :func:`~torchratslam.pose_cells._step.step_crop`).

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
        from torchratslam.pose_cells._frame import step_span

        act = self._act_view(activity)
        span = self.span_of(activity, act)
        status, peak, centre = step_span(
            act, span, float(trans), float(rot), *self.kernel_args(act.dtype)
        )
        if status == ALL_ZERO:
            raise InputError("pose-cell activity is all zero; reset() or inject() before stepping")
        if status:
            raise InputError(F.DIED_OUT)
        if self.decoder.cpp_decode:
            return centre
        return self.decoder.decode_one(act, peak)

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
        from torchratslam.pose_cells._frame import inject_cell

        act = self._act_view(activity)
        keep = self._span_key == (activity.data_ptr(), activity._version)
        inject_cell(act, self._span, int(th), int(y), int(x), float(energy), keep)
