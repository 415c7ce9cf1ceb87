"""The exact SAD kernels against float64 loops; chunked and one-chunk calls agree."""

from __future__ import annotations

import numpy as np
import torch

from torchratslam.local_view.exact import rolled_sad, window_sad, window_sad_at


def test_window_sad_per_offset_and_in_chunks_equals_the_loop():
    rng = np.random.default_rng(3)
    y, x, w = 128, 130, 120  # 16 640 pixels: chunks of 31 templates
    data = torch.from_numpy(rng.random((40, y, x)))
    block = torch.from_numpy(rng.random((y, w)))
    offsets = torch.tensor([0, 5, 10])
    t = torch.from_numpy(rng.integers(0, 40, 70))
    k = torch.from_numpy(rng.integers(0, 3, 70))
    got = window_sad(data, block, t, k, offsets)
    for i in range(70):
        o = int(offsets[k[i]])
        want = (data[t[i], :, o : o + w] - block).abs().sum()
        assert abs(float(got[i]) - float(want)) < 1e-9
    for kk in range(3):  # one offset at a time: the same bits, above and below a chunk
        sel = (k == kk).nonzero()[:, 0]
        assert torch.equal(window_sad_at(data, block, t[sel], int(offsets[kk])), got[sel])
        assert torch.equal(window_sad_at(data, block, t[sel][:1], int(offsets[kk])), got[sel][:1])


def test_rolled_sad_in_chunks_equals_one_chunk_per_pair():
    rng = np.random.default_rng(4)
    y, x = 128, 130
    data = torch.from_numpy(rng.random((40, y, x))).float()
    rolled = torch.from_numpy(rng.random((3, y * x))).float()
    t = torch.from_numpy(rng.integers(0, 40, 70))
    k = torch.from_numpy(rng.integers(0, 3, 70))
    got = rolled_sad(data, rolled, t, k)  # three chunks
    for i in range(70):
        one = rolled_sad(data, rolled, t[i : i + 1], k[i : i + 1])
        assert torch.equal(one, got[i : i + 1])
        want = np.abs(
            data[t[i]].numpy().astype(np.float64).reshape(-1) - rolled[k[i]].numpy()
        ).sum()
        assert abs(float(got[i]) - want) < 1e-2
