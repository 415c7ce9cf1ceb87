"""Shape checks for tensor and array arguments: one helper, one clear error line."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from torchratslam.errors import InputError

__all__ = ["check_shape"]


def _parse(spec: str | Sequence[int | str | None]) -> list[int | str | None]:
    items = spec.split() if isinstance(spec, str) else list(spec)
    out: list[int | str | None] = []
    for item in items:
        if isinstance(item, str):
            if item in ("_", "*"):
                out.append(None)
            elif item.isdigit():
                out.append(int(item))
            else:
                out.append(item)
        elif item is None or isinstance(item, int):
            out.append(item)
        else:
            raise TypeError(f"shape spec entries are int, str or None, got {item!r}")
    return out


def check_shape(
    x: Any, spec: str | Sequence[int | str | None], name: str = "input"
) -> dict[str, int]:
    """Check the shape of ``x`` against ``spec`` and return the sizes of its named axes.

    ``spec`` lists one entry per axis, either as a space-separated string
    (``"B TH Y X"``, ``"B 3"``, ``"_ Y X"``) or as a sequence (``(None, 3)``,
    ``("B", 64, 64)``):

    - an integer (or a string of digits) demands that size;
    - ``None``, ``"_"`` or ``"*"`` accepts any size;
    - a name (``"B"``, ``"TH"``) accepts any size but the same name must have the
      same size wherever it appears in ``spec``.

    Args:
        x: anything with a ``.shape`` (a tensor or an array).
        spec: the expected shape, as above.
        name: the argument's name, used in the error message.

    Returns:
        The size of each named axis, e.g. ``{"B": 2, "TH": 36, "Y": 21, "X": 21}``.

    Raises:
        InputError: ``x`` has no shape, the wrong number of axes, a wrong size, or two
            axes of one name with different sizes. The message is one line naming
            ``name``, the expected spec and the shape received.

    Shape:
        x: any shape that matches ``spec``.

    Example:
        >>> import torch
        >>> check_shape(torch.zeros(2, 36, 21, 21), "B TH Y X", name="activity")
        {'B': 2, 'TH': 36, 'Y': 21, 'X': 21}
        >>> check_shape(torch.zeros(5, 3), (None, 3), name="odometry")
        {}
    """
    axes = _parse(spec)
    names = ["_" if a is None else str(a) for a in axes]
    want = "(" + ", ".join(names) + ("," if len(names) == 1 else "") + ")"
    shape = getattr(x, "shape", None)
    if shape is None:
        raise InputError(f"{name}: expected an array of shape {want}, got {type(x).__name__}")
    got = tuple(int(s) for s in shape)
    if len(got) != len(axes):
        raise InputError(f"{name}: expected shape {want}, got {got} ({len(got)} axes)")
    sizes: dict[str, int] = {}
    for axis, (a, s) in enumerate(zip(axes, got, strict=True)):
        if a is None:
            continue
        if isinstance(a, int):
            if s != a:
                raise InputError(
                    f"{name}: expected shape {want}, got {got} (axis {axis} must be {a})"
                )
        elif a in sizes and sizes[a] != s:
            raise InputError(
                f"{name}: expected shape {want}, got {got} "
                f"(axes named {a} have sizes {sizes[a]} and {s})"
            )
        else:
            sizes[a] = s
    return sizes
