"""Local view cells, the first stage of the data flow: ``LocalView`` and ``FeatureView``.

The local view decides, for every frame, whether the scene is familiar (which visual
template, at which column offset) or new, following OpenRatSLAM's ``LocalViewMatch``.
Both stages are thin :class:`~torchratslam.local_view.template_view.TemplateView`
modules that turn an observation into a template; the rest is done by the rooms of this
package:

* :mod:`~torchratslam.local_view.preprocessing`: image -> template (crop, grey, block
  averaging, global and patch normalisation);
* :mod:`~torchratslam.local_view.bank`: every template in one tensor that grows by
  doubling, with its metadata and summaries;
* :mod:`~torchratslam.local_view.matcher`, :mod:`~torchratslam.local_view.bounds`,
  :mod:`~torchratslam.local_view.exact`, :mod:`~torchratslam.local_view.search`: the
  exact, pruned best (template, offset) by mean absolute difference.

:mod:`torchratslam.pipeline.defaults` registers both in
:data:`~torchratslam.registry.LOCAL_VIEWS` (``"ratslam"``, ``"features"``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from torchratslam.config import LocalViewParams
from torchratslam.errors import ConfigError, InputError, MapFormatError
from torchratslam.local_view.preprocessing import as_tensor, check_finite, preprocess
from torchratslam.local_view.template_view import TemplateView
from torchratslam.messages import Frame

__all__ = ["FeatureView", "LocalView"]


class LocalView(TemplateView):
    """RatSLAM local view cells on camera images (OpenRatSLAM's ``LocalViewMatch``).

    Args:
        params: local view parameters.
        dtype: template dtype (float64, the default, as OpenRatSLAM's ``double``; or float32).
        device: template device.
        prune: skip work with exact lower bounds (False: evaluate every pair; same result).
        exact_errors: report the exact best error of novel views too (slower); by
            default a new template's ``ViewMatch.error`` is a lower bound (above
            ``vt_match_threshold``) of the best error, the decision being the same.

    Example:
        >>> lv = LocalView(LocalViewParams(template_x_size=8, template_y_size=4))
        >>> lv.process(np.zeros((4, 8), np.uint8)).is_new
        True
    """

    kind = "ratslam"
    _trusted_templates = True  # preprocess() checks images and yields finite templates

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
        prune: bool = True,
        exact_errors: bool = False,
    ) -> None:
        super().__init__(params, dtype=dtype, device=device, prune=prune, exact_errors=exact_errors)
        self.image_shape: tuple[int, ...] | None = None  # (H, W) of the processed frames
        self._setup(params.template_y_size, params.template_x_size)

    def preprocess(self, image: Any) -> torch.Tensor:
        """:func:`preprocess` with this module's parameters, dtype and device.

        Shape:
            image: ``(H, W)`` or ``(H, W, 3)`` -> ``(Y, X)``.
        """
        return preprocess(image, self.params, dtype=self.dtype, device=self.device)

    def _to_template(self, observation: Any) -> torch.Tensor:
        if isinstance(observation, Frame):
            observation = observation.image
        shape = tuple(getattr(observation, "shape", ()))[:2]
        if self.image_shape is None:
            template = self.preprocess(observation)
            self.image_shape = shape  # recorded once the first image passed the checks
            return template
        if shape != self.image_shape:
            raise InputError(
                f"image of shape {shape} differs from the earlier frames' {self.image_shape}; "
                "one local view processes one camera (use a new LocalView for another)"
            )
        return self.preprocess(observation)

    def _extra_state(self) -> dict:
        return {"image_shape": np.asarray(self.image_shape or (), dtype=np.int64)}

    def _set_extra_state(self, state: dict) -> None:
        shape = tuple(int(v) for v in np.asarray(state.get("image_shape", ())).reshape(-1))
        self.image_shape = shape if len(shape) == 2 else None

    def _validate_shape(self, shape: tuple[int, ...]) -> None:
        want = (self.params.template_y_size, self.params.template_x_size)
        if shape != want:
            raise MapFormatError(
                f"saved templates are {shape[1]}x{shape[0]} but the configuration asks for "
                f"{want[1]}x{want[0]} (template_x_size x template_y_size); use the saved config"
            )


class FeatureView(TemplateView):
    """Local view cells on any 1D or 2D feature array (a laser scan, a descriptor).

    The same bank and matcher as :class:`LocalView`, without image preprocessing: a 1D
    array of N values is a 1 x N template, a 2D array is used as is. The template size is
    fixed by the first observation. ``vt_panoramic`` makes the matching circular (a 360
    degree scan); the error is the mean absolute difference in the feature's units
    (times ``scale``), compared with ``vt_match_threshold``.

    Args:
        params: local view parameters (matching keys only; crop/size keys are unused).
        dtype: template dtype.
        device: template device.
        key: when given a :class:`~torchratslam.messages.Frame`, read ``frame.scans[key]``
            (None: ``frame.image``).
        scale: multiply features by this before matching.
        prune: skip work with exact lower bounds.
        exact_errors: report the exact best error of novel views too (slower).
    """

    kind = "features"

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
        key: str | None = None,
        scale: float = 1.0,
        prune: bool = True,
        exact_errors: bool = False,
    ) -> None:
        super().__init__(params, dtype=dtype, device=device, prune=prune, exact_errors=exact_errors)
        if not math.isfinite(scale) or scale <= 0:
            raise ConfigError(f"scale must be a positive finite number, got {scale}")
        self.key, self.scale = key, float(scale)

    def _to_template(self, observation: Any) -> torch.Tensor:
        if isinstance(observation, Frame):
            if self.key is None:
                observation = observation.image
            elif self.key not in observation.scans:
                raise InputError(
                    f"frame {observation.index} has no scan {self.key!r} "
                    f"(available: {', '.join(sorted(observation.scans)) or 'none'})"
                )
            else:
                observation = observation.scans[self.key]
        x = as_tensor(observation, "features")
        if x.numel() == 0:
            raise InputError("features: empty array")
        if x.ndim == 1:
            x = x[None]
        if x.ndim != 2:
            raise InputError(f"features: expected a 1D or 2D array, got shape {tuple(x.shape)}")
        x = x.to(device=self.device, dtype=self.dtype)
        check_finite(x, "features")
        if self.scale != 1.0:
            x = x * self.scale
        if self.bank is None:
            self._setup(x.shape[0], x.shape[1])
        elif tuple(x.shape) != self.template_shape:
            raise InputError(
                f"features of shape {tuple(x.shape)} differ from the first observation's "
                f"{self.template_shape}; every observation must have the same size"
            )
        return x
