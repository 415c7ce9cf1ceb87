"""Read and write the save format of the multisession paper's own Python implementation,
exactly as that code lays it out (``shared/reference/reference-save-format.md``).

A save is a directory of plain-text files read line by line: every field is one line
(a blank line is a field too: an empty list), every list is one ``numpy.savetxt(...,
newline=" ")`` line (each value ``%.18e`` followed by a space; an empty list is an empty
line), every scalar is Python's ``str()`` of a float or an int. The files:

* ``localviewcells.txt``: TEMPLATE_SIZE, then per template ``id``, ``mean`` and the data
  as one list; ``-``, current_vt, prev_vt. Some published saves lack it: the map still
  loads (plots, ICP, ATE) with zero templates marked missing
  (:data:`MISSING_KEY`), and anything that needs templates (a merge, a run continuing
  the map) stops with an error naming the file (:func:`require_templates`).
* ``posecellvisual_templates.txt``: per template ``id, pc_x, pc_y, pc_th, decay`` and
  its experience indices (a list); ``-``, current_vt, prev_vt (prev may be blank).
* ``posecellexperiences.txt``: per experience ``x_pc, y_pc, th_pc, vt_id``; ``-``,
  current_exp, prev_exp.
* ``experiences.txt``: per experience ``id, x, y, th, vt_id``, the links_from and
  links_to lists (link indices), ``time_from_current_s, goal_to_current,
  current_to_goal``; ``-``, current_exp, prev_exp.
* ``links.txt``: per link ``d, heading, facing, exp_to_id, exp_from_id, delta_time_s``
  (TO before FROM), no ``-`` tail: their loader reads to the end of the file.
* ``goal_list.txt``: the goal experience ids as one list (an empty file when none);
  their loader opens it, so :func:`write_reference` always writes it.

Reading: the per-template experience lists and per-experience link lists are derived
from ``posecellexperiences.txt`` / ``links.txt`` (after a merge their code can leave
stale lists in the files); they are parsed only to check them, and a template's list
that disagrees is a warning. :func:`compare_texts` names every field whose value differs
between two saves (``torchratslam convert`` reports with it). Ids that equal the
record position are checked. Values with no place in :class:`MapState` are kept so a
write gives them back: the goal list (``extra["ref.goal_list"]``), non-default
``time_from_current_s`` / ``goal_to_current`` / ``current_to_goal``
(``extra["exp:ref_..."]``), the pose cells' own experience template ids when they differ
(``extra["exp:pc_template"]``) and the secondary files' ``-`` tails when they differ
from the main ones (``scalars["ref.tail...."]``). The format has no activity, creation
frames or times: the activity is left empty, frames -1, times 0.

Every malformed file gives one :class:`MapFormatError` line naming the file and line.

Example:
    >>> from torchratslam.maps.reference_format import read_reference  # doctest: +SKIP
    >>> state = read_reference("their_map/", load_config("irat"))  # doctest: +SKIP
    >>> state.summary()  # doctest: +SKIP
    {'templates': 74, 'experiences': 81, 'links': 82}
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from ratslam_graph.atomic import write_directory_atomically
from torchratslam.errors import InputError, MapFormatError
from torchratslam.maps.state import MISSING_KEY, MapState

__all__ = [
    "DERIVED",
    "FILES",
    "GOAL_FILE",
    "LAYOUT",
    "MISSING_KEY",
    "REQUIRED_FILES",
    "FieldChange",
    "compare_texts",
    "is_reference_map",
    "read_reference",
    "read_texts",
    "reference_texts",
    "write_reference",
]

log = logging.getLogger(__name__)

LVC, PVT, PCE, EXP, LINKS = (
    "localviewcells.txt",
    "posecellvisual_templates.txt",
    "posecellexperiences.txt",
    "experiences.txt",
    "links.txt",
)
GOAL_FILE = "goal_list.txt"
FILES = (LVC, PVT, PCE, EXP, LINKS)
"""The five data files (``goal_list.txt`` besides them)."""
REQUIRED_FILES = (PVT, PCE, EXP, LINKS)
"""The files a save must hold to be read (``localviewcells.txt`` may be missing)."""
GOALS = "ref.goal_list"
EXP_EXTRAS = (  # (extra key, default) of experiences.txt's last three fields
    ("exp:ref_time_from_current", 0.0),
    ("exp:ref_goal_to_current", -1.0),
    ("exp:ref_current_to_goal", -1.0),
)
TAIL = "ref.tail."
_MAX_ID = 2**53  # larger ids cannot be told apart as floats


def is_reference_map(directory: str | Path) -> bool:
    """True when ``directory`` holds the reference format's ``experiences.txt`` and
    ``posecellexperiences.txt`` (``localviewcells.txt`` may be missing)."""
    d = Path(directory)
    return (d / EXP).is_file() and (d / PCE).is_file()


# ------------------------------------------------------------------------ reading
class _File:
    """The lines of one file as their loader's ``readline()`` sees them."""

    def __init__(self, path: Path, shown: Path | None = None) -> None:
        self.path = path if shown is None else shown  # the name in messages
        try:
            text = path.read_bytes().decode("utf-8")
        except FileNotFoundError:
            raise MapFormatError(
                f"{self.path} is missing: a reference-format map needs {', '.join(REQUIRED_FILES)}"
            ) from None
        except UnicodeDecodeError as exc:
            raise MapFormatError(
                f"{self.path}, byte {exc.start}: not UTF-8 text; the file is corrupt"
            ) from None
        except OSError as exc:
            raise MapFormatError(f"{self.path} cannot be read: {exc.strerror or exc}") from None
        self.lines = text.split("\n")
        if self.lines[-1] == "":  # the newline ending the last line; '' is the end
            self.lines.pop()

    def error(self, line: int, what: str) -> MapFormatError:
        """``line`` is 0-based."""
        return MapFormatError(
            f"{self.path}, line {line + 1}: {what}; the file is corrupt or truncated "
            "(re-export it from the reference implementation)"
        )

    def records(self, start: int, width: int, *, tail: bool, what: str) -> tuple[int, int]:
        """Count the records of ``width`` lines from ``start``: up to the ``-`` line at a
        record start (``tail``) or to the end of the file. Returns ``(n, end)`` with
        ``end`` the index of the ``-`` line (or the file's length)."""
        heads = [s.strip() == "-" for s in self.lines[start::width]]
        n_full = (len(self.lines) - start) // width
        if tail:
            if True not in heads:
                raise self.error(
                    len(self.lines), f"unexpected end of file (no '-' line closing the {what})"
                )
            n = heads.index(True)
        else:
            n = n_full
            if True in heads[:n_full]:
                k = heads.index(True)
                raise self.error(start + k * width, f"unexpected '-' in the {what}")
            if start + n * width != len(self.lines):
                raise self.error(
                    len(self.lines),
                    f"unexpected end of file inside {what[:-1]} {n} (a record has {width} lines)",
                )
        return n, start + n * width

    def column(self, start: int, width: int, n: int, col: int) -> list[str]:
        return self.lines[start + col : start + n * width : width]

    def floats(self, start: int, width: int, n: int, col: int, what: str) -> np.ndarray:
        """Column ``col`` of ``n`` records as finite float64."""
        values = self.column(start, width, n, col)
        try:
            out = np.array(values, dtype=np.float64)
        except ValueError:
            out = None
        if out is not None and bool(np.isfinite(out).all()):
            return out
        for k, s in enumerate(values):  # error path only: find the first bad line
            try:
                v = float(s)
            except ValueError:
                raise self.error(
                    start + k * width + col, f"expected a number ({what}), found {s[:40]!r}"
                ) from None
            if not math.isfinite(v):
                raise self.error(start + k * width + col, f"{what} is {s.strip()[:40]}")
        raise AssertionError("unreachable")  # pragma: no cover

    def ids(
        self, start: int, width: int, n: int, col: int, what: str, lo: int, hi: int
    ) -> np.ndarray:
        """Column ``col`` as integer ids in ``lo..hi-1``."""
        v = self.floats(start, width, n, col, what)
        bad = (v != np.floor(v)) | (v < lo) | (v >= hi)
        if bad.any():
            k = int(np.argmax(bad))
            raise self.error(
                start + k * width + col,
                f"{what} {self.lines[start + k * width + col].strip()[:40]!r} is not an id "
                f"in {lo}..{hi - 1}",
            )
        return v.astype(np.int64)

    def lists(
        self, start: int, width: int, n: int, col: int, what: str, size: int | None = None
    ) -> list[np.ndarray]:
        """Column ``col`` as savetxt lists (one line each; empty line: empty list).
        With ``size`` every list must hold exactly that many values."""
        lines = self.column(start, width, n, col)
        parts = [s.split() for s in lines]
        counts = np.array([len(p) for p in parts], dtype=np.int64)
        if size is not None and (counts != size).any():
            k = int(np.argmax(counts != size))
            raise self.error(
                start + k * width + col, f"{what} {k} has {counts[k]} values, expected {size}"
            )
        flat = [t for p in parts for t in p]
        try:
            values = np.array(flat, dtype=np.float64)
        except ValueError:
            values = None
        if values is None or not bool(np.isfinite(values).all()):
            for k, p in enumerate(parts):  # error path only
                for t in p:
                    try:
                        ok = math.isfinite(float(t))
                    except ValueError:
                        ok = False
                    if not ok:
                        raise self.error(
                            start + k * width + col,
                            f"{what} holds {t[:40]!r}, not a finite number",
                        )
        assert values is not None
        return np.split(values, np.cumsum(counts)[:-1]) if n else []

    def tail(self, at: int, *, blank_prev: bool = False) -> tuple[int, int, str, str]:
        """The two id lines after the ``-`` at ``at``: ``(current, prev)`` and their
        stripped texts. A blank line reads as -1 (where their code can leave one)."""
        out: list[int] = []
        texts: list[str] = []
        for i in (at + 1, at + 2):
            if i >= len(self.lines):
                raise self.error(i, "unexpected end of file (the list's current/previous id)")
            s = self.lines[i].strip()
            texts.append(s)
            if s == "" and blank_prev:
                out.append(-1)
                continue
            try:
                v = float(s)
            except ValueError:
                raise self.error(i, f"expected an id, found {s[:40]!r}") from None
            if not math.isfinite(v) or v != math.floor(v) or abs(v) >= _MAX_ID:
                raise self.error(i, f"expected an id, found {s[:40]!r}")
            out.append(int(v))
        for i in range(at + 3, len(self.lines)):
            if self.lines[i].strip():
                raise self.error(i, "unexpected text after the list's closing ids")
        return out[0], out[1], texts[0], texts[1]


def _flat_config(config: Any) -> dict[str, Any]:
    if config is None:
        return {}
    return config.to_flat() if hasattr(config, "to_flat") else dict(config)


def _current(f: _File, at: int, value: int, n: int, what: str) -> int:
    """A current/previous id in range, -1, or 0 in an empty list (their empty save)."""
    if -1 <= value < n:
        return value
    if n == 0 and value == 0:
        return -1
    raise f.error(at, f"{what} {value} is not an id in 0..{n - 1}")


def read_reference(
    directory: str | Path, config: Any = None, *, shown_as: str | Path | None = None
) -> MapState:
    """Read a map saved by the multisession paper's implementation.

    Args:
        directory: the save directory.
        config: a ``RatSLAMConfig`` or flat dict giving ``template_x_size`` /
            ``template_y_size`` (the files hold only their product; without a config a
            template of size S is read as one row ``(1, S)``) and the pose-cell sizes.
        shown_as: the directory's name in messages and warnings (default: ``directory``;
            a command reading back what it wrote to a temporary place names the user's
            target instead).

    Returns:
        A validated :class:`MapState` (``scalars["imported_from"] == "reference"``).

    Raises:
        MapFormatError: a required file is missing, or a file is malformed (one line
            naming the file and line), or the template size disagrees with ``config``.
    """
    d = Path(directory)
    shown = d if shown_as is None else Path(shown_as)
    file = partial(_open, d, shown)
    flat = _flat_config(config)
    # ---------------------------------------------------------------- templates
    pvt = file(PVT)
    n, pvt_end = pvt.records(0, 6, tail=True, what="templates")
    ids = pvt.ids(0, 6, n, 0, "template id", 0, max(n, 1))
    if (ids != np.arange(n)).any():
        k = int(np.argmax(ids != np.arange(n)))
        raise pvt.error(6 * k, f"template id {ids[k]} out of order (expected {k})")
    t_pc = np.stack([pvt.floats(0, 6, n, c, "pose-cell coordinate") for c in (1, 2, 3)], 1)
    t_decay = pvt.floats(0, 6, n, 4, "decay")
    pvt_lists = pvt.lists(0, 6, n, 5, "experience list")
    pvt_tail = pvt.tail(pvt_end, blank_prev=True)
    scalars: dict[str, Any] = {"imported_from": "reference"}
    have_lvc = (d / LVC).is_file()
    if have_lvc:
        lv = file(LVC)
        if not lv.lines:
            raise lv.error(0, "unexpected end of file (TEMPLATE_SIZE)")
        size_v = lv.floats(0, 1, 1, 0, "TEMPLATE_SIZE")[0]
        if size_v != math.floor(size_v) or not 1 <= size_v < _MAX_ID:
            raise lv.error(0, f"TEMPLATE_SIZE {lv.lines[0].strip()[:40]!r} is not a size")
        size = int(size_v)
        n_lv, lv_end = lv.records(1, 3, tail=True, what="templates")
        if n_lv != n:
            raise lv.error(lv_end, f"{n_lv} templates end here but {PVT} holds {n}")
        ids = lv.ids(1, 3, n, 0, "template id", 0, max(n, 1))
        if (ids != np.arange(n)).any():
            k = int(np.argmax(ids != np.arange(n)))
            raise lv.error(1 + 3 * k, f"template id {ids[k]} out of order (expected {k})")
        means = lv.floats(1, 3, n, 1, "template mean")
        data = lv.lists(1, 3, n, 2, "template", size=size)
        cur_vt, prev_vt, *_ = lv.tail(lv_end, blank_prev=True)
        cur_vt = _current(lv, lv_end + 1, cur_vt, n, "current_vt")
        prev_vt = _current(lv, lv_end + 2, prev_vt, n, "prev_vt")
        if flat:
            ty = int(flat.get("template_y_size", 1))
            tx = int(flat.get("template_x_size", size))
        else:
            ty, tx = 1, size
        if ty * tx != size:
            raise MapFormatError(
                f"{shown / LVC}, line 1: templates have {size} values but the config's "
                f"template_x_size x template_y_size = {tx} x {ty} = {tx * ty}; use the "
                "config the map was made with"
            )
        templates = np.array(data, dtype=np.float64).reshape(n, ty, tx)
    else:
        log.warning("%s: %s is missing; the map loads without templates", shown, LVC)
        cur_vt = _current(pvt, pvt_end + 1, pvt_tail[0], n, "current_vt")
        prev_vt = _current(pvt, pvt_end + 2, pvt_tail[1], n, "prev_vt")
        ty = int(flat.get("template_y_size", 1)) if flat else 1
        tx = int(flat.get("template_x_size", 0)) if flat else 0
        templates = np.zeros((n, ty, tx))
        means = np.zeros(n)
        scalars[MISSING_KEY] = LVC
    # ---------------------------------------------------------------- experiences
    pce = file(PCE)
    m, pce_end = pce.records(0, 4, tail=True, what="experiences")
    e_pc = np.stack([pce.floats(0, 4, m, c, "pose-cell coordinate") for c in (0, 1, 2)], 1)
    pc_vt = pce.ids(0, 4, m, 3, "template id", -1, n)
    pce_tail = pce.tail(pce_end, blank_prev=True)
    ex = file(EXP)
    m_ex, ex_end = ex.records(0, 10, tail=True, what="experiences")
    if m_ex != m:
        raise ex.error(ex_end, f"{m_ex} experiences end here but {PCE} holds {m}")
    eid = ex.ids(0, 10, m, 0, "experience id", 0, max(m, 1))
    if (eid != np.arange(m)).any():
        k = int(np.argmax(eid != np.arange(m)))
        raise ex.error(10 * k, f"experience id {eid[k]} out of order (expected {k})")
    poses = np.stack([ex.floats(0, 10, m, c, "pose") for c in (1, 2, 3)], 1).reshape(m, 3)
    exp_vt = ex.ids(0, 10, m, 4, "template id", -1, n)
    ex.lists(0, 10, m, 5, "links_from list")
    ex.lists(0, 10, m, 6, "links_to list")
    extra: dict[str, np.ndarray] = {}
    for c, (key, default) in zip((7, 8, 9), EXP_EXTRAS):
        v = ex.floats(0, 10, m, c, key.split("_", 1)[1])
        if (v != default).any():
            extra[key] = v
    cur_exp, prev_exp, *_ = ex.tail(ex_end)
    cur_exp = _current(ex, ex_end + 1, cur_exp, m, "current_exp")
    prev_exp = _current(ex, ex_end + 2, prev_exp, m, "prev_exp")
    if (pc_vt != exp_vt).any():
        extra["exp:pc_template"] = pc_vt
    _warn_stale_lists(pvt, pvt_lists, exp_vt)
    # secondary tails that differ from what a write would give: kept verbatim
    for name, (_, _, t_cur, t_prev), (want_c, want_p), count in (
        (PVT, pvt_tail, (cur_vt, prev_vt), n),
        (PCE, pce_tail, (cur_exp, prev_exp), m),
    ):
        written = (_id_text(want_c, count), _id_text(want_p, count))
        if (t_cur, t_prev) != written:
            scalars[f"{TAIL}{name}"] = f"{t_cur}\n{t_prev}"
    # ---------------------------------------------------------------- links
    lk = file(LINKS)
    n_l, _ = lk.records(0, 6, tail=False, what="links")
    geo = [lk.floats(0, 6, n_l, c, w) for c, w in ((0, "d"), (1, "heading"), (2, "facing"))]
    to = lk.ids(0, 6, n_l, 3, "exp_to_id", 0, m)
    frm = lk.ids(0, 6, n_l, 4, "exp_from_id", 0, m)
    dt = lk.floats(0, 6, n_l, 5, "delta_time_s")
    self_link = to == frm
    if self_link.any():
        k = int(np.argmax(self_link))
        raise lk.error(6 * k + 3, f"link {k} joins experience {to[k]} to itself")
    # ---------------------------------------------------------------- goals
    if (d / GOAL_FILE).is_file():
        gf = file(GOAL_FILE)
        if len(gf.lines) > 1 and any(s.strip() for s in gf.lines[1:]):
            raise gf.error(1, "expected the goal ids on one line")
        if gf.lines:
            goals = gf.lists(0, 1, 1, 0, "goal list")[0]
            if ((goals != np.floor(goals)) | (goals < 0) | (goals >= m)).any():
                raise gf.error(0, f"a goal is not an experience id in 0..{m - 1}")
            extra[GOALS] = goals.astype(np.int64)
    config_out = (
        dict(flat) if flat else ({"template_x_size": tx, "template_y_size": ty} if have_lvc else {})
    )
    state = MapState(
        config=config_out,
        templates=templates,
        template_mean=np.asarray(means, np.float64),
        template_frame=np.full(n, -1, np.int64),
        template_pc=t_pc.reshape(n, 3),
        template_decay=t_decay,
        exp_pose=poses,
        exp_pc=e_pc.reshape(m, 3),
        exp_template=exp_vt,
        exp_frame=np.full(m, -1, np.int64),
        exp_t=np.zeros(m),
        link_from=frm,
        link_to=to,
        link_d=geo[0],
        link_heading=geo[1],
        link_facing=geo[2],
        link_dt=dt,
        activity=np.zeros((0, 0, 0)),
        current_vt=cur_vt,
        prev_vt=prev_vt,
        current_exp=cur_exp,
        prev_exp=prev_exp,
        extra=extra,
        scalars=scalars,
    )
    return state.validate(source=str(shown))


def _open(directory: Path, shown: Path, name: str) -> _File:
    return _File(directory / name, shown / name)


def _warn_stale_lists(f: _File, lists: list[np.ndarray], exp_template: np.ndarray) -> None:
    """Warn when templates' experience lists disagree with the experiences' template ids
    (their merge leaves the partial map's lists behind); the map uses the ids."""
    derived = _group_indices(exp_template, len(lists))
    stale = [i for i, (a, b) in enumerate(zip(lists, derived)) if not np.array_equal(a, b)]
    if stale:
        i = stale[0]
        log.warning(
            "%s: %d template experience list(s) disagree with the experiences' template "
            "ids (template %d lists %s, experiences.txt gives %s); the map uses the "
            "experiences' ids, and writing it gives their lists",
            f.path,
            len(stale),
            i,
            _ids_text(lists[i]),
            _ids_text(derived[i]),
        )


def _ids_text(values: np.ndarray, limit: int = 6) -> str:
    """``[37]``, ``[1, 2]``, ``[]``: a list of ids for a message."""
    v = [int(x) if float(x).is_integer() else float(x) for x in np.asarray(values)[:limit]]
    more = f", ... ({np.asarray(values).size} values)" if np.asarray(values).size > limit else ""
    return "[" + ", ".join(str(x) for x in v) + more + "]"


# ------------------------------------------------------------------------ comparing
LAYOUT: dict[str, tuple[int, int, str, tuple[str, ...]]] = {
    LVC: (1, 3, "template", ("id", "mean", "data")),
    PVT: (0, 6, "template", ("id", "pc_x", "pc_y", "pc_th", "decay", "experience list")),
    PCE: (0, 4, "experience", ("x_pc", "y_pc", "th_pc", "vt_id")),
    EXP: (
        0,
        10,
        "experience",
        (
            "id",
            "x",
            "y",
            "th",
            "vt_id",
            "links_from list",
            "links_to list",
            "time_from_current_s",
            "goal_to_current",
            "current_to_goal",
        ),
    ),
    LINKS: (0, 6, "link", ("d", "heading", "facing", "exp_to_id", "exp_from_id", "delta_time")),
    GOAL_FILE: (0, 1, "goals", ("goal list",)),
}
"""Per file: the first record's line, lines per record, what a record is, its fields."""
DERIVED = {(PVT, "experience list"), (EXP, "links_from list"), (EXP, "links_to list")}
"""The fields a write derives from the others (a stale list in a save is not kept)."""


@dataclass(frozen=True)
class FieldChange:
    """One field of a reference-format file whose value differs between two versions.

    Attributes:
        file: the file name (``posecellvisual_templates.txt``).
        field: the field (``experience list``, ``current id``, ``lines``).
        text: the change in words (``posecellvisual_templates.txt, template 425:
            experience list [37] -> [508]``).
    """

    file: str
    field: str
    text: str

    @property
    def derived(self) -> bool:
        """True for a list a write derives from the other fields (see :data:`DERIVED`)."""
        return (self.file, self.field) in DERIVED


def _lines(text: str) -> list[str]:
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()
    return lines


def _same(a: str, b: str) -> bool:
    """Two lines hold the same values (``10`` and ``10.0`` are the same id)."""
    ta, tb = a.split(), b.split()
    if len(ta) != len(tb):
        return False
    try:
        return all(float(x) == float(y) for x, y in zip(ta, tb))
    except ValueError:
        return ta == tb


def _shown(line: str, listed: bool) -> str:
    tokens = line.split()
    if not listed and len(tokens) == 1:
        return tokens[0]
    try:
        return _ids_text(np.array([float(t) for t in tokens]))
    except ValueError:
        return repr(line.strip()[:40])


def _where(name: str, lines: list[str], i: int) -> tuple[str, str]:
    """``(record, field)`` of line ``i`` (0-based) of file ``name``."""
    start, width, kind, fields = LAYOUT[name]
    if i < start:
        return "header", "TEMPLATE_SIZE"
    heads = [s.strip() == "-" for s in lines[start::width]]
    n = heads.index(True) if name not in (LINKS, GOAL_FILE) and True in heads else len(heads)
    if i < start + n * width:
        rec, col = divmod(i - start, width)
        return (f"{kind} {rec}" if name != GOAL_FILE else kind), fields[col]
    tail = ("the '-' line", "current id", "previous id")
    k = i - start - n * width
    return "tail", tail[k] if k < len(tail) else f"line {i + 1}"


def compare_texts(before: dict[str, str], after: dict[str, str]) -> list[FieldChange]:
    """Every field whose value differs between two versions of a reference-format save.

    Args:
        before, after: file name -> text (a file absent from one side is compared as
            missing; an absent ``goal_list.txt`` equals an empty one).

    Returns:
        One :class:`FieldChange` per changed field, in file and line order.
    """
    out: list[FieldChange] = []
    for name in (*FILES, GOAL_FILE):
        a, b = before.get(name), after.get(name)
        if name == GOAL_FILE:
            a, b = a or "", b or ""
        if a is None or b is None:
            if (a is None) != (b is None):
                state = "missing" if b is None else "added"
                out.append(FieldChange(name, "file", f"{name}: the file is {state}"))
            continue
        la, lb = _lines(a), _lines(b)
        if len(la) != len(lb):
            out.append(FieldChange(name, "lines", f"{name}: {len(la)} lines -> {len(lb)} lines"))
        for i in range(min(len(la), len(lb))):
            if _same(la[i], lb[i]):
                continue
            where, field = _where(name, la, i)
            listed = field.endswith("list") or field == "data"
            out.append(
                FieldChange(
                    name,
                    field,
                    f"{name}, {where}: {field} {_shown(la[i], listed)} -> {_shown(lb[i], listed)}",
                )
            )
    return out


def read_texts(directory: str | Path) -> dict[str, str]:
    """The reference-format files present in ``directory``, name -> text."""
    d = Path(directory)
    out = {}
    for name in (*FILES, GOAL_FILE):
        if (d / name).is_file():
            out[name] = (d / name).read_bytes().decode("utf-8", errors="replace")
    return out


# ------------------------------------------------------------------------ writing
def _id_text(value: int, count: int) -> str:
    """An id as their code writes it: an empty list's ids are 0."""
    return "0" if count == 0 and value == -1 else str(int(value))


def _num(v: float) -> str:
    """A float as Python's ``str()`` writes it."""
    return repr(float(v))


def _num_or_int(v: float) -> str:
    """Integral values as their code's ints (``0``, ``-1``), others as floats."""
    f = float(v)
    return str(int(f)) if f.is_integer() and abs(f) < _MAX_ID else repr(f)


def _savetxt(values: np.ndarray) -> str:
    """One ``numpy.savetxt(fh, values, newline=" ")`` line (without the ``\\n``)."""
    v = np.asarray(values, np.float64).reshape(-1)
    return ("%.18e " * v.size) % tuple(v.tolist())


def _group_indices(keys: np.ndarray, n: int) -> list[np.ndarray]:
    """For each key value 0..n-1, the indices holding it, in increasing order (one sort)."""
    keys = np.asarray(keys, np.int64)
    order = np.argsort(keys, kind="stable")
    bounds = np.searchsorted(keys[order], np.arange(n + 1))
    return [order[bounds[i] : bounds[i + 1]] for i in range(n)]


def _write_bytes(fh: BinaryIO, data: bytes) -> None:
    fh.write(data)


def reference_texts(state: MapState) -> dict[str, str]:
    """The files of ``state`` in the reference format, name -> text (see the module
    docstring). ``localviewcells.txt`` is left out when the map's templates are missing.
    """
    n, m, el = state.n_templates, state.n_experiences, state.n_links
    vt = (_id_text(state.current_vt, n), _id_text(state.prev_vt, n))
    ids_exp = (_id_text(state.current_exp, m), _id_text(state.prev_exp, m))

    def tail(name: str, default: tuple[str, str]) -> list[str]:
        text = state.scalars.get(f"{TAIL}{name}")
        return ["-", *(text.split("\n", 1) if isinstance(text, str) else default)]

    files: dict[str, list[str]] = {}
    if not state.scalars.get(MISSING_KEY):
        size = int(np.prod(state.templates.shape[1:]))
        flat_t = np.asarray(state.templates, np.float64).reshape(n, size)
        lv = [str(size)]
        for i in range(n):
            lv += [str(i), _num(state.template_mean[i]), _savetxt(flat_t[i])]
        files[LVC] = [*lv, "-", *vt]
    exps_of_template = _group_indices(state.exp_template, n)
    pt: list[str] = []
    for i in range(n):
        x, y, th = state.template_pc[i]
        pt += [str(i), _num(x), _num(y), _num(th), _num(state.template_decay[i])]
        pt.append(_savetxt(exps_of_template[i]))
    files[PVT] = pt + tail(PVT, vt)
    pc_vt = np.asarray(state.extra.get("exp:pc_template", state.exp_template), np.int64)
    pe: list[str] = []
    for j in range(m):
        x, y, th = state.exp_pc[j]
        pe += [_num(x), _num(y), _num(th), str(int(pc_vt[j]))]
    files[PCE] = pe + tail(PCE, ids_exp)
    links_from = _group_indices(state.link_from, m)
    links_to = _group_indices(state.link_to, m)
    last = [
        np.asarray(state.extra.get(key, np.full(m, default)), np.float64)
        for key, default in EXP_EXTRAS
    ]
    ex: list[str] = []
    for j in range(m):
        x, y, th = state.exp_pose[j]
        ex += [str(j), _num(x), _num(y), _num(th), str(int(state.exp_template[j]))]
        ex += [_savetxt(links_from[j]), _savetxt(links_to[j])]
        ex += [_num_or_int(c[j]) for c in last]
    files[EXP] = [*ex, "-", *ids_exp]
    lk: list[str] = []
    for k in range(el):
        lk += [
            _num(state.link_d[k]),
            _num(state.link_heading[k]),
            _num(state.link_facing[k]),
            str(int(state.link_to[k])),
            str(int(state.link_from[k])),
            _num(state.link_dt[k]),
        ]
    texts = {name: "".join(s + "\n" for s in lines) for name, lines in files.items()}
    texts[LINKS] = "".join(s + "\n" for s in lk)
    goals = state.extra.get(GOALS)
    texts[GOAL_FILE] = "" if goals is None else _savetxt(goals)
    return texts


def write_reference(state: MapState, directory: str | Path) -> Path:
    """Write ``state`` in the reference format, atomically, so that the authors' loader
    reads it back (and :func:`read_reference` gives back every value it holds).

    Scalars are written as Python's ``str()`` (full precision), lists as ``savetxt``
    lines. The activity, creation frames and times, the config and the module extras
    have no place in that format and are not written (``torchratslam convert`` reports
    them).

    Raises:
        InputError: ``directory`` exists and holds files other than a reference map.
        MapFormatError: ``state`` does not validate.
    """
    state = state.validate(source="map to export")
    target = Path(directory)
    if target.exists():
        if not target.is_dir():
            raise InputError(f"{target} exists and is not a directory; choose another path")
        other = {p.name for p in target.iterdir()} - {*FILES, GOAL_FILE}
        if other:
            raise InputError(
                f"{target} holds files other than a reference map "
                f"({', '.join(sorted(other)[:3])}); choose an empty directory"
            )
    texts = reference_texts(state)
    writers = {name: partial(_write_bytes, data=text.encode()) for name, text in texts.items()}
    return write_directory_atomically(target, writers)
