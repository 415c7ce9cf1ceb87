"""Import and export of the save format of the multisession paper's own Python
implementation (``shared/reference/reference-save-format.md``).

That format is a directory of five plain-text files, one value per line:
``localviewcells.txt`` (templates), ``posecellvisual_templates.txt`` (template ->
pose-cell association and decay), ``posecellexperiences.txt`` (experience -> pose
cells and template), ``experiences.txt`` (experience poses and link lists) and
``links.txt`` (d, heading, facing, TO, FROM, time). Ids are 0-based and equal the
record position; they may be written as ``16.0``. Each list ends with ``-`` and two
lines with the current and previous id.

The format has no pose-cell activity, no creation frames and no config beyond the
template size; :func:`read_reference` leaves the activity empty (the pipeline then
places a packet at the current template's cell) and the frames -1.

Example:
    >>> from torchratslam.maps import read_reference, write_reference  # doctest: +SKIP
    >>> state = read_reference("their_map/", load_config("virtual_tour"))  # doctest: +SKIP
"""

from __future__ import annotations

import ast
from functools import partial
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from torchratslam.graph.atomic import write_directory_atomically
from torchratslam.graph.errors import InputError, MapFormatError
from torchratslam.maps.state import MapState

__all__ = ["FILES", "is_reference_map", "read_reference", "write_reference"]

FILES = (
    "localviewcells.txt",
    "posecellvisual_templates.txt",
    "posecellexperiences.txt",
    "experiences.txt",
    "links.txt",
)


def is_reference_map(directory: str | Path) -> bool:
    """True when ``directory`` holds the reference format's ``localviewcells.txt``."""
    return (Path(directory) / FILES[0]).is_file()


class _Lines:
    """A cursor over the non-empty lines of one file, with located errors."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            text = path.read_text()
        except FileNotFoundError:
            raise MapFormatError(
                f"{path} is missing: a reference-format map needs all of {', '.join(FILES)}"
            ) from None
        except UnicodeDecodeError:
            raise MapFormatError(f"{path} is not a text file") from None
        self.lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        self.i = 0

    def error(self, what: str) -> MapFormatError:
        return MapFormatError(
            f"{self.path}, line {self.i + 1}: {what}; the file is corrupt or "
            "truncated (re-export it from the reference implementation)"
        )

    def at_end(self) -> bool:
        return self.i >= len(self.lines) or self.lines[self.i] == "-"

    def next(self) -> str:
        if self.i >= len(self.lines):
            raise self.error("unexpected end of file")
        line = self.lines[self.i]
        self.i += 1
        return line

    def number(self) -> float:
        line = self.next()
        try:
            return float(line)
        except ValueError:
            self.i -= 1
            raise self.error(f"expected a number, found {line[:40]!r}") from None

    def integer(self) -> int:
        v = self.number()
        if not float(v).is_integer():
            self.i -= 1
            raise self.error(f"expected an integer id, found {v}")
        return int(v)

    def int_list(self) -> list[int]:
        line = self.next()
        try:
            values = ast.literal_eval(line)
        except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
            self.i -= 1
            raise self.error(f"expected a list like [0, 3], found {line[:40]!r}") from None
        if not isinstance(values, (list, tuple)):
            self.i -= 1
            raise self.error(f"expected a list, found {line[:40]!r}")
        try:
            return [int(float(v)) for v in values]
        except (TypeError, ValueError, OverflowError):
            self.i -= 1
            raise self.error(f"expected a list of ids, found {line[:40]!r}") from None

    def floats(self) -> np.ndarray:
        line = self.next()
        try:
            return np.array(line.split(), dtype=np.float64)
        except ValueError:
            self.i -= 1
            raise self.error("template data holds a value that is not a number") from None

    def tail(self, required: bool = True) -> tuple[int, int]:
        """The ``-`` line and the current/previous ids."""
        if self.i >= len(self.lines):
            if required:
                raise self.error("unexpected end of file (no '-' line closing the list)")
            return -1, -1
        if self.next() != "-":
            self.i -= 1
            raise self.error("expected '-' closing the list")
        if self.i >= len(self.lines):
            return -1, -1
        cur = self.integer()
        prev = self.integer() if self.i < len(self.lines) else -1
        return cur, prev


def _flat_config(config: Any) -> dict[str, Any]:
    if config is None:
        return {}
    return config.to_flat() if hasattr(config, "to_flat") else dict(config)


def read_reference(directory: str | Path, config: Any = None) -> MapState:
    """Read a reference-format map directory into a :class:`MapState`.

    Args:
        directory: the directory holding the five text files.
        config: a ``RatSLAMConfig`` or flat dict giving ``template_x_size`` /
            ``template_y_size`` (needed to shape the templates; without it a template of
            size S is read as one row ``(1, S)``) and the pose-cell dimensions.

    Raises:
        MapFormatError: a missing, truncated or malformed file, inconsistent ids, or a
            template size that does not match ``config``.
    """
    d = Path(directory)
    flat = _flat_config(config)
    # --- templates
    lv = _Lines(d / FILES[0])
    size = lv.integer()
    ty, tx = int(flat.get("template_y_size", 1)), int(flat.get("template_x_size", size))
    if config is None:
        ty, tx = 1, size
    if ty * tx != size:
        raise MapFormatError(
            f"{d / FILES[0]}: templates have {size} values but the config's "
            f"template_x_size x template_y_size = {tx} x {ty} = {tx * ty}; use "
            "the config the map was made with"
        )
    tpl, means = [], []
    while not lv.at_end():
        tid = lv.integer()
        if tid != len(tpl):
            raise lv.error(f"template id {tid} out of order (expected {len(tpl)})")
        means.append(lv.number())
        data = lv.floats()
        if data.size != size:
            raise lv.error(f"template {tid} has {data.size} values, expected {size}")
        tpl.append(data.reshape(ty, tx))
    cur_vt, prev_vt = lv.tail()
    n = len(tpl)
    # --- template -> pose cells
    pt = _Lines(d / FILES[1])
    t_pc, t_decay = [], []
    while not pt.at_end():
        tid = pt.integer()
        if tid != len(t_pc):
            raise pt.error(f"template id {tid} out of order (expected {len(t_pc)})")
        t_pc.append([pt.number(), pt.number(), pt.number()])
        t_decay.append(pt.number())
        pt.int_list()  # experience ids of the template: derived from the experiences
    pt.tail()
    if len(t_pc) != n:
        raise MapFormatError(f"{d / FILES[1]} lists {len(t_pc)} templates but {FILES[0]} holds {n}")
    # --- experience -> pose cells
    pe = _Lines(d / FILES[2])
    e_pc, e_vt = [], []
    while not pe.at_end():
        e_pc.append([pe.number(), pe.number(), pe.number()])
        e_vt.append(pe.integer())
    cur_exp, prev_exp = pe.tail()
    # --- experiences
    ex = _Lines(d / FILES[3])
    poses, links_from_lists = [], []
    while not ex.at_end():
        eid = ex.integer()
        if eid != len(poses):
            raise ex.error(f"experience id {eid} out of order (expected {len(poses)})")
        poses.append([ex.number(), ex.number(), ex.number()])
        vt = ex.integer()
        if len(e_vt) > eid and vt != e_vt[eid]:
            raise ex.error(f"experience {eid} has template {vt} but {FILES[2]} says {e_vt[eid]}")
        links_from_lists.append(ex.int_list())
        ex.int_list()
        ex.number()
        ex.number()
        ex.number()
    c2, p2 = ex.tail()
    cur_exp = c2 if c2 >= 0 else cur_exp
    prev_exp = p2 if p2 >= 0 else prev_exp
    m = len(poses)
    if len(e_pc) != m:
        raise MapFormatError(
            f"{d / FILES[2]} lists {len(e_pc)} experiences but {FILES[3]} holds {m}"
        )
    # --- links
    lk = _Lines(d / FILES[4])
    rows = []
    while not lk.at_end():
        dd, hh, ff = lk.number(), lk.number(), lk.number()
        to, frm = lk.integer(), lk.integer()
        rows.append((frm, to, dd, hh, ff, lk.number()))
    lk.tail(required=False)
    links = np.array(rows, dtype=np.float64).reshape(-1, 6)
    state = MapState(
        config=dict(flat) if flat else {"template_x_size": tx, "template_y_size": ty},
        templates=np.array(tpl, dtype=np.float64).reshape(n, ty, tx),
        template_mean=np.array(means, dtype=np.float64),
        template_frame=np.full(n, -1, np.int64),
        template_pc=np.array(t_pc, dtype=np.float64).reshape(n, 3),
        template_decay=np.array(t_decay, dtype=np.float64),
        exp_pose=np.array(poses, dtype=np.float64).reshape(m, 3),
        exp_pc=np.array(e_pc, dtype=np.float64).reshape(m, 3),
        exp_template=np.array(e_vt, dtype=np.int64),
        exp_frame=np.full(m, -1, np.int64),
        exp_t=np.zeros(m),
        link_from=links[:, 0].astype(np.int64),
        link_to=links[:, 1].astype(np.int64),
        link_d=links[:, 2].copy(),
        link_heading=links[:, 3].copy(),
        link_facing=links[:, 4].copy(),
        link_dt=links[:, 5].copy(),
        activity=np.zeros((0, 0, 0)),
        current_vt=cur_vt,
        prev_vt=prev_vt,
        current_exp=cur_exp,
        prev_exp=prev_exp,
        scalars={"imported_from": "reference"},
    )
    return state.validate(source=str(d))


def _num(v: float) -> str:
    return repr(float(v))


def _ids(values: np.ndarray) -> str:
    return "[" + ", ".join(str(int(v)) for v in values) + "]"


def _group_indices(keys: np.ndarray, n: int) -> list[np.ndarray]:
    """For each key value 0..n-1, the indices holding it, in increasing order (one sort)."""
    order = np.argsort(keys, kind="stable")
    bounds = np.searchsorted(keys[order], np.arange(n + 1))
    return [order[bounds[i] : bounds[i + 1]] for i in range(n)]


def _write_bytes(fh: BinaryIO, data: bytes) -> None:
    fh.write(data)


def write_reference(state: MapState, directory: str | Path) -> Path:
    """Write ``state`` in the reference format (five text files), atomically.

    Values are written with full precision (``repr``), so :func:`read_reference` gives
    back the same numbers. Activity, creation frames and times, and module extras have
    no place in that format and are not written.

    Raises:
        InputError: ``directory`` exists and holds files other than a reference map.
    """
    state = state.validate(source="map to export")
    target = Path(directory)
    if target.exists():
        other = {p.name for p in target.iterdir()} - set(FILES)
        if other:
            raise InputError(
                f"{target} holds files other than a reference map "
                f"({', '.join(sorted(other)[:3])}); choose an empty directory"
            )
    target.parent.mkdir(parents=True, exist_ok=True)
    n, m = state.n_templates, state.n_experiences
    tail_vt = ["-", str(state.current_vt), str(state.prev_vt)]
    tail_exp = ["-", str(state.current_exp), str(state.prev_exp)]
    size = int(np.prod(state.templates.shape[1:]))
    lv = [str(size)]
    flat_t = state.templates.reshape(n, size)
    for i in range(n):
        lv += [str(i), _num(state.template_mean[i]), " ".join(map(_num, flat_t[i]))]
    exps_of_template = _group_indices(state.exp_template, n)
    pt = []
    for i in range(n):
        x, y, th = state.template_pc[i]
        pt += [
            str(i),
            _num(x),
            _num(y),
            _num(th),
            _num(state.template_decay[i]),
            _ids(exps_of_template[i]),
        ]
    pe = []
    for j in range(m):
        x, y, th = state.exp_pc[j]
        pe += [_num(x), _num(y), _num(th), str(int(state.exp_template[j]))]
    links_from = _group_indices(state.link_from, m)
    links_to = _group_indices(state.link_to, m)
    ex = []
    for j in range(m):
        x, y, th = state.exp_pose[j]
        ex += [
            str(j),
            _num(x),
            _num(y),
            _num(th),
            str(int(state.exp_template[j])),
            _ids(links_from[j]),
            _ids(links_to[j]),
            "0.0",
            "0.0",
            "0.0",
        ]
    lk = []
    for k in range(state.n_links):
        lk += [
            _num(state.link_d[k]),
            _num(state.link_heading[k]),
            _num(state.link_facing[k]),
            str(int(state.link_to[k])),
            str(int(state.link_from[k])),
            _num(state.link_dt[k]),
        ]
    contents = {
        FILES[0]: lv + tail_vt,
        FILES[1]: pt + tail_vt,
        FILES[2]: pe + tail_exp,
        FILES[3]: ex + tail_exp,
        FILES[4]: lk + tail_exp,
    }
    texts = {name: ("\n".join(lines) + "\n").encode() for name, lines in contents.items()}
    writers = {name: partial(_write_bytes, data=data) for name, data in texts.items()}
    return write_directory_atomically(target, writers)
