"""``LinearScanView``: local view cells that search as OpenRatSLAM's C++ does, one
template after another (the baseline of xRatSLAM's Experiment II).

OpenRatSLAM's ``LocalViewMatch::compare`` compares the view with every template in the
order they were learnt (skipping those whose mean differs by more than
``vt_match_threshold + 0.005``), every offset summed row by row with an early exit once
the sum exceeds the best so far. Its time grows linearly with the templates (xRatSLAM's
Fig. 7: 14.43 ms a frame on the iRat recording). :class:`LinearScanView` runs that loop,
compiled (:func:`~torchratslam.local_view._scan.linear_scan`), so that the project's
searches can be timed against the one the paper timed.

Its decisions are :class:`~torchratslam.local_view.view.LocalView`'s in panoramic mode
(a template whose mean differs by more than the threshold cannot match: every offset
compares every pixel). In normal mode the compared columns are a window whose mean is
not the template's, so the mean rule can skip the best template, as it can in
OpenRatSLAM. :mod:`torchratslam.pipeline.defaults` registers it as ``"linear"`` in
:data:`~torchratslam.registry.LOCAL_VIEWS`.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from torchratslam.config import LocalViewParams
from torchratslam.local_view.view import LocalView

__all__ = ["LinearScanView"]


class LinearScanView(LocalView):
    """:class:`~torchratslam.local_view.view.LocalView` searching by OpenRatSLAM's
    linear scan (on the CPU; a bank on another device is searched pair by pair in
    torch, every pair, with the same mean rule).

    Args:
        params: local view parameters.
        dtype: template dtype (float64, the default, as OpenRatSLAM's ``double``; or float32).
        device: template device.
    """

    kind = "linear"

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
    ) -> None:
        super().__init__(params, dtype=dtype, device=device, prune=False)

    def _search(self, t: torch.Tensor, threshold: float | None) -> tuple[int, int, float]:
        if self.bank is None or len(self.bank) == 0:
            return -1, 0, math.inf
        from torchratslam.local_view._scan import MEAN_EPSILON, linear_scan

        matcher, bank = self.matcher, self.bank
        assert matcher is not None
        skip = self.params.vt_match_threshold + MEAN_EPSILON
        if not bank.on_cpu:
            errs = matcher.errors(bank, t)  # (N, K), every pair
            far = (bank.means - t.mean()).abs() > skip
            errs = errs.masked_fill(far[:, None], math.inf).reshape(-1)
            i = int(torch.argmin(errs))
            if not math.isfinite(float(errs[i])):
                return -1, 0, math.inf
            kk = matcher.n_offsets
            return i // kk, int(matcher.offsets[i % kk]), float(errs[i])
        tid, k, sad = linear_scan(
            bank.array("data"),
            bank.array("means"),
            len(bank),
            np.ascontiguousarray(t.numpy()),
            matcher.offsets_np,
            matcher.panoramic,
            matcher.width,
            matcher.shift,
            skip,
        )
        if tid < 0:
            return -1, 0, math.inf
        return int(tid), int(matcher.offsets_np[k]), float(sad) / matcher.npix
