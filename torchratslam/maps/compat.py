"""Whether a map can be used with a configuration, and making it usable.

A map can be continued or merged only with the pose-cell network size and the template
size it was made with (:func:`check_compatible`); a map read without its templates can be
plotted but not continued (:func:`require_templates`); a reference-format map read
without a configuration gets the configuration's template shape and pose-cell sizes
(:func:`conform`).

Example:
    >>> from torchratslam.maps.compat import check_compatible  # doctest: +SKIP
    >>> check_compatible(stored, config, what="map run1")  # doctest: +SKIP
"""

from __future__ import annotations

from typing import Any

from torchratslam.errors import MapFormatError
from torchratslam.maps.state import MISSING_KEY, MapState, config_pc_dims

__all__ = ["check_compatible", "conform", "require_templates"]


def check_compatible(state: MapState, config: Any, *, what: str = "stored map") -> None:
    """Raise :class:`MapFormatError` unless ``state`` can be used with ``config``.

    Maps can only be continued or merged with the same pose-cell network size and the
    same template size: pose-cell coordinates and templates would not line up.

    Args:
        state: the map.
        config: a ``RatSLAMConfig`` or a flat dict.
        what: how to name the map in the message.
    """
    flat = config.to_flat() if hasattr(config, "to_flat") else dict(config)
    problems = []
    sides = (state.config, flat)
    square = not any(c.get(k) for c in sides for k in ("pc_dim_x", "pc_dim_y"))
    if not square and all("pc_dim_xy" in c for c in sides):
        mine_d, theirs_d = config_pc_dims(state.config)[:2], config_pc_dims(flat)[:2]
        if mine_d != theirs_d:
            problems.append(
                f"the pose cells' (X, Y) = {mine_d} in the map but {theirs_d} in the "
                "config (pc_dim_x / pc_dim_y, else pc_dim_xy)"
            )
    keys = ("pc_dim_xy",) if square else ()
    for key in (*keys, "pc_dim_th", "template_x_size", "template_y_size"):
        mine, theirs = state.config.get(key), flat.get(key)
        if mine is not None and theirs is not None and int(mine) != int(theirs):
            problems.append(f"{key} = {mine} in the map but {theirs} in the config")
    if problems:
        raise MapFormatError(
            f"{what} is incompatible with the configuration: {'; '.join(problems)}. "
            "Use the config the map was made with (saved in its state.json)."
        )


def require_templates(state: MapState, *, what: str = "map") -> None:
    """Raise :class:`MapFormatError` when ``state`` was read without its templates (a
    reference-format save lacking ``localviewcells.txt``): it can be plotted and compared,
    but not merged or continued."""
    missing = state.scalars.get(MISSING_KEY)
    if missing:
        raise MapFormatError(
            f"{what} ({state.name or 'in memory'}) has no templates: {missing} is missing "
            "from its directory; merging or continuing a map needs its templates (plots, "
            "ICP and ATE work without them)"
        )


def conform(state: MapState, config: Any, *, what: str = "stored map") -> MapState:
    """``state`` made usable with ``config``: a reference-format map read without a
    config (templates ``(N, 1, S)``, no pose-cell sizes) gets its templates reshaped to
    the config's ``template_y_size x template_x_size`` and the config's pose-cell sizes;
    then compatibility is checked (:func:`check_compatible`).

    Raises:
        MapFormatError: the map cannot be used with ``config``.
    """
    require_templates(state, what=what)
    flat = config.to_flat() if hasattr(config, "to_flat") else dict(config)
    ty, tx = int(flat.get("template_y_size", 1)), int(flat.get("template_x_size", 1))
    if (
        state.scalars.get("imported_from") == "reference"
        and state.templates.shape[1:] != (ty, tx)
        and state.templates.shape[1] * state.templates.shape[2] == ty * tx
        and state.templates.shape[1] == 1
    ):
        state = state.copy()
        state.templates = state.templates.reshape(-1, ty, tx)
        state.config = {
            **flat,
            **{
                k: v
                for k, v in state.config.items()
                if k not in ("template_x_size", "template_y_size")
            },
        }
    missing = [
        k for k in ("pc_dim_xy", "pc_dim_th", "pc_dim_x", "pc_dim_y") if k not in state.config
    ]
    if state.scalars.get("imported_from") == "reference" and missing:
        state = state.copy()
        state.config.update({k: flat.get(k) for k in missing})
    check_compatible(state, config, what=what)
    return state
