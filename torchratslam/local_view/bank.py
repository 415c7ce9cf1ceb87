"""The template bank: every template in one preallocated tensor, with its metadata."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping

import numpy as np
import torch
from torch import nn

from torchratslam.errors import ConfigError
from torchratslam.local_view.preprocessing import check_finite
from torchratslam.shapes import check_shape

__all__ = ["TemplateBank"]


class TemplateBank(nn.Module):
    """All templates in one preallocated tensor that grows by doubling.

    Row ``i`` holds template id ``i``. Per template the bank also keeps its mean, its
    creation frame and any small summaries a matcher asks for (computed once, when the
    template is added; see :meth:`TemplateMatcher.make_bank
    <torchratslam.local_view.matcher.TemplateMatcher.make_bank>`).

    The rows, means, frames and summaries are non-persistent buffers (allocated
    ``capacity`` rows at a time): the module that owns the bank stores the templates in
    its own state, so the bank adds nothing to ``state_dict()``.

    Args:
        y_size: template height (rows).
        x_size: template width (columns).
        summaries: function computing the summaries of a batch ``(K, Y, X)`` of templates
            (tensors, or numpy arrays for a bank on the CPU).
        summary_shapes: name -> per-template shape of each summary.
        lazy: summaries computed when first read (then kept up to date as templates
            are appended, on each read) rather than on append: no memory until a
            search asks for them.
        capacity: initial number of rows.
        dtype: template dtype.
        device: template device.
    """

    # Buffers allocated by _alloc: the rows, their means, frames and the summaries.
    _data: torch.Tensor
    _means: torch.Tensor
    _frames: torch.Tensor

    def __init__(
        self,
        y_size: int,
        x_size: int,
        *,
        summaries: Callable[[torch.Tensor], Mapping[str, torch.Tensor | np.ndarray]] | None = None,
        summary_shapes: Mapping[str, tuple[int, ...]] | None = None,
        capacity: int = 64,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
        lazy: Collection[str] = (),
    ) -> None:
        if y_size <= 0 or x_size <= 0:
            raise ConfigError(f"template size must be positive, got {x_size}x{y_size}")
        super().__init__()
        self.y_size, self.x_size = int(y_size), int(x_size)
        self._summarise = summaries
        self._summary_shapes = dict(summary_shapes or {})
        unknown = set(lazy) - set(self._summary_shapes)
        if unknown:
            raise ConfigError(f"lazy summaries {sorted(unknown)} are not among the summaries")
        self._lazy_n = dict.fromkeys(lazy, -1)  # rows computed; -1: not allocated
        self.dtype, self.device = dtype, torch.device(device) if device is not None else None
        self._n = 0
        self._means_n = 0  # templates whose mean is computed (on demand: see means)
        self._capacity = 0
        self._arrays: dict[str, tuple[torch.Tensor, np.ndarray]] = {}
        self._columns: dict[str, tuple[np.ndarray, np.ndarray, int]] = {}
        self._alloc(max(1, int(capacity)))

    def _shapes(self) -> dict[str, tuple[int, ...]]:
        """The buffers allocated: rows, means and the summaries (lazy ones once read)."""
        lazy = self._lazy_n
        return {
            "data": (self.y_size, self.x_size),
            "means": (),
            **{k: v for k, v in self._summary_shapes.items() if lazy.get(k, 0) >= 0},
        }

    def _zeros(self, capacity: int, shape: tuple[int, ...]) -> torch.Tensor:
        """A zero buffer of ``capacity`` rows. On the CPU its memory comes from the
        operating system's zeroed pages (numpy's ``calloc``), so the rows not yet written
        cost no memory (``torch.zeros`` writes every row)."""
        probe = torch.empty(0, dtype=self.dtype, device=self.device)  # the default device too
        if probe.device.type == "cpu":
            try:
                np_dtype = probe.numpy().dtype
            except (TypeError, RuntimeError):  # a dtype numpy does not have
                pass
            else:
                return torch.from_numpy(np.zeros((capacity, *shape), dtype=np_dtype))
        return torch.zeros(capacity, *shape, dtype=self.dtype, device=self.device)

    def _alloc(self, capacity: int) -> None:
        for name, shape in self._shapes().items():
            tensor = self._zeros(capacity, shape)
            old = self._buffers.get("_" + name)
            if old is not None:
                tensor[: self._n] = old[: self._n]
            self._arrays.pop(name, None)  # the old buffer is freed once replaced
            for key in [k for k in self._columns if k.split(":")[0] == name]:
                del self._columns[key]  # its copies are made again from the new rows
            self.register_buffer("_" + name, tensor, persistent=False)
            del old
        frames = torch.full((capacity,), -1, dtype=torch.int64, device=self.device)
        old = self._buffers.get("_frames")
        if old is not None:
            frames[: self._n] = old[: self._n]
        self.register_buffer("_frames", frames, persistent=False)
        self._capacity = capacity

    @property
    def capacity(self) -> int:
        """Rows allocated (grows by doubling)."""
        return self._capacity

    @property
    def summary_shapes(self) -> dict[str, tuple[int, ...]]:
        """Name -> per-template shape of each summary."""
        return dict(self._summary_shapes)

    def __len__(self) -> int:
        return self._n

    @property
    def data(self) -> torch.Tensor:
        """The templates, shape ``(N, Y, X)`` (a view; do not modify)."""
        return self._data[: self._n]

    @property
    def means(self) -> torch.Tensor:
        """Mean of each template, shape ``(N,)``.

        Computed when read, template by template (``mean`` of each appended template,
        as at its append): the search never reads them, and a torch call per new
        template costs more than its search.
        """
        self._fill_means()
        return self._means[: self._n]

    def _fill_means(self) -> None:
        data, means = self._buffer("data"), self._buffer("means")
        for i in range(self._means_n, self._n):
            means[i : i + 1] = data[i : i + 1].mean(dim=(1, 2))
        self._means_n = self._n

    @property
    def frames(self) -> torch.Tensor:
        """Frame at which each template was created (-1 if unknown), shape ``(N,)``."""
        return self._frames[: self._n]

    @property
    def ids(self) -> torch.Tensor:
        """Template ids, shape ``(N,)`` (the row numbers)."""
        return torch.arange(self._n, device=self.device)

    def summary(self, name: str) -> torch.Tensor:
        """The summary ``name`` of every template (a view; do not modify).

        Shape:
            ``(N, *summary_shapes[name])``.
        """
        if name not in self._summary_shapes:
            raise KeyError(f"the bank keeps no summary {name!r} ({sorted(self._summary_shapes)})")
        self._fill_lazy(name)
        return self._buffer(name)[: self._n]

    def _fill_lazy(self, name: str) -> None:
        """A lazy summary's rows up to ``len(self)``: allocated on first use, then the
        new rows' summaries computed."""
        done = self._lazy_n.get(name)
        if done is None or done == self._n:
            return
        if done < 0:
            zeros = self._zeros(self._capacity, self._summary_shapes[name])
            self.register_buffer("_" + name, zeros, persistent=False)
            done = 0
        assert self._summarise is not None  # a lazy summary is one of the summaries
        self._lazy_n[name] = self._n
        if done < self._n:
            value = self._summarise(self._buffer("data")[done : self._n])[name]
            if isinstance(value, np.ndarray):
                self.array(name)[done : self._n] = value
            else:
                self._buffer(name)[done : self._n] = value

    @property
    def on_cpu(self) -> bool:
        """Whether the rows live in CPU memory (then :meth:`array` works)."""
        return self._buffer("data").device.type == "cpu"

    def array(self, name: str) -> np.ndarray:
        """A numpy view of the rows (``"data"``), the means or a summary over the whole
        capacity (rows from ``len(self)`` on are zeros); CPU only. Made once per buffer
        (again after the bank grows): what a compiled search reads every frame.

        Shape:
            ``(capacity, *shape)``.
        """
        if name == "means":
            self._fill_means()
        self._fill_lazy(name)
        buf = self._buffer(name)
        cached = self._arrays.get(name)
        if cached is None or cached[0] is not buf:
            cached = (buf, buf.numpy())
            self._arrays[name] = cached
        return cached[1]

    def column_major(self, name: str, dtype: np.dtype | type | None = None) -> np.ndarray:
        """A column-major copy of :meth:`array` ``(name)`` over the whole capacity (rows
        from ``len(self)`` on are zeros), kept up to date as templates are appended (only
        the new rows are copied): what a search that reads one entry of every template
        at a time streams through. CPU only.

        Args:
            name: ``"data"``, ``"means"`` or a summary.
            dtype: the copy's dtype (default: the bank's); a value the dtype cannot
                hold (beyond float32's range, say) is NaN in the copy, never infinite.

        Shape:
            ``(*shape, capacity)``.
        """
        rows = self.array(name)
        dt = rows.dtype if dtype is None else np.dtype(dtype)
        key = f"{name}:{dt.str}"
        cached = self._columns.get(key)
        if cached is None or cached[0] is not rows:
            cached = (rows, np.zeros((*rows.shape[1:], rows.shape[0]), dt), 0)
        src, out, filled = cached
        if filled < self._n:
            new = src[filled : self._n]
            if dt != rows.dtype:
                with np.errstate(over="ignore"):
                    cast = new.astype(dt)
                if not np.isfinite(cast).all():  # past dt's range (the rows are finite)
                    cast[~np.isfinite(cast)] = np.nan
                new = cast
            out[..., filled : self._n] = new.T if new.ndim == 2 else np.moveaxis(new, 0, -1)
            cached = (src, out, self._n)
        self._columns[key] = cached
        return out

    def _buffer(self, name: str) -> torch.Tensor:
        buf = self._buffers["_" + name]
        assert buf is not None  # allocated by _alloc for every name of _shapes()
        return buf

    def bytes_per_template(self) -> int:
        """Memory per stored template: data, summaries (lazy ones too) and metadata."""
        shapes = {"data": (self.y_size, self.x_size), "means": (), **self._summary_shapes}
        floats = sum(math.prod(shape) for shape in shapes.values())
        return floats * (torch.finfo(self.dtype).bits // 8) + 8

    def append(
        self,
        templates: torch.Tensor,
        frames: torch.Tensor | int | None = None,
        *,
        checked: bool = False,
    ) -> range:
        """Append templates; returns their ids.

        Args:
            templates: the templates.
            frames: creation frame of each (or one for all); -1 if None.
            checked: the caller vouches that ``templates`` are finite, of the bank's
                shape, dtype and device (a local view's own templates): the checks are
                skipped.

        Shape:
            templates: ``(K, Y, X)`` or ``(Y, X)``.
        """
        t = (
            templates
            if checked
            else torch.as_tensor(templates, dtype=self.dtype, device=self.device)
        )
        if t.ndim == 2:
            t = t[None]
        if not checked:
            check_shape(t, ("K", self.y_size, self.x_size), "templates")
            check_finite(t, "templates")
        k = t.shape[0]
        if self._n + k > self._capacity:
            cap = self._capacity
            while cap < self._n + k:
                cap *= 2
            self._alloc(cap)
        sl = slice(self._n, self._n + k)
        on_cpu = t.device.type == "cpu"
        if on_cpu:  # numpy views of the buffers: a torch call costs more than the copy
            self.array("data")[sl] = t.detach().numpy()
        else:
            self._buffer("data")[sl] = t
        if self._summarise is not None:
            for name, value in self._summarise(t).items():
                if name in self._lazy_n:  # computed when read
                    continue
                if isinstance(value, np.ndarray):
                    self.array(name)[sl] = value
                else:
                    self._buffer(name)[sl] = value
        if frames is None:
            frames = -1
        if isinstance(frames, int) and on_cpu:
            self.array("frames")[sl] = frames
        else:
            if not isinstance(frames, int):
                frames = torch.as_tensor(frames, dtype=torch.int64, device=self.device)
            self._buffer("frames")[sl] = frames
        self._n += k
        return range(self._n - k, self._n)
