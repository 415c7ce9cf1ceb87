"""The Python API's argument checks for :class:`~torchratslam.pipeline.ratslam.RatSLAM`:
each refusal names the argument, and comes before any state changes."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from torchratslam.config import RatSLAMConfig, load_config
from torchratslam.errors import ConfigError, InputError
from torchratslam.readers.limits import MAX_SPEED, MAX_TURN_RATE


def as_config(config: Any) -> RatSLAMConfig:
    """``config``: a :class:`RatSLAMConfig`, None (the defaults), a preset name or file
    path, or a dict of flat keys (as :func:`~torchratslam.config.load_config` takes)."""
    if config is None:
        return RatSLAMConfig()
    if isinstance(config, RatSLAMConfig):
        return config
    if isinstance(config, (str, Path, Mapping)):
        return load_config(config)
    raise ConfigError(
        "RatSLAM(config=...): expected a RatSLAMConfig, a preset name, a config file path "
        f"or a dict of flat keys; got {type(config).__name__}"
    )


def check_device(device: torch.device | str | None) -> None:
    """Refuse a ``device`` torch cannot use here (naming the argument)."""
    if device is None:
        return
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError) as exc:
        raise InputError(f"RatSLAM(device={device!r}): not a torch device ({exc})") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise InputError(
            f"RatSLAM(device={device!r}): this torch has no CUDA device; use device='cpu'"
        )


def check_odometry_step(odometry: Any) -> tuple[float, float, float]:
    """``step(odometry=...)``: three finite numbers ``(vtrans, vrot, dt)``, ``dt >= 0``
    and the speeds within the readers' limits, or an :class:`InputError` naming it."""
    try:
        values = tuple(float(v) for v in odometry)
    except (TypeError, ValueError):
        raise InputError(
            f"step(odometry={odometry!r:.80}): expected three numbers (vtrans m/s, "
            "vrot rad/s, dt s)"
        ) from None
    if len(values) != 3:
        raise InputError(
            f"step(odometry={odometry!r:.80}): expected three numbers (vtrans m/s, "
            f"vrot rad/s, dt s), got {len(values)}"
        )
    vtrans, vrot, dt = values
    for name, v, limit in (("vtrans", vtrans, MAX_SPEED), ("vrot", vrot, MAX_TURN_RATE)):
        if not math.isfinite(v) or abs(v) > limit:
            raise InputError(
                f"step(odometry=...): {name} = {v:g} is not finite or exceeds {limit:g}; "
                "the step was refused and the state is unchanged"
            )
    if not math.isfinite(dt) or dt < 0:
        raise InputError(
            f"step(odometry=...): dt = {dt:g} must be a finite number >= 0; the step was "
            "refused and the state is unchanged"
        )
    return vtrans, vrot, dt
