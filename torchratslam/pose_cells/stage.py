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
from typing import Any, cast

import numpy as np
import torch

from ratslam_graph.geometry import pc_distance, pc_distance_one
from ratslam_graph.messages import Action, ActionKind
from torchratslam.config import PoseCellParams
from torchratslam.errors import InputError, MapFormatError
from torchratslam.messages import ViewMatch
from torchratslam.pose_cells.network import PoseCellNetwork

__all__ = ["RECENT_TEMPLATES", "PoseCells"]

RECENT_TEMPLATES = 10
"""Templates among the last this many learnt do not inject energy."""


def _with_room(a: np.ndarray, n: int) -> np.ndarray:
    """``a`` (its first ``n`` rows in use) with room for one more row (doubling)."""
    if n < len(a):
        return a
    out = np.zeros((max(16, 2 * n), *a.shape[1:]), dtype=a.dtype)
    out[:n] = a[:n]
    return out


def _nearest() -> Any:
    """:func:`~torchratslam.pose_cells._nearest.nearest_cell` (numba, imported on first
    use)."""
    from torchratslam.pose_cells._nearest import nearest_cell

    return nearest_cell


def _exp(x: float) -> float:
    """``exp(x)`` as C's: ``inf`` past the largest double, where Python raises (a
    template seen on every frame for long enough decays past it; OpenRatSLAM's energy
    is then -inf and nothing is injected)."""
    try:
        return math.exp(x)
    except OverflowError:
        return math.inf


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
        dtype: activity dtype (float64 default, as OpenRatSLAM's ``double``; float32 supported).
        device: torch device.
        method: dynamics method of the network (see :class:`PoseCellNetwork`).
    """

    def __init__(
        self,
        params: PoseCellParams | None = None,
        *,
        dtype: torch.dtype = torch.float64,
        device: Any = None,
        method: str = "auto",
    ) -> None:
        self.params = params if params is not None else PoseCellParams()
        self.network = PoseCellNetwork(self.params, 1, dtype=dtype, device=device, method=method)
        self.dims = self.network.dims
        self._dims_f = (float(self.dims[0]), float(self.dims[1]), float(self.dims[2]))
        self._clear()

    def _clear(self) -> None:
        # rows [:n] of buffers with spare room (no copy of every row per new one)
        self._set_templates(np.zeros((0, 3)), np.zeros(0))
        self._set_experiences(np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
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

    def _set_templates(self, pc: np.ndarray, decay: np.ndarray) -> None:
        self._n_t = len(pc)
        self._t_pc, self._t_decay = pc.astype(np.float64), decay.astype(np.float64)

    def _set_experiences(self, pc: np.ndarray, template: np.ndarray) -> None:
        self._n_e = len(pc)
        self._e_pc, self._e_template = pc.astype(np.float64), template.astype(np.int64)

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
            self._t_pc = _with_room(self._t_pc, n)
            self._t_decay = _with_room(self._t_decay, n)
            self._t_pc[n] = self._best
            self._t_decay[n] = p.vt_active_decay
            self._n_t = n + 1
        elif vt < n - RECENT_TEMPLATES or (
            p.vt_inject_rule == "openratslam" and n < RECENT_TEMPLATES
        ):  # OpenRatSLAM's unsigned "size - 10" wraps while fewer than 10 exist
            if vt == self.current_vt:
                self._t_decay[vt] += p.vt_active_decay
            energy = p.pc_vt_inject_energy / 30.0 * (30.0 - _exp(1.2 * self._t_decay[vt]))
            if energy > 0:
                n_th = self.dims[2]
                self.vt_delta_pc_th = rad / (2.0 * math.pi) * n_th
                pc_x, pc_y, pc_th = self._t_pc[vt]
                th = pc_th + self.vt_delta_pc_th
                if th < 0:
                    th += n_th
                if th >= n_th:
                    th -= n_th
                self.network.inject(int(pc_x), int(pc_y), int(th) % n_th, energy)
        decay = self.template_decay  # in place: the same elementwise arithmetic
        np.subtract(decay, p.pc_vt_restore, out=decay)
        np.maximum(decay, p.vt_active_decay, out=decay)
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

    def _create(self) -> Action:
        src = self.current_exp
        new = self.n_experiences
        self._e_pc = _with_room(self._e_pc, new)
        self._e_template = _with_room(self._e_template, new)
        self._e_pc[new] = self._best
        self._e_template[new] = self.current_vt
        self._n_e = new + 1
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
        d_current = pc_distance_one(
            self._e_pc[self.current_exp].tolist(), self._corrected_centre(), self.dims
        )
        if d_current > threshold or self.current_vt != self.prev_vt:
            # the first nearest, as OpenRatSLAM's strict '<' (pc_distance's arithmetic)
            k, d = _nearest()(
                self._e_pc,
                np.array(exps, dtype=np.int64),
                self.current_exp,
                self._corrected_centre(),
                self._dims_f,
            )
            if k >= 0 and d < threshold:
                src = self.current_exp
                self.current_exp = int(k)
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
        self._set_templates(tpc, decay)
        self._set_experiences(epc, etpl)
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
            self.network.place_packet(x, y, th)
        self.network.set_centre(self._best)
