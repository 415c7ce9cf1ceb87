"""Path-integration tables: how each theta layer moves in ``(y, x)`` per cell of travel."""

from __future__ import annotations

import math

import numpy as np

from torchratslam.config import PoseCellParams
from torchratslam.pose_cells.functional import QUADRANTS

__all__ = ["MotionTables"]


class MotionTables:
    """Per theta layer, the parts of path integration that do not depend on the
    distance (cached per direction of travel), and the per-step translation plan.

    Args:
        params: pose-cell parameters (``pc_dim_th``, ``pc_axis``, ``pc_multi_cell``,
            ``pc_wrap``).
    """

    def __init__(self, params: PoseCellParams) -> None:
        self.n_th = params.pc_dim_th
        self.swap_axes = params.pc_axis == "math"
        self.one_cell = not params.pc_multi_cell
        self.edge_loss = params.pc_wrap == "openratslam"
        self._geo: dict[tuple, dict[str, np.ndarray]] = {}

    def geometry(self, backwards: bool) -> dict[str, np.ndarray]:
        """``coef_y``, ``coef_x`` (the move per cell of translation), ``step_y``,
        ``step_x`` (one-cell: the neighbour's shift), ``sin``, ``cos`` (of ``dir90``),
        ``src`` ``(TH, 2, 2)`` and ``corner`` ``(TH, 2)`` (the edge loss's cells as
        (y_is_last, x_is_last)), one entry per global theta layer."""
        key = (bool(backwards), self.one_cell, self.swap_axes, self.n_th)
        g = self._geo.get(key)
        if g is not None:
            return g
        n_t = self.n_th
        layers = np.arange(n_t)
        add = math.pi if backwards else 0.0
        g = {}
        if not self.one_cell:
            direction = layers * (2.0 * math.pi / n_t) + add
            cx, cy = np.cos(direction), np.sin(direction)
            if not self.swap_axes:  # OpenRatSLAM: (sin, cos)
                cx, cy = cy, cx
            g["coef_y"], g["coef_x"] = cy, cx
        else:  # OpenRatSLAM's path_integration, its own arithmetic
            direction = layers * ((2.0 * math.pi) / n_t) + add
            q = np.floor(direction * 2 / math.pi)
            d90 = direction - q * math.pi / 2
            sin, cos = np.sin(d90), np.cos(d90)  # a = v sin along +i, b = v cos along +j
            tab = QUADRANTS[np.remainder(q.astype(np.int64), 4)]  # (TH, 5, 2)
            ax = 1 if self.swap_axes else 0  # "math": the mirror across the diagonal
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
            if self.swap_axes:
                cells = cells[..., ::-1]
            g["src"] = np.ascontiguousarray(cells[:, :2, :])
            g["corner"] = np.ascontiguousarray(cells[:, 2, :])
        self._geo[key] = g
        return g

    def translation_plan(self, trans: np.ndarray, layers: np.ndarray) -> dict[str, np.ndarray]:
        """Per theta layer, how path integration moves it in (y, x).

        Args:
            trans: translation in cells (signed), one per network.
            layers: global theta layer of each layer.

        Returns:
            ``shift_y``, ``shift_x`` (integer base shift), ``step_y``, ``step_x`` (the
            neighbour's shift, base +- 1) and ``w_y``, ``w_x`` (the neighbour's weight),
            all ``(B, T)``: ``out = take(base) + w (take(step) - take(base))``. With the
            edge loss, also ``lost`` ``(B, T, 2)`` weights and ``src`` ``(B, T, 2, 2)``,
            ``corner`` ``(B, T, 2)`` cells as (y_is_last, x_is_last).

        Shape:
            trans: ``(B,)``; layers: ``(B, T)``.
        """
        back = trans < 0
        g0, g1 = self.geometry(False), self.geometry(True)
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
        if not self.one_cell:
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
        if self.edge_loss:
            sin, cos = geo["sin"], geo["cos"]
            se = v * sin * (1.0 - v * cos)
            nw = v * cos * (1.0 - v * sin)
            plan["lost"] = np.stack([se, nw], axis=-1)
            plan["src"], plan["corner"] = geo["src"], geo["corner"]
        return plan
