"""``RecodedView``: local view cells that accept the newest matching template
(xRatSLAM's RecodedLV).

xRatSLAM's authors sped their local view up by searching the templates from the newest
backwards and accepting the first one under ``vt_match_threshold``: a familiar place has
usually been seen recently, so the search stops early; a new place still compares every
template. The decision can differ from :class:`~torchratslam.local_view.view.LocalView`'s
(the *best* template): when an older template matches better, the newer one is taken.
The search is :func:`~torchratslam.local_view.search.newest_first`.
:mod:`torchratslam.pipeline.defaults` registers it as ``"recoded"`` in
:data:`~torchratslam.registry.LOCAL_VIEWS` (config key ``general.local_view``).
"""

from __future__ import annotations

import torch

from torchratslam.config import LocalViewParams
from torchratslam.local_view.search import newest_first
from torchratslam.local_view.view import LocalView

__all__ = ["RecodedView"]


class RecodedView(LocalView):
    """:class:`~torchratslam.local_view.view.LocalView` with the newest-first search:
    :meth:`process` and :meth:`match` return the newest template whose best mean error
    is at most the threshold (``vt_match_threshold`` unless ``match`` is given one).

    Args:
        params: local view parameters.
        dtype: template dtype (float64, the default, as OpenRatSLAM's ``double``; or float32).
        device: template device.
    """

    kind = "recoded"

    def __init__(
        self,
        params: LocalViewParams,
        *,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
    ) -> None:
        super().__init__(params, dtype=dtype, device=device)

    def _search(self, t: torch.Tensor, threshold: float | None) -> tuple[int, int, float]:
        if self.bank is None or len(self.bank) == 0:
            return super()._search(t, threshold)
        assert self.matcher is not None
        limit = self.params.vt_match_threshold if threshold is None else threshold
        return newest_first(self.matcher, self.bank, t, limit)
