"""The shared ``nn.Module`` machinery of the local views: bank, matcher, learning, state.

:class:`TemplateView` holds a :class:`~torchratslam.local_view.bank.TemplateBank` and a
:class:`~torchratslam.local_view.matcher.TemplateMatcher`, matches every observation
against the bank and learns a new template when the best mean absolute difference (MAD)
is above ``vt_match_threshold``, following OpenRatSLAM's ``LocalViewMatch`` (see
``shared/reference/ratslam-algorithm.md``). Subclasses only turn an observation into a
template (:class:`~torchratslam.local_view.view.LocalView`: a camera image;
:class:`~torchratslam.local_view.view.FeatureView`: any 1D or 2D feature array).

``match()`` always reports the true minimum error; :meth:`TemplateView.process` stops
as soon as every candidate is provably above ``vt_match_threshold``, so for a new
template its ``ViewMatch.error`` is a lower bound (> threshold) of the best error unless
``exact_errors=True``. The decision is the brute-force one either way. Unlike
OpenRatSLAM, templates are not skipped by ``|mean difference| > vt_match_threshold``:
that rule is exact in panoramic mode but not in normal mode (the compared columns are a
window, whose mean differs from the template's).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from torchratslam.config import LocalViewParams
from torchratslam.errors import ConfigError, InputError, MapFormatError
from torchratslam.local_view.bank import TemplateBank
from torchratslam.local_view.matcher import TemplateMatcher
from torchratslam.local_view.preprocessing import as_tensor, check_finite
from torchratslam.messages import ViewMatch
from torchratslam.shapes import check_shape

__all__ = ["STATE_VERSION", "TemplateView"]

STATE_VERSION = 1


def _check_dtype(dtype: torch.dtype) -> None:
    if dtype not in (torch.float32, torch.float64):
        raise ConfigError(f"dtype must be torch.float32 or torch.float64, got {dtype}")


class TemplateView(nn.Module):
    """Shared machinery of :class:`LocalView` and :class:`FeatureView`.

    A ``torch.nn.Module`` without parameters: ``.to(device, dtype)``, ``.double()``,
    ``.float()``, ``.cpu()`` and ``.cuda()`` move the template bank and rebuild what is
    derived from it (the matcher's index tensors and per-template summaries) in the new
    dtype and device; ``state_dict()`` holds the whole state (all templates, their
    creation frames, the current and previous template, the frame counter) as CPU
    tensors and Python scalars under ``_extra_state``, so ``torch.save`` /
    ``torch.load(weights_only=True)`` and ``load_state_dict`` round-trip it.
    """

    kind = "base"

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
        prune: bool = True,
        exact_errors: bool = False,
    ) -> None:
        if not isinstance(params, LocalViewParams):
            raise ConfigError(f"expected LocalViewParams, got {type(params).__name__}")
        _check_dtype(dtype)
        super().__init__()
        self.params = params
        self.dtype = dtype
        self.device = torch.device(device) if device is not None else torch.device("cpu")
        self.prune = prune
        self.exact_errors = exact_errors
        self.bank: TemplateBank | None = None
        self.matcher: TemplateMatcher | None = None
        self.current_id = -1
        self.previous_id = -1
        self.frame_counter = 0

    # -- setup
    def _setup(self, y_size: int, x_size: int) -> None:
        p = self.params
        self.matcher = TemplateMatcher(
            y_size,
            x_size,
            panoramic=p.vt_panoramic,
            shift=p.vt_shift_match,
            step=p.vt_step_match,
            device=self.device,
        )
        self.bank = self.matcher.make_bank(dtype=self.dtype, device=self.device)

    @property
    def template_shape(self) -> tuple[int, int] | None:
        """``(Y, X)`` of the templates (None before the size is known)."""
        return None if self.bank is None else (self.bank.y_size, self.bank.x_size)

    _trusted_templates = False
    """True when :meth:`_to_template` always returns finite templates of the bank's
    shape, dtype and device (then :meth:`process` skips re-checking them)."""

    def _to_template(self, observation: Any) -> torch.Tensor:
        raise NotImplementedError

    # -- bank access
    @property
    def templates(self) -> torch.Tensor:
        """All templates, shape ``(N, Y, X)``."""
        if self.bank is None:
            return torch.zeros(0, 0, 0, dtype=self.dtype, device=self.device)
        return self.bank.data

    def __len__(self) -> int:
        bank = self._modules.get("bank")  # not through nn.Module's __getattr__: every frame
        return 0 if bank is None else len(cast(TemplateBank, bank))

    @property
    def offsets(self) -> torch.Tensor:
        """The compared column offsets, shape ``(K,)``."""
        if self.matcher is None:
            raise InputError("no template size yet: process one observation first")
        return self.matcher.offsets

    def relative_rad(self, offset: int) -> float:
        """Relative view angle of a match at ``offset`` (0 in normal mode)."""
        if not self.params.vt_panoramic or self.bank is None:
            return 0.0
        rad = offset / self.bank.x_size * 2.0 * math.pi
        return rad - 2.0 * math.pi if rad > math.pi else rad

    def _check_template(self, template: Any) -> torch.Tensor:
        t = as_tensor(template, "template").to(device=self.device, dtype=self.dtype)
        if self.template_shape is not None:
            check_shape(t, self.template_shape, "template")
        check_finite(t, "template")
        return t

    # -- matching
    def match(self, template: Any, *, threshold: float | None = None) -> tuple[int, int, float]:
        """Best (template id, offset, mean error) for a preprocessed template; no learning.

        Exactly what a brute-force loop over all templates and offsets returns (ties: the
        lowest id, then the lowest offset); ``(-1, 0, inf)`` when the bank is empty.

        Args:
            template: the view template.
            threshold: if given and the best error is above it, return ``(-1, 0, e)``
                with ``e`` a lower bound (> threshold) of the best error; faster for
                novel views. At or below the threshold the result is exact.

        Shape:
            template: ``(Y, X)``.
        """
        return self._search(self._check_template(template), threshold)

    def _search(self, t: torch.Tensor, threshold: float | None) -> tuple[int, int, float]:
        """:meth:`match` of an already checked template (``process`` made it itself)."""
        if self.bank is None or len(self.bank) == 0:
            return -1, 0, math.inf
        assert self.matcher is not None
        return self.matcher.search(
            self.bank, t, hint=self.current_id, prune=self.prune, threshold=threshold
        )

    def errors(self, template: Any, ids: Any = None) -> torch.Tensor:
        """Exact mean absolute error of the template against templates at every offset.

        Returns:
            Shape ``(M, K)``: row per template id in ``ids`` (default all), column per
            entry of :attr:`offsets`.

        Shape:
            template: ``(Y, X)``.
        """
        t = self._check_template(template)
        if self.bank is None:
            raise InputError("the template bank is empty")
        sel = None if ids is None else torch.as_tensor(ids, dtype=torch.int64, device=self.device)
        assert self.matcher is not None
        return self.matcher.errors(self.bank, t, sel)

    def process(self, observation: Any, frame_index: int | None = None) -> ViewMatch:
        """Match one observation against the bank; learn a new template if none matches.

        Args:
            observation: an image / feature array, or a :class:`~torchratslam.messages.Frame`.
            frame_index: recorded as the creation frame of a new template (default: the
                number of observations processed so far).

        Returns:
            The :class:`~torchratslam.messages.ViewMatch`.
        """
        frame = self.frame_counter if frame_index is None else int(frame_index)
        view = self._to_template(observation)
        self._set_ints(frame_counter=self.frame_counter + 1)
        threshold = None if self.exact_errors else self.params.vt_match_threshold
        if not self._trusted_templates:
            view = self._check_template(view)
        tid, offset, err = self._search(view, threshold)
        matched = tid >= 0 and err <= self.params.vt_match_threshold
        if not matched:
            assert self.bank is not None  # _to_template set it up
            tid = self.bank.append(view, frame, checked=True)[0]
        self._set_ints(previous_id=self.current_id, current_id=tid)
        if matched:
            return ViewMatch(tid, self.relative_rad(offset), err, offset, False)
        return ViewMatch(tid, 0.0, err, 0, True)

    def _set_ints(self, **values: int) -> None:
        """Set plain int attributes past ``nn.Module.__setattr__``'s checks (which look
        for parameters, buffers and modules; a per-frame cost)."""
        vars(self).update(values)

    def forward(self, observation: Any, frame_index: int | None = None) -> ViewMatch:
        """``module(observation)`` is :meth:`process` (the ``nn.Module`` call)."""
        return self.process(observation, frame_index)

    def add_templates(self, templates: Any, frames: Any = None) -> range:
        """Append templates (e.g. from a merged map); returns their new ids.

        Shape:
            templates: ``(K, Y, X)``.
        """
        t = as_tensor(templates, "templates").to(device=self.device, dtype=self.dtype)
        check_shape(t, "K Y X", "templates")
        if self.bank is None:
            self._setup(t.shape[1], t.shape[2])
        assert self.bank is not None
        return self.bank.append(t, frames)

    # -- state
    def get_state(self, *, share: bool = False) -> dict:
        """Everything needed to resume: numpy arrays and Python scalars only.

        Args:
            share: the templates as a read-only view of the bank's rows (on the CPU)
                rather than a copy: for a save that is done before the next frame (a
                checkpoint then holds no second copy of the templates).
        """
        shape = self.template_shape or (0, 0)
        n = len(self)
        bank = cast(TemplateBank, self.bank)  # set up whenever n > 0
        if not n:
            templates = np.zeros((0, *shape), np.float32)
        elif share and bank.on_cpu:
            templates = bank.data.numpy().view()
            templates.flags.writeable = False
        else:
            templates = bank.data.cpu().numpy().copy()
        return {
            "kind": self.kind,
            "version": STATE_VERSION,
            "template_shape": np.asarray(shape, dtype=np.int64),
            "templates": templates,
            "means": bank.means.cpu().numpy().copy() if n else np.zeros(0, np.float32),
            "frames": bank.frames.cpu().numpy().copy() if n else np.zeros(0, np.int64),
            "current_id": int(self.current_id),
            "previous_id": int(self.previous_id),
            "frame_counter": int(self.frame_counter),
            **self._extra_state(),
        }

    def set_state(self, state: dict) -> None:
        """Restore :meth:`get_state`'s output (replaces the bank)."""
        try:
            version = int(state.get("version", -1))
            templates = np.asarray(state["templates"])
            frames = np.asarray(state.get("frames", np.full(len(templates), -1)), dtype=np.int64)
            shape = tuple(
                int(s) for s in np.asarray(state.get("template_shape", templates.shape[1:]))
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise MapFormatError(
                f"local view state is malformed ({exc!r}); was it saved by get_state()?"
            ) from None
        if version != STATE_VERSION:
            raise MapFormatError(
                f"local view state version {version} is not supported (expected {STATE_VERSION})"
            )
        if templates.ndim != 3 or (len(templates) and tuple(templates.shape[1:]) != shape):
            raise MapFormatError(
                f"local view state: templates of shape {templates.shape} are not (N, {shape})"
            )
        self._validate_shape(shape)
        if len(frames) != len(templates):
            raise MapFormatError("local view state: 'frames' and 'templates' differ in length")
        if not np.isfinite(templates).all():
            raise MapFormatError("local view state: templates contain NaN or infinite values")
        self.bank = None
        self.matcher = None
        if shape != (0, 0):
            self._setup(*shape)
            if len(templates):
                cast(TemplateBank, self.bank).append(
                    torch.as_tensor(templates), torch.as_tensor(frames)
                )
        self.current_id = int(state.get("current_id", -1))
        self.previous_id = int(state.get("previous_id", -1))
        self.frame_counter = int(state.get("frame_counter", 0))
        self._set_extra_state(state)

    def _extra_state(self) -> dict:
        return {}

    def _set_extra_state(self, state: dict) -> None:
        pass

    # -- torch.nn.Module behaviour
    def _apply(self, fn: Callable[[torch.Tensor], torch.Tensor], recurse: bool = True) -> Any:
        """Follow ``.to`` / ``.double`` / ``.float`` / ``.cuda``: rebuild the bank and matcher
        in the dtype and device that ``fn`` gives a floating tensor."""
        probe = fn(torch.zeros((), dtype=self.dtype, device=self.device))
        if (probe.dtype, probe.device) != (self.dtype, self.device):
            _check_dtype(probe.dtype)
            state = self.get_state()
            self.dtype, self.device = probe.dtype, probe.device
            self.set_state(state)  # the summaries and index tensors are derived again
        return super()._apply(fn, recurse)

    def get_extra_state(self) -> dict:
        """:meth:`get_state` with arrays as CPU tensors (what ``state_dict()`` stores)."""
        return {
            k: torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray) else v
            for k, v in self.get_state().items()
        }

    def set_extra_state(self, state: Any) -> None:
        """Restore :meth:`get_extra_state`'s output (``load_state_dict()``)."""
        if not isinstance(state, dict):
            raise MapFormatError(f"local view state_dict entry is a {type(state).__name__}")
        self.set_state(
            {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in state.items()}
        )

    def _validate_shape(self, shape: tuple[int, ...]) -> None:
        pass

    def memory_bytes(self) -> int:
        """Bytes held by the bank (allocated capacity)."""
        if self.bank is None:
            return 0
        return self.bank.capacity * self.bank.bytes_per_template()
