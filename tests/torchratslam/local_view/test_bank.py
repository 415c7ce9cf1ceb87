"""The template bank: rows, metadata and summaries kept in step as it grows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from torchratslam.errors import ConfigError, InputError
from torchratslam.local_view.bank import TemplateBank


def _summaries(t: torch.Tensor) -> dict[str, torch.Tensor]:
    return {"cols": t.sum(1), "peak": t.amax(dim=(1, 2))[:, None]}


def _bank(capacity: int = 1) -> TemplateBank:
    return TemplateBank(
        3,
        5,
        summaries=_summaries,
        summary_shapes={"cols": (5,), "peak": (1,)},
        capacity=capacity,
        dtype=torch.float64,
    )


def test_append_keeps_rows_metadata_and_summaries_in_step_while_doubling():
    rng = np.random.default_rng(0)
    rows = rng.random((37, 3, 5))
    bank = _bank()
    caps = []
    for i, r in enumerate(rows):
        ids = bank.append(torch.from_numpy(r) if i % 2 else torch.from_numpy(r[None]), i * 10)
        assert list(ids) == [i]
        caps.append(bank.capacity)
    assert sorted(set(caps)) == [1, 2, 4, 8, 16, 32, 64]
    assert len(bank) == 37 and bank.ids.tolist() == list(range(37))
    np.testing.assert_array_equal(bank.data.numpy(), rows)
    np.testing.assert_allclose(bank.means.numpy(), rows.mean((1, 2)), atol=1e-15)
    assert bank.frames.tolist() == [i * 10 for i in range(37)]
    for i in range(37):  # every summary row belongs to its template
        np.testing.assert_allclose(bank.summary("cols")[i].numpy(), rows[i].sum(0), atol=1e-15)
        assert float(bank.summary("peak")[i, 0]) == rows[i].max()
    assert bank.summary_shapes == {"cols": (5,), "peak": (1,)}


def test_array_is_a_numpy_view_of_the_whole_capacity_that_follows_growth():
    bank = _bank(capacity=2)
    bank.append(torch.ones(2, 3, 5))
    first = bank.array("data")
    assert first.shape == (2, 3, 5) and bank.array("data") is first  # made once
    bank.append(torch.full((1, 3, 5), 2.0))  # grows to 4 rows: a new view
    data, cols = bank.array("data"), bank.array("cols")
    assert data is not first and data.shape == (4, 3, 5) and bank.on_cpu
    np.testing.assert_array_equal(data[:3], bank.data.numpy())
    assert not data[3].any()  # rows past len(bank) are zeros
    np.testing.assert_array_equal(cols[:3], bank.summary("cols").numpy())
    bank.append(torch.zeros(1, 3, 5))  # no growth: the same view sees the new row
    assert bank.array("data") is data and not data[3].any()
    data[0, 0, 0] = 7.0  # a view, not a copy
    assert float(bank.data[0, 0, 0]) == 7.0


def test_column_major_copy_follows_appends_and_growth():
    rng = np.random.default_rng(3)
    bank = _bank(capacity=2)
    for k in (1, 2, 1, 5, 3):  # growth 2 -> 4 -> 16 on the way
        bank.append(torch.from_numpy(rng.random((k, 3, 5))))
        cm = bank.column_major("cols")
        rows = bank.array("cols")
        assert cm.shape == (5, bank.capacity) and cm.flags.c_contiguous
        for i in range(bank.capacity):  # entry by entry: row i's entries in column i
            for c in range(5):
                assert cm[c, i] == rows[i, c]
        assert not cm[:, len(bank) :].any()
    assert bank.column_major("cols") is cm  # nothing new: the same copy


def test_column_major_copy_in_a_narrower_dtype_stores_nan_for_what_it_cannot_hold():
    bank = _bank(capacity=4)
    rows = np.full((2, 3, 5), 0.1)
    rows[1, 0, 2] = 1e39  # past float32's range
    bank.append(torch.from_numpy(rows))
    cm = bank.column_major("data", np.float32)
    assert cm.dtype == np.float32 and cm.shape == (3, 5, 4)
    assert np.isnan(cm[0, 2, 1]) and np.isnan(cm).sum() == 1
    assert cm[1, 1, 0] == np.float32(0.1) and not np.isinf(cm).any()
    assert bank.column_major("data").dtype == np.float64  # a copy per dtype


def test_a_lazy_summary_takes_no_memory_until_read_then_follows_appends():
    calls = []

    def summaries(t: torch.Tensor) -> dict[str, torch.Tensor]:
        calls.append(len(t))
        return _summaries(t)

    def make(lazy: tuple[str, ...]) -> TemplateBank:
        return TemplateBank(
            3, 5, summaries=summaries, summary_shapes={"cols": (5,), "peak": (1,)},
            capacity=2, dtype=torch.float64, lazy=lazy,
        )  # fmt: skip

    rng = np.random.default_rng(4)
    rows = rng.random((11, 3, 5))
    eager, bank = make(()), make(("peak",))
    assert bank.bytes_per_template() == eager.bytes_per_template()  # what it may use
    for r in rows[:5]:
        eager.append(torch.from_numpy(r))
        bank.append(torch.from_numpy(r))
    assert "_peak" not in bank._buffers and "_peak" in eager._buffers  # nothing allocated
    calls.clear()
    np.testing.assert_array_equal(bank.summary("peak").numpy(), eager.summary("peak").numpy())
    assert calls == [5]  # the five rows at once
    bank.summary("peak")
    assert calls == [5]  # nothing new: nothing computed
    for r in rows[5:]:  # grows 8 -> 16 rows on the way
        eager.append(torch.from_numpy(r))
        bank.append(torch.from_numpy(r))
    peak = bank.array("peak")
    assert peak.shape == (16, 1) and not peak[11:].any()
    np.testing.assert_array_equal(peak[:11], eager.array("peak")[:11])
    for i in range(11):
        assert peak[i, 0] == rows[i].max()
    with pytest.raises(ConfigError, match="lazy"):
        make(("nope",))


def test_frames_default_to_minus_one_and_batches_take_one_frame_each():
    bank = _bank(capacity=8)
    assert list(bank.append(torch.zeros(2, 3, 5))) == [0, 1]
    assert list(bank.append(torch.ones(3, 3, 5), torch.tensor([7, 8, 9]))) == [2, 3, 4]
    assert bank.frames.tolist() == [-1, -1, 7, 8, 9]
    assert bank.capacity == 8


def test_buffers_are_not_part_of_the_state_dict():
    bank = _bank()
    bank.append(torch.ones(4, 3, 5))
    assert bank.state_dict() == {}
    names = {name for name, _ in bank.named_buffers()}
    assert names == {"_data", "_means", "_frames", "_cols", "_peak"}
    assert bank.bytes_per_template() == (15 + 1 + 5 + 1) * 8 + 8


def test_bad_templates_and_sizes_are_clear_errors():
    bank = _bank()
    with pytest.raises(InputError, match="templates"):
        bank.append(torch.zeros(2, 3, 4))
    with pytest.raises(InputError, match="NaN"):
        bank.append(torch.full((1, 3, 5), float("nan")))
    assert len(bank) == 0
    with pytest.raises(KeyError, match="nothing"):
        bank.summary("nothing")
    with pytest.raises(ConfigError, match="positive"):
        TemplateBank(0, 5)


def _rss_mib() -> float:
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmRSS line")


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc (Linux)")
def test_capacity_not_written_costs_no_memory_and_reads_as_zeros():
    """A CPU bank's rows not yet written are the system's zero pages: a capacity of
    2**16 rows (384 MiB of float64) adds a few MiB at most, and reads as zeros."""
    before = _rss_mib()
    bank = TemplateBank(16, 48, capacity=2**16, dtype=torch.float64)
    bank.append(torch.ones(3, 16, 48, dtype=torch.float64), 0)
    grown = _rss_mib() - before
    assert grown < 16.0, f"{grown:.1f} MiB for 3 rows of 6 KiB"
    data = bank.array("data")
    assert data.shape == (2**16, 16, 48)
    assert (data[:3] == 1).all() and not data[3:4096].any() and not data[-4096:].any()
