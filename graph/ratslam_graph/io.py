"""Read and write 2D pose graphs: g2o (``VERTEX_SE2``/``EDGE_SE2``) and TORO
(``VERTEX2``/``EDGE2``), plus the city10000 multi-hypothesis variant.

Formats (one record per line, angles in radians):

- g2o: ``VERTEX_SE2 id x y th`` and
  ``EDGE_SE2 id1 id2 dx dy dth I11 I12 I13 I22 I23 I33`` (upper triangle, row by row).
- TORO: ``VERTEX2 id x y th`` and ``EDGE2 id1 id2 dx dy dth I11 I12 I22 I33 I13 I23``
  (TORO's own order of the information entries). ``EQUIV a b`` lines (w100, w10000) are
  ignored, as gtsam does.
- city10000 (``T1_city10000_04.txt``): ``EDGE2 s 1 t 0 n x y th [x y th ...]``: ``n``
  hypotheses of the pose of ``t`` in ``s``'s frame and no noise model. As gtsam's own
  ``ISAM2_City10000`` example does, the FIRST hypothesis is used and every edge gets the
  diagonal model with sigmas ``(1/30, 1/30, 1/100)`` (stored as ``information``). The
  file has no vertices: the initial estimate is the composed odometry chain.

In every case ``(dx, dy, dth)`` is the pose of ``id2`` in ``id1``'s frame (gtsam's
``BetweenFactorPose2(id1, id2, ...)``). Files are written atomically with ``repr``
floats, so a write/read round trip is exact.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ratslam_graph.atomic import atomic_write_text
from ratslam_graph.errors import InputError, MapFormatError
from ratslam_graph.posegraph import PoseGraph, compose_odometry

CITY_SIGMAS = (1.0 / 30.0, 1.0 / 30.0, 1.0 / 100.0)
"""Noise model gtsam's ISAM2_City10000 example uses for city10000 (x, y, th sigmas)."""

_VERTEX_TAGS = {"VERTEX_SE2": "g2o", "VERTEX2": "toro"}
_EDGE_TAGS = {"EDGE_SE2": "g2o", "EDGE2": "toro"}
_IGNORED_TAGS = {"EQUIV", "FIX"}
FORMATS = ("g2o", "toro", "city")


def _info_from_upper(v: np.ndarray, fmt: str) -> np.ndarray:
    """(E, 6) upper-triangle entries in the file's order -> (E, 3, 3) symmetric matrices."""
    if fmt == "g2o":  # I11 I12 I13 I22 I23 I33
        i11, i12, i13, i22, i23, i33 = v.T
    else:  # TORO: I11 I12 I22 I33 I13 I23
        i11, i12, i22, i33, i13, i23 = v.T
    return np.stack(
        [
            np.stack([i11, i12, i13], -1),
            np.stack([i12, i22, i23], -1),
            np.stack([i13, i23, i33], -1),
        ],
        axis=-2,
    )


def _info_to_upper(info: np.ndarray, fmt: str) -> np.ndarray:
    i = info
    if fmt == "g2o":
        cols = (i[:, 0, 0], i[:, 0, 1], i[:, 0, 2], i[:, 1, 1], i[:, 1, 2], i[:, 2, 2])
    else:
        cols = (i[:, 0, 0], i[:, 0, 1], i[:, 1, 1], i[:, 2, 2], i[:, 0, 2], i[:, 1, 2])
    return np.stack(cols, axis=-1)


def _is_city_edge(tok: list[str]) -> bool:
    if len(tok) < 9 or tok[2] != "1" or tok[4] != "0":
        return False
    try:
        n = int(tok[5])
    except ValueError:
        return False
    return n >= 1 and len(tok) == 6 + 3 * n


def read_posegraph(
    path: str | os.PathLike, *, format: str | None = None, initial: str = "file"
) -> PoseGraph:
    """Read a 2D pose graph file (g2o, TORO or the city10000 variant).

    Args:
        path: the file.
        format: "g2o", "toro" or "city" (it decides the order of the information
            entries); ``None`` detects it: g2o for ``*_SE2`` tags or a ``.g2o`` suffix,
            city for vertex-less files whose edges all have the city layout, else TORO.
        initial: "file" (the VERTEX poses; composed odometry when there are none) or
            "odometry" (always compose the odometry edges ``i -> i+1`` in row order,
            the initial estimate of the backend-comparison reference figures).

    Returns:
        A :class:`PoseGraph`; ``ids`` are the file's vertex ids, rows follow the vertex
        lines' order (or 0..N-1 when the file has no vertices and the initial estimate
        is composed from the odometry edges ``i -> i+1``); ``information`` is the file's
        (identity where an edge has none; the city sigmas for city10000).

    Raises:
        InputError: the file does not exist.
        MapFormatError: a line cannot be parsed, an edge names an unknown vertex, or
            the file holds records other than 2D poses and pose-pose edges.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"pose-graph file {str(path)!r} does not exist")
    if initial not in ("file", "odometry"):
        raise InputError(f"initial must be 'file' or 'odometry', got {initial!r}")
    if format is not None and format not in FORMATS:
        raise MapFormatError(f"unknown pose-graph format {format!r} (valid: {', '.join(FORMATS)})")
    vertices: list[list[str]] = []
    edges: list[list[str]] = []
    where: list[int] = []
    tags: set[str] = set()
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise MapFormatError(f"{path.name}: not a text file ({exc.reason})") from None
    for lineno, line in enumerate(text.split("\n"), 1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        tag = tok[0]
        if tag in _IGNORED_TAGS:
            continue
        if tag in _VERTEX_TAGS:
            vertices.append(tok)
        elif tag in _EDGE_TAGS:
            edges.append(tok)
            where.append(lineno)
        else:
            raise MapFormatError(
                f"{path.name}:{lineno}: unsupported record {tag!r}; only 2D pose graphs "
                "(VERTEX_SE2/EDGE_SE2, VERTEX2/EDGE2, EQUIV) are read"
            )
        tags.add(tag)
    if not edges and not vertices:
        raise MapFormatError(f"{path.name}: no VERTEX or EDGE lines: is this a 2D pose graph?")
    if format is None:
        if "VERTEX_SE2" in tags or "EDGE_SE2" in tags or path.suffix.lower() == ".g2o":
            format = "g2o"
        elif edges and not vertices and all(_is_city_edge(t) for t in edges):
            format = "city"
        else:
            format = "toro"

    def floats(rows: list[list[str]], cols: slice, what: str) -> np.ndarray:
        try:
            out = np.array([r[cols] for r in rows], dtype=np.float64)
        except ValueError as exc:  # ragged or non-numeric
            bad = next((i for i, r in enumerate(rows) if len(r[cols]) != len(rows[0][cols])), None)
            line = f" (line {where[bad]})" if what == "edge" and bad is not None else ""
            raise MapFormatError(f"{path.name}: malformed {what} line{line}: {exc}") from None
        return out

    def vertex_ids(ids: np.ndarray, what: str) -> np.ndarray:
        """Integer ids, refused when not whole, not finite, negative or beyond 2**53."""
        bad = ~np.isfinite(ids) | (ids != np.round(ids)) | (ids < 0) | (ids > 2.0**53)
        if bad.any():
            i = int(np.flatnonzero(bad.reshape(len(ids), -1).any(axis=1))[0])
            line = f":{where[i]}" if what == "edge" else ""
            raise MapFormatError(
                f"{path.name}{line}: {what} vertex id {ids.reshape(len(ids), -1)[i].tolist()} "
                "is not a non-negative integer"
            )
        return ids.astype(np.int64)

    def chain_size(ids: np.ndarray) -> int:
        """Vertices of a file without VERTEX lines: ids 0..N-1 joined by odometry edges;
        an id beyond the number of edges cannot be reached (and must not size arrays)."""
        n = int(ids.max()) + 1 if ids.size else 0
        if n > len(edges) + 1:
            raise MapFormatError(
                f"{path.name}: an edge names vertex {n - 1} but the file has {len(edges)} "
                "edges and no VERTEX lines; vertex ids must run 0..N-1 along the odometry"
            )
        return n

    if format == "city":
        if not all(_is_city_edge(t) for t in edges):
            bad = next(i for i, t in enumerate(edges) if not _is_city_edge(t))
            raise MapFormatError(
                f"{path.name}:{where[bad]}: not a city10000 edge 'EDGE2 s 1 t 0 n x y th ...'"
            )
        ends = vertex_ids(floats([[t[1], t[3]] for t in edges], slice(0, 2), "edge"), "edge")
        meas = floats(edges, slice(6, 9), "edge")
        info = np.broadcast_to(np.diag(1.0 / np.square(CITY_SIGMAS)), (len(edges), 3, 3)).copy()
        n = chain_size(ends)
        try:
            poses = compose_odometry(n, ends, meas)
            return PoseGraph(poses, ends, meas, np.arange(n), info)
        except InputError as exc:
            raise MapFormatError(f"{path.name}: {exc}") from None

    if edges:
        lengths = {len(t) for t in edges}
        if not lengths <= {6, 12}:
            bad = next(i for i, t in enumerate(edges) if len(t) not in (6, 12))
            raise MapFormatError(
                f"{path.name}:{where[bad]}: an edge has {len(edges[bad])} fields; expected "
                "'TAG id1 id2 dx dy dth' plus 6 information entries"
            )
        ids12 = vertex_ids(floats(edges, slice(1, 3), "edge"), "edge")
        meas = floats([t[:6] for t in edges], slice(3, 6), "edge")
        info = np.broadcast_to(np.eye(3), (len(edges), 3, 3)).copy()
        full = np.array([len(t) == 12 for t in edges])
        if full.any():
            upper = floats([t for t, f in zip(edges, full) if f], slice(6, 12), "edge")
            info[full] = _info_from_upper(upper, format)
    else:
        ids12 = np.zeros((0, 2), np.int64)
        meas = np.zeros((0, 3))
        info = np.zeros((0, 3, 3))

    if vertices:
        if any(len(t) != 5 for t in vertices):
            raise MapFormatError(f"{path.name}: a vertex line is not 'TAG id x y th'")
        vid = vertex_ids(floats(vertices, slice(1, 2), "vertex")[:, 0], "a")
        poses = floats(vertices, slice(2, 5), "vertex")
        if len(np.unique(vid)) != len(vid):
            raise MapFormatError(f"{path.name}: duplicate vertex ids")
        order = np.argsort(vid, kind="stable")
        pos = np.searchsorted(vid[order], ids12)
        pos = np.minimum(pos, len(vid) - 1)
        found = vid[order][pos] == ids12
        if not found.all():
            bad = int(np.flatnonzero(~found.all(axis=1))[0])
            raise MapFormatError(
                f"{path.name}:{where[bad]}: edge names vertex "
                f"{ids12[bad][~found[bad]][0]} that has no VERTEX line"
            )
        rows = order[pos]
    else:
        n = chain_size(ids12)
        vid = np.arange(n)
        rows = ids12
    try:
        if not vertices:
            poses = compose_odometry(n, ids12, meas)
        if initial == "odometry" and vertices:
            poses = compose_odometry(len(vid), rows, meas, start=poses[0])
        return PoseGraph(poses, rows, meas, vid, info)
    except InputError as exc:
        raise MapFormatError(f"{path.name}: {exc}") from None


def _write(pg: PoseGraph, path: str | os.PathLike, fmt: str) -> None:
    vtag, etag = ("VERTEX_SE2", "EDGE_SE2") if fmt == "g2o" else ("VERTEX2", "EDGE2")
    ids = np.arange(pg.num_poses) if pg.ids is None else pg.ids
    info = pg.information
    if info is None:
        info = np.broadcast_to(np.eye(3), (pg.num_edges, 3, 3))
    upper = _info_to_upper(info, fmt)
    lines = [
        f"{vtag} {i} {x!r} {y!r} {th!r}" for i, (x, y, th) in zip(ids.tolist(), pg.poses.tolist())
    ]
    eids = ids[pg.edges].tolist()
    for (a, b), m, u in zip(eids, pg.measurements.tolist(), upper.tolist()):
        lines.append(f"{etag} {a} {b} " + " ".join(repr(v) for v in (*m, *u)))
    atomic_write_text(Path(path), "\n".join(lines) + "\n")


def write_g2o(pg: PoseGraph, path: str | os.PathLike) -> None:
    """Write ``pg`` as a g2o file (``VERTEX_SE2``/``EDGE_SE2``), atomically.

    Edges without information (``pg.information is None``) are written with identity.
    """
    _write(pg, path, "g2o")


def write_toro(pg: PoseGraph, path: str | os.PathLike) -> None:
    """Write ``pg`` as a TORO file (``VERTEX2``/``EDGE2``), atomically.

    Edges without information (``pg.information is None``) are written with identity.
    """
    _write(pg, path, "toro")


def read_poses(path: str | os.PathLike) -> np.ndarray:
    """Read a ground-truth pose file with one ``x y th`` per line (city10000's
    ``ISAM2_GT_city10000.txt``); a leading index column (4 fields) is dropped.

    Returns:
        (N, 3) float64.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"pose file {str(path)!r} does not exist")
    try:
        data = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise MapFormatError(f"{path.name}: not a table of numbers: {exc}") from None
    if data.shape[1] == 4:
        data = data[:, 1:]
    if data.shape[1] != 3:
        raise MapFormatError(f"{path.name}: expected 3 columns 'x y th', got {data.shape[1]}")
    return data


def example_file(name: str) -> Path:
    """Path of a pose-graph file shipped with the gtsam wheel (``w100.graph``,
    ``w10000.graph``, ``T1_city10000_04.txt``, ``ISAM2_GT_city10000.txt``)."""
    import gtsam

    try:
        found = gtsam.findExampleDataFile(name)
    except (RuntimeError, ValueError) as exc:
        raise InputError(f"gtsam ships no example file {name!r}: {exc}") from None
    return Path(found)
