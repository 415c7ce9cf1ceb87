"""The pose-cell math as plain functions on ``(B, TH, Y, X)`` activity tensors.

``x`` is the last axis, ``y`` the middle one, theta the second. Nothing here holds
state: the engines (:mod:`~torchratslam.pose_cells.torch_engine`,
:mod:`~torchratslam.pose_cells.crop_engine`, :mod:`~torchratslam.pose_cells.numpy_engine`)
cache what these functions take (matrices, gather indices) and call them.

Kept from OpenRatSLAM: the Gaussian weights use the configured "variance" as the
standard deviation (``exp(-d^2 / (2 var^2))``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from torchratslam.errors import ConfigError, InputError
from torchratslam.shapes import check_shape

__all__ = [
    "QUADRANTS",
    "arc",
    "arc_with",
    "as_batch",
    "circular_conv3d",
    "edge_loss_",
    "gather_shift_index",
    "gaussian_kernel_1d",
    "global_inhibition",
    "inject_",
    "minimal_arcs",
    "normalise",
    "peak_index",
    "ring_matrix",
    "roll0",
    "rotate_theta",
    "separable_conv3d",
    "separable_dynamics_",
    "shift_axis_",
    "shift_one_",
]

DIED_OUT = (
    "pose-cell activity died out (every cell <= pc_global_inhib); lower "
    "pc_global_inhib or reset()/inject() the network"
)


def gaussian_kernel_1d(dim: int, var: float) -> np.ndarray:
    """OpenRatSLAM's 1D Gaussian weights, normalised to sum 1.

    The weight at offset ``d = i - dim // 2`` (``i = 0 .. dim-1``) is proportional to
    ``exp(-d**2 / (2 var**2))``: OpenRatSLAM's ``norm2d`` uses the configured
    "variance" as the standard deviation, and so does this project. The 3D kernel is
    the outer product of three of these.

    Args:
        dim: kernel side (``pc_w_e_dim`` or ``pc_w_i_dim``).
        var: the configured variance (``pc_w_e_var`` or ``pc_w_i_var``).

    Returns:
        ``(dim,)`` float64 weights.
    """
    d = np.arange(dim, dtype=np.float64) - dim // 2
    w = np.exp(-(d * d) / (2.0 * var * var))
    return w / w.sum()


def ring_matrix(kernel: np.ndarray, n: int, circular: bool) -> np.ndarray:
    """``(n, n)`` matrix M with ``(M @ v)[p] = sum_d kernel[d + h] v[p - d]``.

    ``circular``: indices wrap (a circulant matrix; kernel taps that alias the same
    offset, when the kernel is longer than the ring, add up). Otherwise ``v`` is zero
    outside ``0..n-1`` (a banded Toeplitz matrix).

    Shape:
        kernel: ``(K,)``; returns ``(n, n)`` float64.
    """
    h = len(kernel) // 2
    m = np.zeros((n, n), dtype=np.float64)
    p = np.arange(n)
    for i, w in enumerate(kernel):  # kernel taps only (at most pc_w_e_dim), not cells
        q = p - (i - h)
        if circular:
            np.add.at(m, (p, q % n), w)
        else:
            ok = (q >= 0) & (q < n)
            m[p[ok], q[ok]] += w
    return m


def minimal_arcs(occ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the shortest circular arc holding every True entry.

    Args:
        occ: boolean occupancy of one ring axis.

    Returns:
        ``start (B,)`` and ``length (B,)``; length 0 for an empty row.

    Shape:
        occ: ``(B, n)``.
    """
    b, n = occ.shape
    occ2 = np.concatenate([occ, occ], axis=1)
    idx = np.where(occ2, np.arange(2 * n), -1)
    prev = np.maximum.accumulate(idx, axis=1)  # last True at or before j
    j = np.arange(n, 2 * n)
    gap = np.where(occ, j - prev[:, n - 1 : 2 * n - 1] - 1, -1)  # empty run before each True
    best = gap.argmax(axis=1)
    big = gap[np.arange(b), best]
    length = np.where(occ.any(axis=1), n - big, 0)
    return best.astype(np.int64), length.astype(np.int64)


def arc(mask: Any) -> tuple[int, int]:
    """``(start, length)`` of the shortest circular arc holding every True of ``mask``.

    Shape:
        mask: ``(n,)`` boolean.
    """
    s, ln = minimal_arcs(mask[None])
    return int(s[0]), int(ln[0])


def arc_with(span: tuple[int, int], p: int, n: int) -> tuple[int, int]:
    """A short circular arc (on a ring of ``n``) holding ``span`` and the cell ``p``."""
    s, ln = span
    if ln == 0:
        return p, 1
    if (p - s) % n < ln:
        return span
    fwd = (p - s) % n + 1  # extend the end up to p
    back = (s + ln - 1 - p) % n + 1  # extend the start down to p
    return (s, fwd) if fwd <= back else (p, back)


def as_batch(value: Any, batch: int, name: str, dtype: Any = np.float64) -> np.ndarray:
    """A scalar or ``(batch,)`` value as a ``(batch,)`` numpy array.

    Raises:
        InputError: a value that is neither a scalar nor of shape ``(batch,)``.
    """
    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().numpy()
    arr = np.asarray(value, dtype=dtype)
    if arr.ndim == 0:
        return np.full(batch, arr, dtype=dtype)
    check_shape(arr, (batch,), name=name)
    return arr


def _quadrant_table() -> np.ndarray:
    """How OpenRatSLAM's path integration maps onto the global ``(y, x)`` axes.

    ``path_integration`` rotates layer ``k`` by ``q = floor(dir 2 / pi)`` quarter turns
    (``rot90_square``: ``new[r][c] = old[n - 1 - c][r]``, numpy's ``rot90(., -1)``), moves
    it by ``a = v sin(dir90)`` cells along its columns (``+i``) and ``b = v cos(dir90)``
    along its rows (``+j``) and turns it back. Row ``q`` of the table, found by applying
    those rotations to index grids, holds (all in the global frame, ``(dy, dx)`` or a
    cell as ``(y_is_last, x_is_last)``): the direction of ``+i``, of ``+j``, the cell
    whose ``+i`` move crosses the wrap and is dropped (rotated ``(0, n - 1)``), the cell
    whose ``+j`` move is dropped (rotated ``(n - 1, 0)``), and the corner both would
    have reached (rotated ``(0, 0)``).

    Returns:
        ``(4, 5, 2)`` int64.
    """
    n = 5
    gy, gx = np.mgrid[0:n, 0:n]
    out = np.zeros((4, 5, 2), dtype=np.int64)
    c = n // 2
    for q in range(4):  # four quarter turns, not cells
        ry, rx = np.rot90(gy, -q), np.rot90(gx, -q)
        out[q, 0] = (ry[c, c + 1] - ry[c, c], rx[c, c + 1] - rx[c, c])
        out[q, 1] = (ry[c + 1, c] - ry[c, c], rx[c + 1, c] - rx[c, c])
        for row, (r, cc) in zip((2, 3, 4), ((0, n - 1), (n - 1, 0), (0, 0)), strict=True):
            out[q, row] = (ry[r, cc] == n - 1, rx[r, cc] == n - 1)
    return out


QUADRANTS = _quadrant_table()
"""``(4, 5, 2)``: OpenRatSLAM's path integration per quarter turn (see ``_quadrant_table``)."""


def roll0(a: np.ndarray, s: int) -> np.ndarray:
    """``np.roll(a, s, axis=0)`` by two slices (less overhead)."""
    n = a.shape[0]
    s %= n
    if s == 0:
        return a
    return np.concatenate((a[n - s :], a[: n - s]), axis=0)


# ------------------------------------------------------------------ excitation
def separable_conv3d(
    a: torch.Tensor, mt: torch.Tensor, my: torch.Tensor, mx: torch.Tensor
) -> torch.Tensor:
    """Separable 3D convolution: three matrix products with ring matrices
    (:func:`ring_matrix`) along theta, y and x.

    Shape:
        a: ``(B, T, Y, X)``; mt: ``(T, T)``; my: ``(Y, Y)``; mx: ``(X, X)``;
        returns ``(B, T, Y, X)``.
    """
    b, t, y, x = a.shape
    out = a @ mx.T
    out = my @ out
    out = (mt @ out.reshape(b, t, y * x)).reshape(b, t, y, x)
    return out


def circular_conv3d(a: torch.Tensor, kernel: np.ndarray) -> torch.Tensor:
    """Circular 3D convolution of ``a`` with the outer product of the 1D ``kernel``
    (OpenRatSLAM's scatter of every cell's weights), in ``a``'s dtype and device.

    Raises:
        ConfigError: kernel halves longer than a network axis.

    Shape:
        a: ``(B, TH, Y, X)``; kernel: ``(K,)``; returns ``(B, TH, Y, X)``.
    """
    dim = len(kernel)
    k1 = torch.as_tensor(kernel, dtype=a.dtype, device=a.device)
    k3 = (k1[:, None, None] * k1[None, :, None] * k1[None, None, :])[None, None]
    h = dim // 2
    lo, hi = h, dim - 1 - h  # taps before/after the centre
    if max(lo, hi) > min(a.shape[1:]):
        dims = (a.shape[3], a.shape[2], a.shape[1])
        raise ConfigError(
            f"method 'conv3d' needs kernel halves <= the network dims {dims}; "
            "use method 'separable' or 'crop'"
        )
    # F.conv3d is a correlation: flip the kernel so this is OpenRatSLAM's scatter.
    k3 = torch.flip(k3, dims=(2, 3, 4))
    pad = (hi, lo, hi, lo, hi, lo)  # flipped kernel: the larger side pads first
    v = a.unsqueeze(1)
    v = torch.nn.functional.pad(v, pad, mode="circular")
    return torch.nn.functional.conv3d(v, k3).squeeze(1)


def global_inhibition(a: torch.Tensor, inhib: float) -> torch.Tensor:
    """``max(a - inhib, 0)``: global inhibition and the clamp at zero.

    Shape:
        a: ``(B, TH, Y, X)``; returns the same shape.
    """
    return torch.clamp_min(a - inhib, 0.0)


def normalise(a: torch.Tensor) -> torch.Tensor:
    """Each network divided by its sum.

    Raises:
        InputError: a network whose activity is all zero (it died out).

    Shape:
        a: ``(B, TH, Y, X)``; returns the same shape.
    """
    total = a.sum(dim=(1, 2, 3), keepdim=True)
    if not bool((total > 0).all()):
        raise InputError(DIED_OUT)
    return a / total


def separable_dynamics_(
    a: torch.Tensor,
    mats_e: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    mats_i: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    inhib: float,
    work: list[torch.Tensor],
) -> list[torch.Tensor]:
    """Excite, inhibit, global inhibition, clamp and normalise ``a`` with separable
    kernels, written into the scratch tensors ``work`` (no allocation).

    Args:
        a: the activity (not modified).
        mats_e, mats_i: ``(mt, my, mx)`` ring matrices of the excitatory and inhibitory
            kernels (circulant on a wrapping axis, Toeplitz on a cropped one).
        inhib: ``pc_global_inhib``.
        work: four scratch tensors of ``a``'s shape.

    Returns:
        ``work`` reordered so that the first entry holds the result.

    Raises:
        InputError: a network whose activity died out.

    Shape:
        a: ``(B, T, Y, X)``; work: four ``(B, T, Y, X)``.
    """
    b, t, y, x = a.shape
    out, s1, s2, e = work
    for (mt, my, mx), src, dst in ((mats_e, a, e), (mats_i, e, out)):
        torch.matmul(src, mx.T, out=s1)
        torch.matmul(my, s1, out=s2)
        torch.matmul(mt, s2.view(b, t, y * x), out=dst.view(b, t, y * x))
    torch.sub(e, out, out=out)
    out.sub_(inhib).clamp_min_(0.0)
    total = out.sum(dim=(1, 2, 3), keepdim=True)
    if not bool((total > 0).all()):
        raise InputError(DIED_OUT)
    out.div_(total)
    return [out, s1, s2, e]


# ------------------------------------------------------------ path integration
def gather_shift_index(
    shape: tuple[int, ...], axis: int, ints: np.ndarray, device: Any
) -> torch.Tensor:
    """Gather index moving each layer of a ``shape`` tensor by ``ints`` cells along
    ``axis``, wrapping on the tensor's own length.

    Shape:
        ints: ``(B,)`` or ``(B, T)``; returns ``shape`` (an expanded view).
    """
    n = shape[axis]
    lay = [1, 1, 1, 1]
    lay[axis] = n
    lead = ints.shape + (1,) * (4 - ints.ndim)
    idx = np.remainder(np.arange(n).reshape(lay) - ints.reshape(lead), n)
    return torch.from_numpy(idx).to(device).expand(shape)


def _cached_index(
    cache: dict[tuple, torch.Tensor] | None,
    key: tuple,
    shape: tuple[int, ...],
    axis: int,
    ints: np.ndarray,
    device: Any,
) -> torch.Tensor:
    index = cache.get(key) if cache is not None else None
    if index is None:
        index = gather_shift_index(shape, axis, ints, device)
        if cache is not None:
            if len(cache) > 256:
                cache.clear()
            cache[key] = index
    return index


def shift_axis_(
    pool: list[torch.Tensor],
    shift: np.ndarray,
    axis: int,
    cache: dict[tuple, torch.Tensor] | None = None,
) -> None:
    """Move the content of ``pool[0]`` by ``shift`` cells along ``axis``, wrapping on
    the tensor's own length: integer part by a gather, fraction by linear weights.
    The result becomes ``pool[0]`` (the other entries are scratch of the same shape).

    Args:
        pool: the activity and at least one scratch tensor.
        shift: cells per network (theta) or per theta layer (x, y).
        axis: 1 (theta), 2 (y) or 3 (x).
        cache: gather indices by integer shift, reused between calls (optional).

    Shape:
        pool: ``(B, T, Y, X)`` each; shift: ``(B,)`` or ``(B, T)``.
    """
    a, g0 = pool[0], pool[1]
    fl = np.floor(shift)
    frac = shift - fl
    lead = shift.shape + (1,) * (4 - shift.ndim)
    ints = fl.astype(np.int64)
    dev = a.device
    if (ints == ints.flat[0]).all():  # one integer shift for everything: a roll
        g0.copy_(torch.roll(a, int(ints.flat[0]), dims=axis))
    else:  # the integer parts repeat from step to step: cache their gather index
        key = (axis, tuple(a.shape), ints.tobytes(), ints.shape, dev)
        index = _cached_index(cache, key, tuple(a.shape), axis, ints, dev)
        torch.gather(a, axis, index, out=g0)
    if frac.any():
        w = torch.from_numpy(frac.reshape(lead)).to(device=dev, dtype=a.dtype)
        torch.lerp(g0, torch.roll(g0, 1, dims=axis), w, out=g0)
    pool[0], pool[1] = g0, a


def shift_one_(
    pool: list[torch.Tensor],
    step: np.ndarray,
    w: np.ndarray,
    axis: int,
    cache: dict[tuple, torch.Tensor] | None = None,
) -> None:
    """``pool[0] + w (pool[0] moved by step - pool[0])`` per layer (``step`` is +-1):
    OpenRatSLAM's one-cell weights, extrapolating when ``w > 1``. The result becomes
    ``pool[0]``.

    Shape:
        pool: ``(B, T, Y, X)`` each; step, w: ``(B, T)``.
    """
    a, g0 = pool[0], pool[1]
    dev = a.device
    key = ("one", axis, tuple(a.shape), step.tobytes(), dev)
    index = _cached_index(cache, key, tuple(a.shape), axis, step, dev)
    torch.gather(a, axis, index, out=g0)
    wt = torch.from_numpy(w.reshape((*w.shape, 1, 1))).to(device=dev, dtype=a.dtype)
    torch.lerp(a, g0, wt, out=g0)
    pool[0], pool[1] = g0, a


def edge_loss_(
    out: torch.Tensor,
    src: torch.Tensor,
    plan: dict[str, np.ndarray],
    starts: tuple[np.ndarray, np.ndarray] | None,
    n: tuple[int, int],
) -> None:
    """Take from ``out`` what OpenRatSLAM drops at the x/y wrap: the moves of two
    corner cells of each layer (of ``src``, before the move) across the edge.

    Args:
        out: the moved activity (modified in place).
        src: the activity before the move.
        plan: a translation plan with ``lost``, ``src`` and ``corner``
            (:meth:`~torchratslam.pose_cells.motion.MotionTables.translation_plan`).
        starts: the crop's global y and x starts per network; None for the whole ring.
        n: the y and x ring sizes.

    Shape:
        out, src: ``(B, T, LY, LX)``.
    """
    b, t, ly, lx = out.shape
    pos = []
    for start, length, ring in zip(
        starts if starts is not None else (np.zeros(b, np.int64), np.zeros(b, np.int64)),
        (ly, lx),
        n,
        strict=True,
    ):
        ends = np.array([0, ring - 1])
        p = np.remainder(ends[None, :] - start[:, None], ring)  # (B, 2)
        pos.append(np.where(p < length, p, -1))
    if (pos[0] < 0).all() or (pos[1] < 0).all():
        return
    bb = np.repeat(np.arange(b), t).reshape(b, t)
    kk = np.tile(np.arange(t), b).reshape(b, t)
    take = torch.zeros(b, t, dtype=out.dtype, device=out.device)
    for m in range(2):
        yy = np.take_along_axis(pos[0], plan["src"][:, :, m, 0], axis=1)
        xx = np.take_along_axis(pos[1], plan["src"][:, :, m, 1], axis=1)
        ok = (yy >= 0) & (xx >= 0)
        if ok.any():
            ix = tuple(torch.from_numpy(v[ok]).to(out.device) for v in (bb, kk, yy, xx))
            w = torch.from_numpy(plan["lost"][:, :, m][ok]).to(out.device, out.dtype)
            take[torch.from_numpy(bb[ok]), torch.from_numpy(kk[ok])] += w * src[ix]
    cy = np.take_along_axis(pos[0], plan["corner"][:, :, 0], axis=1)
    cx = np.take_along_axis(pos[1], plan["corner"][:, :, 1], axis=1)
    ok = (cy >= 0) & (cx >= 0)
    if ok.any():
        ix = tuple(torch.from_numpy(v[ok]).to(out.device) for v in (bb, kk, cy, cx))
        out.index_put_(ix, -take[ix[0], ix[1]], accumulate=True)


def rotate_theta(a: np.ndarray, rot: float) -> np.ndarray:
    """OpenRatSLAM's theta shift of ``a`` by ``rot`` cells (fraction linear; a whole
    number of cells moves with weight 1, as its ``while (weight > 1)`` loop).

    Shape:
        a: ``(T, Y, X)``; returns the same shape.
    """
    r = abs(rot)
    fl = math.floor(r)
    w = r - fl
    if w == 0.0:
        w = 1.0  # its "while (weight > 1) weight -= 1" stops at 1
    sign = -1 if rot < 0 else 1
    s1, s2 = sign * fl, sign * math.ceil(r)
    out = roll0(a, s1) * (1.0 - w)
    out += roll0(a, s2) * w
    return out


# ------------------------------------------------------------- energy, packet
def inject_(
    activity: torch.Tensor, th: np.ndarray, y: np.ndarray, x: np.ndarray, energy: np.ndarray
) -> None:
    """Add ``energy[b]`` at cell ``(th[b], y[b], x[b])`` of network ``b`` (in place;
    the indices must already be wrapped into the network).

    Shape:
        activity: ``(B, TH, Y, X)``; th, y, x, energy: ``(B,)``.
    """
    dev = activity.device
    b = activity.shape[0]
    with torch.no_grad():
        index = tuple(torch.from_numpy(v).to(dev) for v in (np.arange(b), th, y, x))
        values = torch.from_numpy(energy).to(device=dev, dtype=activity.dtype)
        activity.index_put_(index, values, accumulate=True)


def peak_index(activity: torch.Tensor) -> torch.Tensor | np.ndarray:
    """Flat index of the most active cell of each network (first on ties).

    Shape:
        activity: ``(B, TH, Y, X)``; returns ``(B,)``.
    """
    act = activity.detach().reshape(activity.shape[0], -1)
    if act.device.type == "cpu":  # numpy's argmax has less per-call overhead
        return act.numpy().argmax(axis=1)
    return torch.argmax(act, dim=1)
