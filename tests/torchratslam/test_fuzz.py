"""Every parser fuzzed: a valid result or the project's own error with one line.

Parsers: configs (YAML and OpenRatSLAM ``.txt``), native saved maps (``state.json`` and
``state.npz``), the authors' reference-format maps, pose graphs (g2o / TORO / city10000),
odometry and ground-truth CSVs. The property, for every generated input: the parser
returns, or raises a :class:`RatSLAMError` whose message is one line; never another
exception, and never a large allocation (the peak of numpy/Python allocations traced by
``tracemalloc`` stays under 64 MB, so an input that declares a huge size is refused
before anything is allocated).

``make test`` replays the corpus (``tests/data/fuzz_corpus/``: every input that ever
failed, one file each, kept so it never fails again) and runs the ``fuzz-quick`` profile
(150 new random examples per parser, different on every run); ``make fuzz`` sets
``TORCHRATSLAM_FUZZ_PROFILE=fuzz`` (5000 random examples per parser). A NumPy warning
is a failure (an input must be refused, not computed on with NaNs). A failing example
is printed by hypothesis; add it to the corpus.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ratslam_graph.io import read_posegraph
from torchratslam.config import RatSLAMConfig, check_config_limits, load_config
from torchratslam.errors import RatSLAMError
from torchratslam.maps.native import load_map, save_map
from torchratslam.maps.reference_format import FILES, read_reference
from torchratslam.readers.datasets import read_groundtruth_csv, read_odometry_csv
from torchratslam.sweeps.spec import load_sweep

from .maps.test_reference_format import CFG as REF_CFG
from .maps.test_reference_format import HAND
from .maps.test_state import random_map

_COMMON = {
    "deadline": None,
    "suppress_health_check": list(HealthCheck),
    "database": None,
}
settings.register_profile("fuzz-quick", max_examples=150, **_COMMON)
settings.register_profile("fuzz", max_examples=5000, **_COMMON)
FUZZ = settings.get_profile(os.environ.get("TORCHRATSLAM_FUZZ_PROFILE", "fuzz-quick"))
PEAK_BYTES = 64 << 20

WORK = Path(tempfile.mkdtemp(prefix="torchratslam-fuzz-"))
CORPUS = Path(__file__).resolve().parents[1] / "data" / "fuzz_corpus"

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@pytest.fixture(scope="module", autouse=True)
def _cleanup():
    yield
    shutil.rmtree(WORK, ignore_errors=True)


def check(parse, *args, **kwargs):
    """Run ``parse``; the property: a result or a one-line RatSLAMError, small peak memory."""
    tracemalloc.start()
    try:
        out = parse(*args, **kwargs)
    except RatSLAMError as exc:
        msg = str(exc)
        assert msg and "\n" not in msg, f"multi-line message: {msg!r}"
        out = exc
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak < PEAK_BYTES, f"{peak / 1e6:.0f} MB allocated"
    return out


# ----------------------------------------------------------------------- shared strategies
NUMBER_TEXT = st.one_of(
    st.integers(-(10**30), 10**30).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["nan", "inf", "-inf", "1e400", "-1e400", "1e12", "-1", "0", "1.5", "16.0"]),
)
TOKEN = st.one_of(
    NUMBER_TEXT,
    st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=8),
    st.sampled_from(["[", "]", "[0, 3]", "[[1]]", "[1e400]", "[0,'a']", "-", ",", "#", ";"]),
)
PARAM_KEYS = sorted(RatSLAMConfig.key_owner())
YAML_VALUE = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(10**20), 10**20),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=10),
    ),
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=6,
)


def _lines(draw_line):
    return st.lists(draw_line, max_size=12).map(lambda ls: "\n".join(ls) + "\n")


# ----------------------------------------------------------------------- configs
@FUZZ
@given(
    st.one_of(
        st.dictionaries(
            st.one_of(st.sampled_from(PARAM_KEYS), st.text(max_size=12), st.integers(), st.none()),
            YAML_VALUE,
            max_size=6,
        ).map(lambda d: yaml.safe_dump(d, allow_unicode=True)),
        st.text(max_size=200),
        st.lists(st.tuples(st.sampled_from(PARAM_KEYS), NUMBER_TEXT), max_size=6).map(
            lambda kv: "".join(f"{k}: {v}\n" for k, v in kv)
        ),
    ),
    st.dictionaries(
        st.sampled_from(PARAM_KEYS), st.one_of(NUMBER_TEXT, st.text(max_size=6)), max_size=2
    ),
)
def test_fuzz_yaml_config(text, overrides):
    p = WORK / "c.yaml"
    p.write_text(text)
    out = check(load_config, p, **overrides)
    if isinstance(out, RatSLAMConfig):
        check(check_config_limits, out)


@FUZZ
@given(
    st.lists(
        st.one_of(
            st.sampled_from(["[general]", "[ratslam]", "[visual_odometry]", "[draw]", "[", "]"]),
            st.tuples(st.sampled_from(PARAM_KEYS), st.sampled_from(["=", ":", " = "]), TOKEN).map(
                "".join
            ),
            st.text(max_size=30),
        ),
        max_size=12,
    ).map("\n".join),
)
def test_fuzz_openratslam_txt_config(text):
    p = WORK / "c.txt"
    p.write_text(text)
    check(load_config, p)


# ----------------------------------------------------------------------- sweeps
SWEEP_VALUES = st.one_of(
    st.lists(st.one_of(NUMBER_TEXT.map(yaml.safe_load), st.text(max_size=4)), max_size=4),
    st.fixed_dictionaries(
        {"start": st.floats(-1, 1), "stop": st.floats(-1, 1)},
        optional={"num": st.integers(-3, 10**13), "log": st.booleans()},
    ),
    YAML_VALUE,
)


@FUZZ
@given(
    st.fixed_dictionaries(
        {},
        optional={
            "base": st.sampled_from(["virtual_tour", "irat", "nope", "", None]),
            "datasets": st.one_of(
                st.lists(st.sampled_from(["sim:loop", "sim:loop?frames=5", "", "x"]), max_size=2),
                YAML_VALUE,
            ),
            "parameters": st.dictionaries(
                st.one_of(st.sampled_from(PARAM_KEYS), st.text(max_size=6)),
                SWEEP_VALUES,
                max_size=3,
            ),
            "mode": st.sampled_from(["grid", "list", "random", 3]),
            "seeds": st.one_of(st.lists(st.integers(-2, 10**12), max_size=3), YAML_VALUE),
            "max_frames": st.one_of(st.integers(-2, 10**12), YAML_VALUE),
            "junk": YAML_VALUE,
        },
    ).map(lambda d: yaml.safe_dump(d, allow_unicode=True)),
)
def test_fuzz_sweep_file(text):
    """A sweep file: a spec or one line, at once (a huge grid is counted, not expanded)."""
    p = WORK / "sweep.yaml"
    p.write_text(text)
    check(load_sweep, p)


# ----------------------------------------------------------------------- CSVs
CSV_HEADER = st.sampled_from(
    ["t,vtrans,vrot", "t,x,y,theta", "t, vtrans ,vrot,extra", "vrot,t,vtrans", "", "t"]
)


@FUZZ
@given(
    CSV_HEADER,
    st.lists(st.lists(TOKEN, max_size=5).map(",".join), max_size=10),
    st.sampled_from(["odometry", "groundtruth"]),
)
def test_fuzz_odometry_and_groundtruth_csv(header, rows, kind):
    p = WORK / f"{kind}.csv"
    p.write_text("\n".join([header, *rows]) + "\n")
    out = check(read_odometry_csv if kind == "odometry" else read_groundtruth_csv, p)
    if kind == "odometry" and isinstance(out, tuple):
        t, v, w = out
        assert np.isfinite(t).all() and np.isfinite(v).all() and np.isfinite(w).all()
        assert (np.abs(v) <= 50).all() and (t.size < 2 or (np.diff(t) > 0).all())


# ----------------------------------------------------------------------- pose graphs
ID_TEXT = st.one_of(
    st.integers(-5, 12).map(str),
    st.sampled_from(["1e12", "-1", "1e400", "nan", "3.5", "999999999999999999999", "0.0"]),
)


@st.composite
def posegraph_text(draw):
    lines = []
    for _ in range(draw(st.integers(0, 10))):
        kind = draw(st.sampled_from(["v", "e", "city", "junk"]))
        if kind == "v":
            tag = draw(st.sampled_from(["VERTEX_SE2", "VERTEX2"]))
            vals = draw(st.lists(NUMBER_TEXT, min_size=2, max_size=4))
            lines.append(" ".join([tag, draw(ID_TEXT), *vals]))
        elif kind == "e":
            tag = draw(st.sampled_from(["EDGE_SE2", "EDGE2"]))
            n = draw(st.sampled_from([3, 9, 2, 4]))
            vals = draw(st.lists(NUMBER_TEXT, min_size=n, max_size=n))
            lines.append(" ".join([tag, draw(ID_TEXT), draw(ID_TEXT), *vals]))
        elif kind == "city":
            k = draw(st.integers(1, 2))
            vals = draw(st.lists(NUMBER_TEXT, min_size=3 * k, max_size=3 * k))
            lines.append(" ".join(["EDGE2", draw(ID_TEXT), "1", draw(ID_TEXT), "0", str(k), *vals]))
        else:
            lines.append(" ".join(draw(st.lists(TOKEN, max_size=4))))
    return "\n".join(lines) + "\n"


@FUZZ
@given(
    posegraph_text(),
    st.sampled_from([".g2o", ".graph", ".txt"]),
    st.sampled_from(["file", "odometry"]),
)
def test_fuzz_posegraph(text, suffix, initial):
    p = WORK / f"pg{suffix}"
    p.write_text(text)
    check(read_posegraph, p, initial=initial)


# ----------------------------------------------------------------------- native maps
def _native_bytes():
    d = WORK / "native-src"
    if not d.exists():
        save_map(random_map(), d)
    return (d / "state.json").read_text(), (d / "state.npz").read_bytes()


JSON_VALUE = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(10**15), 10**15),
        st.floats(allow_nan=False),
        st.text(max_size=6),
    ),
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=5,
)


def _paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, (*prefix, i))


def _set(obj, path, value):
    if not path:
        return value
    cur = obj
    for k in path[:-1]:
        cur = cur[k]
    cur[path[-1]] = value
    return obj


def _npz_with(arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


@st.composite
def native_map(draw):
    meta_text, npz = _native_bytes()
    how = draw(st.sampled_from(["json", "json-text", "npz-bytes", "npz-array", "npz-header"]))
    if how == "json":
        meta = json.loads(meta_text)
        paths = list(_paths(meta))
        path = paths[draw(st.integers(0, len(paths) - 1))]
        meta = _set(meta, path, draw(JSON_VALUE))
        meta_text = json.dumps(meta)
    elif how == "json-text":
        i = draw(st.integers(0, len(meta_text)))
        meta_text = (
            meta_text[:i] + draw(st.text(max_size=5)) + meta_text[i + draw(st.integers(0, 5)) :]
        )
    elif how == "npz-bytes":
        b = bytearray(npz)
        for _ in range(draw(st.integers(1, 4))):
            i = draw(st.integers(0, len(b) - 1))
            b[i] = draw(st.integers(0, 255))
        npz = bytes(b[: draw(st.integers(0, len(b)))]) if draw(st.booleans()) else bytes(b)
    elif how == "npz-array":
        with np.load(io.BytesIO(npz)) as z:
            arrays = {k: z[k] for k in z.files}
        key = draw(st.sampled_from(sorted(arrays)))
        dtype = draw(st.sampled_from(["f8", "f4", "i8", "i4", "u1", "b1", "c8", "U3"]))
        shape = tuple(draw(st.lists(st.integers(0, 4), max_size=3)))
        arrays[key] = np.zeros(shape, dtype)
        if draw(st.booleans()):
            meta = json.loads(meta_text)
            meta["arrays"][key] = {"shape": list(shape), "dtype": str(np.dtype(dtype))}
            meta_text = json.dumps(meta)
        npz = _npz_with(arrays)
    else:  # a member whose header declares a huge shape
        big = draw(st.sampled_from([[10**6, 10**6], [2**40], [10**5, 10**5, 3]]))
        header = {"descr": "<f8", "fortran_order": False, "shape": tuple(big)}
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, header)
        out = io.BytesIO()
        with zipfile.ZipFile(io.BytesIO(npz)) as zin, zipfile.ZipFile(out, "w") as zout:
            victim = draw(st.sampled_from(sorted(zin.namelist())))
            for name in zin.namelist():
                zout.writestr(
                    name, buf.getvalue() + b"\0" * 64 if name == victim else zin.read(name)
                )
        npz = out.getvalue()
    return meta_text, npz


@FUZZ
@given(native_map())
def test_fuzz_native_map(files):
    meta_text, npz = files
    d = WORK / "native"
    d.mkdir(exist_ok=True)
    (d / "state.json").write_text(meta_text)
    (d / "state.npz").write_bytes(npz)
    check(load_map, d)


# ----------------------------------------------------------------------- reference maps
@st.composite
def reference_map(draw):
    files = {name: text.splitlines() for name, text in HAND.items()}
    for _ in range(draw(st.integers(1, 3))):
        name = draw(st.sampled_from(FILES))
        lines = files[name]
        op = draw(st.sampled_from(["replace", "insert", "delete", "truncate"]))
        i = draw(st.integers(0, max(len(lines) - 1, 0)))
        if op == "replace" and lines:
            lines[i] = " ".join(draw(st.lists(TOKEN, min_size=1, max_size=3)))
        elif op == "insert":
            lines.insert(i, " ".join(draw(st.lists(TOKEN, min_size=1, max_size=3))))
        elif op == "delete" and lines:
            del lines[i]
        else:
            del lines[i:]
    return {name: "\n".join(lines) + "\n" for name, lines in files.items()}


@FUZZ
@given(reference_map(), st.booleans())
def test_fuzz_reference_map(files, with_config):
    d = WORK / "ref"
    d.mkdir(exist_ok=True)
    for name, text in files.items():
        (d / name).write_text(text)
    check(read_reference, d, REF_CFG if with_config else None)


def test_the_fuzzers_reach_valid_inputs_too():
    # the unmutated seeds parse: the fuzzers start from real examples
    d = WORK / "seed-ref"
    d.mkdir(exist_ok=True)
    for name, text in HAND.items():
        (d / name).write_text(text)
    assert not isinstance(check(read_reference, d, REF_CFG), Exception)
    meta_text, npz = _native_bytes()
    n = WORK / "seed-native"
    n.mkdir(exist_ok=True)
    (n / "state.json").write_text(meta_text)
    (n / "state.npz").write_bytes(npz)
    assert check(load_map, n).equals(random_map())


# ----------------------------------------------------------------------- the corpus
def _corpus_parsers():
    return {
        "yaml": [load_config],
        "txt": [load_config],
        "posegraph": [
            lambda p: read_posegraph(p, initial="file"),
            lambda p: read_posegraph(p, initial="odometry"),
        ],
        "odometry": [read_odometry_csv],
        "groundtruth": [read_groundtruth_csv],
        "sweep": [load_sweep],
    }


CORPUS_FILES = sorted(p for p in CORPUS.rglob("*") if p.is_file() and p.name != "README.md")


@pytest.mark.parametrize("path", CORPUS_FILES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_the_inputs_that_once_failed_are_refused_in_one_line(path):
    parsers = _corpus_parsers()
    assert path.parent.name in parsers, f"{path}: put corpus files in {sorted(parsers)}"
    for parse in parsers[path.parent.name]:
        out = check(parse, path)
        assert isinstance(out, RatSLAMError), f"{path.name} parsed: {out!r:.200}"


def test_the_corpus_covers_every_parser_folder():
    assert {p.parent.name for p in CORPUS_FILES} == set(_corpus_parsers())
