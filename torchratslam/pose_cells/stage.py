"""The RatSLAM pose-cell stage: one network plus OpenRatSLAM's template and experience
bookkeeping.

:class:`PoseCells` is OpenRatSLAM's ``PosecellNetwork`` behaviour: one
:class:`~torchratslam.pose_cells.network.PoseCellNetwork`, the cell where each template
and each experience was learnt, template decay, energy injection, and the action rule
that tells the experience map what to do; :mod:`torchratslam.pipeline.defaults` registers
it as ``"ratslam"`` in :data:`torchratslam.registry.POSE_CELLS`.

Kept from OpenRatSLAM: an action is only decided when a view template and odometry have
both arrived since the last decision.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from ratslam_graph.geometry import pc_distance
from ratslam_graph.messages import Action, ActionKind
from torchratslam.config import PoseCellParams
from torchratslam.errors import InputError, MapFormatError
from torchratslam.messages import ViewMatch
from torchratslam.pose_cells import _layout as L
from torchratslam.pose_cells.functional import DIED_OUT
from torchratslam.pose_cells.network import PoseCellNetwork

__all__ = ["RECENT_TEMPLATES", "PoseCells"]

RECENT_TEMPLATES = L.RECENT
"""Templates among the last this many learnt do not inject energy."""

_KINDS = (ActionKind.NONE, ActionKind.CREATE, ActionKind.LINK)
_NO_ACTION = Action()


_FRAME: Any = None


def _kernels() -> Any:
    """:mod:`torchratslam.pose_cells._frame` (numba, imported on first use and kept)."""
    global _FRAME
    from torchratslam.pose_cells import _frame

    _FRAME = _frame
    return _FRAME


class PoseCells:
    """The RatSLAM pose-cell module (OpenRatSLAM's ``PosecellNetwork`` behaviour).

    It owns one :class:`PoseCellNetwork`, remembers the pose cell where each visual
    template and each experience was learnt, injects energy for familiar views and,
    after each odometry step, decides the experience-map
    :class:`~ratslam_graph.messages.Action`.

    Call :meth:`on_view_template` and :meth:`on_odometry` once per frame, or
    :meth:`on_frame` for both (one compiled call on a CPU network, what the pipeline
    does); as in OpenRatSLAM an action is only decided once both have been received
    since the last decision (otherwise :meth:`on_odometry` returns ``NONE``). The
    scalars (current experience and templates, the flags, the centre) live in two small
    arrays the compiled kernels read and write (:mod:`~torchratslam.pose_cells._layout`).

    Args:
        params: pose-cell parameters.
        dtype: activity dtype (float64 default, as OpenRatSLAM's ``double``; float32 supported).
        device: torch device.
        method: dynamics method of the network (see :class:`PoseCellNetwork`).
    """

    current_exp = L.Slot("_ist", L.CUR_EXP, int)
    current_vt = L.Slot("_ist", L.CUR_VT, int)
    prev_vt = L.Slot("_ist", L.PREV_VT, int)
    vt_delta_pc_th = L.Slot("_fst", L.VT_DELTA, float)
    relative_rad = L.Slot("_fst", L.REL_RAD, float)
    _n_t = L.Slot("_ist", L.N_T, int)
    _n_e = L.Slot("_ist", L.N_E, int)
    _odo_update = L.Slot("_ist", L.ODO_UPD, bool)
    _vt_update = L.Slot("_ist", L.VT_UPD, bool)

    def __init__(
        self,
        params: PoseCellParams | None = None,
        *,
        dtype: torch.dtype = torch.float64,
        device: Any = None,
        method: str = "auto",
    ) -> None:
        self.params = p = params if params is not None else PoseCellParams()
        self.network = PoseCellNetwork(self.params, 1, dtype=dtype, device=device, method=method)
        self.dims = self.network.dims
        self._ist = np.zeros(L.I_SIZE, dtype=np.int64)
        self._fst = np.zeros(L.F_SIZE, dtype=np.float64)
        self._ist[L.I_RULE] = p.vt_inject_rule == "openratslam"
        self._fst[L.F_ENERGY : L.F_DIMS] = (
            p.pc_vt_inject_energy,
            p.vt_active_decay,
            p.pc_vt_restore,
            p.exp_delta_pc_threshold,
            p.pc_cell_x_size,
        )
        self._fst[L.F_DIMS : L.F_DIMS + 3] = self.dims
        self._frame_args: tuple | None = None  # see on_frame
        self._clear()

    def _clear(self) -> None:
        # rows [:n] of buffers with spare room (no copy of every row per new one)
        self._store(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
        self.current_exp = -1
        self.current_vt = -1
        self.prev_vt = -1
        self.vt_delta_pc_th = 0.0
        self.relative_rad = 0.0
        self._odo_update = False
        self._vt_update = False
        self._best = (float(self.dims[0] // 2), float(self.dims[1] // 2), float(self.dims[2] // 2))

    def __getstate__(self) -> dict[str, Any]:
        # a copy or a pickle makes new buffers: the compiled frame's views are made again
        return {**self.__dict__, "_frame_args": None}

    def reset(self) -> None:
        """Back to the start: one active cell in the middle, no templates or experiences."""
        self.network.reset()
        self._clear()

    def _store(
        self, t_pc: np.ndarray, t_decay: np.ndarray, e_pc: np.ndarray, e_template: np.ndarray
    ) -> None:
        """Templates' cells and decays, experiences' cells and templates (copied), and
        the chains of each template's experiences."""
        self._n_t, self._n_e = len(t_pc), len(e_pc)
        self._t_pc, self._t_decay = t_pc.astype(np.float64), t_decay.astype(np.float64)
        self._e_pc, self._e_template = e_pc.astype(np.float64), e_template.astype(np.int64)
        self._t_chain = np.full((len(t_pc), 2), -1, dtype=np.int64)
        self._e_next = np.full(len(e_pc), -1, dtype=np.int64)
        self._frame_args = None
        self._make_room(max(len(t_pc), int(e_template.max(initial=-1)) + 1))
        L.link_chains(e_template, self._t_chain, self._e_next)

    def _make_room(self, n_t: int | None = None) -> None:
        """Free rows for one more template (and templates ``< n_t``) and one more
        experience."""
        n_t = self._n_t if n_t is None else max(n_t, self._n_t)
        if n_t >= len(self._t_pc):
            self._t_pc = L.grown(self._t_pc, n_t, 0.0)
            self._t_decay = L.grown(self._t_decay, n_t, 0.0)
            self._t_chain = L.grown(self._t_chain, n_t, -1)
            self._frame_args = None
        n_e = self._n_e
        if n_e >= len(self._e_pc):
            self._e_pc = L.grown(self._e_pc, n_e, 0.0)
            self._e_template = L.grown(self._e_template, n_e, 0)
            self._e_next = L.grown(self._e_next, n_e, -1)
            self._frame_args = None

    # ------------------------------------------------------------ accessors
    @property
    def template_pc(self) -> np.ndarray:
        """The cell ``(x, y, th)`` where each template was learnt.

        Shape:
            (N, 3).
        """
        return self._t_pc[: self._n_t]

    @property
    def template_decay(self) -> np.ndarray:
        """Each template's decay. Shape: (N,)."""
        return self._t_decay[: self._n_t]

    @property
    def exp_pc(self) -> np.ndarray:
        """The cell ``(x, y, th)`` where each experience was learnt.

        Shape:
            (M, 3).
        """
        return self._e_pc[: self._n_e]

    @property
    def exp_template(self) -> np.ndarray:
        """The template of each experience. Shape: (M,)."""
        return self._e_template[: self._n_e]

    @property
    def _best(self) -> tuple[float, float, float]:
        x, y, th = self._fst[L.BEST : L.BEST + 3].tolist()
        return (x, y, th)

    @_best.setter
    def _best(self, value: tuple[float, float, float]) -> None:
        self._fst[L.BEST : L.BEST + 3] = value

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
        return self._n_t

    @property
    def n_experiences(self) -> int:
        return self._n_e

    def template_experiences(self, template_id: int) -> list[int]:
        """Experience ids learnt with ``template_id``, in creation order."""
        found: list[int] = np.flatnonzero(self.exp_template == int(template_id)).tolist()
        return found

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
        vt = int(match.template_id)
        self._make_room()
        status, th, y, x, energy = _kernels().view_update(
            self._ist, self._fst, self._t_pc, self._t_decay, vt, float(match.relative_rad)
        )
        if status:
            _raise_for(status, self, vt, energy)
        if energy != 0:
            self.network.inject(x, y, th, energy)

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
        self._make_room()
        kind, dest, src = _kernels().decide(
            self._ist, self._fst, self._e_pc, self._e_template, self._e_next, self._t_chain
        )
        if kind == 0:
            return Action.none()
        return Action(_KINDS[kind], dest_id=dest, src_id=src, relative_rad=self.relative_rad)

    def on_frame(
        self,
        match: ViewMatch,
        vtrans: float,
        vrot: float,
        dt: float,
        *,
        injection_angle: bool = False,
    ) -> tuple[Action, tuple[float, float, float]]:
        """:meth:`on_view_template`, then :meth:`on_odometry`, and the centre: for one
        network on the CPU, one compiled call
        (:func:`~torchratslam.pose_cells._frame.frame_step`), the same bits.

        Args:
            match: the frame's view template.
            vtrans, vrot, dt: the frame's odometry (Python floats).
            injection_angle: the action carries the last injection's angle
                (``vt_delta_pc_th`` in radians, OpenRatSLAM's ``get_relative_rad``)
                rather than this view's.

        Returns:
            The action and the packet centre ``(x, y, th)`` after the step.
        """
        bufs = self.network._buffers
        act = bufs["activity"]
        args = self._frame_args
        if (
            args is None
            or args[0] is not act
            or args[1] is not bufs["best"]
            or args[2] != (act.data_ptr(), act._version)
        ):
            args = self._prepare_frame()
            if args is None:  # the torch engine: the two calls
                self.on_view_template(match)
                action = self.on_odometry(vtrans, vrot, dt)
                if injection_angle and action.kind != ActionKind.NONE:
                    rad = self.vt_delta_pc_th * 2.0 * math.pi / self.dims[2]
                    action = Action(action.kind, action.dest_id, action.src_id, rad)
                return action, self._best
        status, kind, dest, src, x, y, th, angle = (_FRAME or _kernels()).frame_step(
            *args[3], match.template_id, match.relative_rad, vtrans, vrot, dt
        )
        if status:
            self._make_room()
            if status != L.GROW:
                _raise_for(status, self, int(match.template_id), 0.0, (vtrans, vrot, dt))
        if kind == 0:
            return _NO_ACTION, (x, y, th)
        rad = angle if injection_angle else self.relative_rad
        return Action(_KINDS[kind], dest, src, rad), (x, y, th)

    def _prepare_frame(self) -> tuple | None:
        """What :meth:`on_frame` passes to the compiled frame (None: the network is not
        one CPU network in numpy decoding as OpenRatSLAM)."""
        net = self.network
        eng = net._np_engine
        act_t, best_t = net._buffers["activity"], net._buffers["best"]
        assert act_t is not None and best_t is not None
        if not (net.uses_numpy and eng.decoder.cpp_decode and best_t.device.type == "cpu"):
            return None
        self._make_room()
        act = eng._act_view(act_t)
        span = eng.span_of(act_t, act)
        arrays = (self._t_pc, self._t_decay, self._e_pc, self._e_template, self._e_next)
        args = (act, span, best_t.numpy(), self._ist, self._fst, *arrays, self._t_chain)
        key = (act_t.data_ptr(), act_t._version)
        self._frame_args = (act_t, best_t, key, (*args, *eng.kernel_args(act.dtype)))
        return self._frame_args

    # --------------------------------------------------------------- action
    def _corrected_centre(self) -> tuple[float, float, float]:
        """The centre with theta corrected by ``-vt_delta_pc_th`` (OpenRatSLAM's
        ``get_delta_pc``)."""
        n_th = self.dims[2]
        x, y, th = self._best
        th = th - self.vt_delta_pc_th
        if th < 0:
            th += n_th
        if th >= n_th:
            th -= n_th
        return x, y, th

    def _delta_pc(self, cells: np.ndarray) -> np.ndarray:
        """Distance of experience cells ``(..., 3)`` from the corrected centre."""
        return pc_distance(cells, np.array(self._corrected_centre()), self.dims)

    # ---------------------------------------------------------------- state
    def get_state(self) -> dict[str, Any]:
        """Everything needed to continue bit-identically (numpy arrays / Python scalars).

        Keys: ``activity`` (TH, Y, X), ``template_pc`` (N, 3), ``template_decay`` (N,),
        ``exp_pc`` (M, 3), ``exp_template`` (M,), ``best`` (3,), ``current_exp``,
        ``current_vt``, ``prev_vt``, ``vt_delta_pc_th``, ``relative_rad``,
        ``odo_update``, ``vt_update``, ``pc_dim_xy``, ``pc_dim_th``; a network with X != Y
        also ``pc_dim_x`` and ``pc_dim_y`` (a square one's dictionary is as before).
        """
        state = {
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
        n_x, n_y, _ = self.dims
        if n_x != n_y:
            state["pc_dim_x"], state["pc_dim_y"] = int(n_x), int(n_y)
        return state

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
        n_x, n_y, n_th = self.dims
        saved_xy = state.get("pc_dim_xy")
        for key, want in (("pc_dim_x", n_x), ("pc_dim_y", n_y), ("pc_dim_th", n_th)):
            # a save without pc_dim_x / pc_dim_y (square, or older) sizes both by pc_dim_xy
            got = state.get(key, saved_xy if key != "pc_dim_th" else None)
            if got is not None and int(got) != want:
                name = key if key in state else "pc_dim_xy"
                raise MapFormatError(
                    f"pose-cell state was saved with {name}={got}, this module has "
                    f"{key}={want}; load it with the same config"
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
        self._store(tpc, decay, epc, etpl)
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
            self.network.place_packet(x, y, th)
        self.network.set_centre(self._best)


def _raise_for(
    status: int, pcs: PoseCells, vt: int, energy: float, odometry: tuple[float, ...] = ()
) -> None:
    """Raise what the separate calls raise for a compiled frame's error ``status``."""
    if status == L.BAD_ID:
        n = pcs.n_templates
        raise InputError(
            f"view template id {vt} is invalid: {n} templates are known, so the id "
            f"must be in 0..{n} ({n} = a new template)"
        )
    if status == L.BAD_CELL:  # int() of the template's cell raises, as it did
        cell = pcs.template_pc[vt].tolist()
        int(cell[0]), int(cell[1]), int(cell[2] + pcs.vt_delta_pc_th)
    if status == L.BAD_ENERGY:
        raise InputError(f"injected energy must be finite, got {energy}")
    if status == L.BAD_ODOMETRY:
        vtrans, vrot, dt = odometry
        raise InputError(f"odometry must be finite, got vtrans={vtrans}, vrot={vrot}, dt={dt}")
    if status == L.ALL_ZERO:
        raise InputError("pose-cell activity is all zero; reset() or inject() before stepping")
    raise InputError(DIED_OUT)
