"""The multisession authors' save format, read and written byte for byte as their code
lays it out (shared/reference/reference-save-format.md).

The fixtures are written here, by the tests, in that byte layout: savetxt lists
(``%.18e`` values each followed by a space; an empty list is an empty line), Python
``str()`` scalars (ids sometimes as ``16.0``), blank lines as fields, ``links.txt``
without a tail, an empty ``goal_list.txt``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from torchratslam.errors import InputError, MapFormatError
from torchratslam.maps.compat import conform
from torchratslam.maps.io import load_state, map_format
from torchratslam.maps.reference_format import (
    FILES,
    GOAL_FILE,
    read_reference,
    reference_texts,
    write_reference,
)
from torchratslam.maps.state import MISSING_KEY, MapState

CFG = {"template_x_size": 3, "template_y_size": 2, "pc_dim_xy": 5, "pc_dim_th": 8}


def savetxt(values):
    """numpy.savetxt(fh, values, newline=" ") written out by hand."""
    return "".join(f"{float(v):.18e} " for v in values)


# A tiny map written by hand in their layout: ids as ints and as floats, a one-element
# list, a several-element list, empty lists (blank lines), links.txt without a tail.
HAND = {
    "localviewcells.txt": "6\n"
    "0\n0.35\n" + savetxt([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]) + "\n"
    "1.0\n0.25\n" + savetxt([0, 0.5, 0.25, 0.25, 0.5, 0]) + "\n"
    "-\n1\n0\n",
    "posecellvisual_templates.txt": "0\n2.0\n3.0\n4.5\n1.5\n"
    + savetxt([0])
    + "\n1\n2.5\n3.0\n7.0\n1.0\n"
    + savetxt([1, 2])
    + "\n-\n1\n\n",  # the prev line left blank
    "posecellexperiences.txt": "2.0\n3.0\n4.5\n0\n2.5\n3.0\n7.0\n1\n2.6\n3.1\n6.9\n1.0\n-\n2\n0\n",
    "experiences.txt": "0\n0.0\n0.0\n2.44346095279\n0\n"
    + savetxt([0])
    + "\n"
    + savetxt([1])
    + "\n0\n-1\n-1\n"
    + "1\n-0.766044443119\n0.642787609687\n2.44346095279\n1\n"
    + savetxt([1])
    + "\n"
    + savetxt([0])
    + "\n0\n-1\n-1\n"
    + "2.0\n-0.9\n0.7\n2.5\n1\n\n\n0\n-1\n-1\n"
    + "-\n2\n1\n",
    "links.txt": "1.0\n0.0\n0.0\n1\n0\n3.5\n1.0\n3.14159265359\n0.0\n0.0\n1\n7.0\n",
    "goal_list.txt": "",
}


def write_hand(d, files=HAND):
    d.mkdir()
    for name, text in files.items():
        (d / name).write_text(text)
    return d


def test_reads_a_hand_written_map(tmp_path):
    s = read_reference(write_hand(tmp_path / "ref"), CFG)
    assert s.templates.shape == (2, 2, 3)
    assert s.templates[0].tolist() == [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]  # row-major
    assert s.template_mean.tolist() == [0.35, 0.25]
    assert s.template_pc.tolist() == [[2.0, 3.0, 4.5], [2.5, 3.0, 7.0]]
    assert s.template_decay.tolist() == [1.5, 1.0]
    assert s.exp_template.tolist() == [0, 1, 1]
    assert s.exp_pc[2].tolist() == [2.6, 3.1, 6.9]
    assert s.exp_pose[1].tolist() == [-0.766044443119, 0.642787609687, 2.44346095279]
    assert s.link_from.tolist() == [0, 1] and s.link_to.tolist() == [1, 0]  # TO before FROM
    assert s.link_dt.tolist() == [3.5, 7.0] and s.link_heading[1] == 3.14159265359
    assert (s.current_vt, s.prev_vt, s.current_exp, s.prev_exp) == (1, 0, 2, 1)
    assert s.activity.size == 0 and "ref.goal_list" not in s.extra
    # the format directory is found by the one loader of every format
    assert map_format(tmp_path / "ref") == "reference"
    assert load_state(tmp_path / "ref", CFG).equals(s)
    assert load_state(tmp_path / "ref").templates.shape == (2, 1, 6)  # no config: one row


# ------------------------------------------------------------------ the authors' loader
def authors_load(d):
    """Their loader's reading logic, from the format notes: readline() after readline(),
    a list ends at a line equal to "-\\n", links.txt ends when readline() returns ''."""

    def vec(line):
        return [float(v) for v in line.split()]

    out = {}
    with open(d / "localviewcells.txt") as f:
        out["size"] = int(float(f.readline()))
        out["templates"] = []
        while True:
            line = f.readline()
            if line == "-\n":
                break
            tid = int(float(line))
            mean = float(f.readline())
            out["templates"].append((tid, mean, vec(f.readline())))
        out["vt"] = (int(float(f.readline())), int(float(f.readline())))
    with open(d / "posecellvisual_templates.txt") as f:
        out["pvt"] = []
        while True:
            line = f.readline()
            if line == "-\n":
                break
            rec = [int(float(line))] + [float(f.readline()) for _ in range(4)]
            out["pvt"].append((*rec, vec(f.readline())))
        cur, prev = f.readline(), f.readline()
        out["pvt_ids"] = (int(float(cur)), int(float(prev)) if prev.strip() else None)
    with open(d / "posecellexperiences.txt") as f:
        out["pce"] = []
        while True:
            line = f.readline()
            if line == "-\n":
                break
            xyz = [float(line), float(f.readline()), float(f.readline())]
            out["pce"].append((*xyz, int(float(f.readline()))))
        out["pce_ids"] = (int(float(f.readline())), int(float(f.readline())))
    with open(d / "experiences.txt") as f:
        out["exps"] = []
        while True:
            line = f.readline()
            if line == "-\n":
                break
            eid = int(float(line))
            x, y, th = (float(f.readline()) for _ in range(3))
            vt = int(float(f.readline()))
            lf, lt = vec(f.readline()), vec(f.readline())
            rest = [float(f.readline()) for _ in range(3)]
            out["exps"].append((eid, x, y, th, vt, lf, lt, *rest))
        out["exp_ids"] = (int(float(f.readline())), int(float(f.readline())))
    with open(d / "links.txt") as f:
        out["links"] = []
        while True:
            line = f.readline()
            if line == "":
                break
            dd, hh, ff = float(line), float(f.readline()), float(f.readline())
            to, frm = int(float(f.readline())), int(float(f.readline()))
            out["links"].append((dd, hh, ff, to, frm, float(f.readline())))
    with open(d / "goal_list.txt") as f:
        out["goals"] = [int(v) for v in vec(f.readline())]
    return out


def random_map(rng, n, m, el, *, goals=None):
    """A valid map whose every field is random (experience j has template tpl[j])."""
    tpl = np.sort(rng.integers(0, n, size=m)) if n else np.full(m, -1)
    if n and m >= n:
        tpl[:n] = np.arange(n)  # every template has an experience
        tpl = np.sort(tpl)
    frm = rng.integers(0, m, size=el) if m > 1 else np.zeros(el, np.int64)
    to = (frm + rng.integers(1, max(m, 2), size=el)) % max(m, 1)
    extra = {} if goals is None else {"ref.goal_list": np.asarray(goals, np.int64)}
    return MapState(
        config=dict(CFG),
        templates=rng.random((n, 2, 3)),
        template_mean=rng.random(n),
        template_frame=np.full(n, -1),
        template_pc=rng.random((n, 3)) * 5,
        template_decay=rng.random(n) + 0.5,
        exp_pose=rng.normal(size=(m, 3)),
        exp_pc=rng.random((m, 3)) * 5,
        exp_template=tpl.astype(np.int64),
        exp_frame=np.full(m, -1),
        exp_t=np.zeros(m),
        link_from=frm.astype(np.int64),
        link_to=to.astype(np.int64),
        link_d=rng.random(el),
        link_heading=rng.normal(size=el),
        link_facing=rng.normal(size=el),
        link_dt=rng.random(el) * 10,
        activity=np.zeros((0, 0, 0)),
        current_vt=n - 1,
        prev_vt=max(n - 2, -1),
        current_exp=m - 1,
        prev_exp=max(m - 2, -1),
        extra=extra,
        scalars={"imported_from": "reference"},
    ).validate()


@pytest.mark.parametrize(
    ("n", "m", "el", "goals"),
    [(4, 6, 7, [2, 5]), (1, 1, 0, [3 % 1]), (3, 5, 1, None), (0, 0, 0, None)],
    ids=["lists", "one-element", "one-link", "empty-map"],
)
def test_the_authors_loader_reads_what_we_write(tmp_path, n, m, el, goals):
    s = random_map(np.random.default_rng(n * 7 + m), n, m, el, goals=goals)
    write_reference(s, tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted([*FILES, GOAL_FILE])
    got = authors_load(tmp_path / "out")
    assert got["size"] == 6
    for i, (tid, mean, data) in enumerate(got["templates"]):
        assert (tid, mean) == (i, s.template_mean[i]) and data == s.templates[i].ravel().tolist()
    assert len(got["templates"]) == n == len(got["pvt"])
    for i, (tid, x, y, th, decay, exps) in enumerate(got["pvt"]):
        assert [tid, x, y, th, decay] == [i, *s.template_pc[i], s.template_decay[i]]
        assert exps == [j for j in range(m) if s.exp_template[j] == i]
    assert [list(r[:3]) for r in got["pce"]] == s.exp_pc.tolist()
    assert [r[3] for r in got["pce"]] == s.exp_template.tolist()
    for j, (eid, x, y, th, vt, lf, lt, t, g1, g2) in enumerate(got["exps"]):
        assert [eid, x, y, th, vt] == [j, *s.exp_pose[j], s.exp_template[j]]
        assert lf == [k for k in range(el) if s.link_from[k] == j]
        assert lt == [k for k in range(el) if s.link_to[k] == j]
        assert (t, g1, g2) == (0, -1, -1)
    assert len(got["exps"]) == m
    want_links = [
        (s.link_d[k], s.link_heading[k], s.link_facing[k], s.link_to[k], s.link_from[k])
        for k in range(el)
    ]
    assert [r[:5] for r in got["links"]] == want_links
    assert [r[5] for r in got["links"]] == s.link_dt.tolist()
    assert got["goals"] == ([] if goals is None else goals)
    if n:
        assert got["vt"] == (s.current_vt, s.prev_vt)
        assert got["exp_ids"] == (s.current_exp, s.prev_exp)
    else:  # their empty save: only the '-' lines and current ids of 0
        assert got["vt"] == got["exp_ids"] == got["pce_ids"] == (0, 0)
        assert (tmp_path / "out" / "links.txt").read_bytes() == b""
        assert (tmp_path / "out" / "goal_list.txt").read_bytes() == b""
    # and we read back every value the format holds
    assert read_reference(tmp_path / "out", CFG).equals(s)


def test_empty_map_as_their_code_saves_it(tmp_path):
    files = {
        "localviewcells.txt": "4096\n-\n0\n0\n",
        "posecellvisual_templates.txt": "-\n0\n0\n",
        "posecellexperiences.txt": "-\n0\n0\n",
        "experiences.txt": "-\n0\n0\n",
        "links.txt": "",
        "goal_list.txt": "",
    }
    s = read_reference(write_hand(tmp_path / "e", files))
    assert s.summary() == {"templates": 0, "experiences": 0, "links": 0}
    assert (s.current_vt, s.prev_vt, s.current_exp, s.prev_exp) == (-1, -1, -1, -1)
    assert s.templates.shape == (0, 1, 4096)
    write_reference(s, tmp_path / "w")
    for name, text in files.items():
        assert (tmp_path / "w" / name).read_text() == text, name


# ------------------------------------------------------------------ a sample-like save
def write_sample_like(d, rng):
    """A save like the iRat session in shared/reference/samples (74 templates, 81
    experiences, 82 links, templates 50 x 30, pc 11 x 11 x 36), written with plain
    loops exactly as their code writes: str() scalars, savetxt lists, some ids as
    floats, the pose cells' own tail (80, 0), an empty goal list."""
    n, m, el, size = 74, 81, 82, 1500
    tpl = np.concatenate([np.arange(n), rng.choice(n, m - n, replace=False)])
    tpl.sort()
    pose = np.cumsum(rng.normal(0, 0.03, (m, 3)), axis=0)
    pose[:, 2] = (pose[:, 2] + np.pi) % (2 * np.pi) - np.pi
    frm = np.concatenate([np.arange(m - 1), rng.integers(0, m - 10, el - (m - 1))])
    to = np.concatenate([np.arange(1, m), frm[m - 1 :] + 5])
    val = {
        "templates": rng.random((n, size)),
        "mean": rng.random(n),
        "tpc": rng.random((n, 3)) * [11, 11, 36],
        "decay": np.full(n, 1.5),
        "pose": pose,
        "epc": rng.random((m, 3)) * [11, 11, 36],
        "tpl": tpl,
        "frm": frm,
        "to": to,
        "geo": rng.normal(size=(el, 3)),
        "dt": np.cumsum(rng.random(el)),
    }
    lines = [str(size)]
    for i in range(n):
        lines += [str(i), str(val["mean"][i]), savetxt(val["templates"][i])]
    (d / "localviewcells.txt").write_text("\n".join([*lines, "-", "73", "73"]) + "\n")
    lines = []
    for i in range(n):
        lines += [str(i), *(str(v) for v in val["tpc"][i]), "1.5"]
        lines.append(savetxt([j for j in range(m) if tpl[j] == i]))
    (d / "posecellvisual_templates.txt").write_text("\n".join([*lines, "-", "73", "73"]) + "\n")
    lines = []
    for j in range(m):
        lines += [*(str(v) for v in val["epc"][j]), str(tpl[j])]
    (d / "posecellexperiences.txt").write_text("\n".join([*lines, "-", "80", "0"]) + "\n")
    lines = []
    for j in range(m):
        lines += [str(j), *(str(v) for v in pose[j]), str(tpl[j])]
        lines.append(savetxt([k for k in range(el) if frm[k] == j]))
        lines.append(savetxt([k for k in range(el) if to[k] == j]))
        lines += ["0", "-1", "-1"]
    (d / "experiences.txt").write_text("\n".join([*lines, "-", "80", "79"]) + "\n")
    lines = []
    for k in range(el):
        ids = [str(float(to[k])), str(float(frm[k]))] if k % 20 == 3 else [str(to[k]), str(frm[k])]
        lines += [*(str(v) for v in val["geo"][k]), *ids, str(val["dt"][k])]
    (d / "links.txt").write_text("\n".join(lines) + "\n")
    (d / "goal_list.txt").write_text("")
    return val


def test_a_sample_like_save_loads_and_round_trips(tmp_path):
    d = tmp_path / "irat"
    d.mkdir()
    val = write_sample_like(d, np.random.default_rng(3))
    cfg = {"template_x_size": 50, "template_y_size": 30, "pc_dim_xy": 11, "pc_dim_th": 36}
    s = read_reference(d, cfg)
    assert s.summary() == {"templates": 74, "experiences": 81, "links": 82}
    assert np.array_equal(s.templates.reshape(74, -1), val["templates"])
    assert np.array_equal(s.template_mean, val["mean"])
    assert np.array_equal(s.template_pc, val["tpc"])
    assert np.array_equal(s.exp_pose, val["pose"]) and np.array_equal(s.exp_pc, val["epc"])
    assert s.exp_template.tolist() == val["tpl"].tolist()
    assert s.link_from.tolist() == val["frm"].tolist()
    assert s.link_to.tolist() == val["to"].tolist()
    assert np.array_equal(np.stack([s.link_d, s.link_heading, s.link_facing], 1), val["geo"])
    assert np.array_equal(s.link_dt, val["dt"])
    assert (s.current_vt, s.prev_vt, s.current_exp, s.prev_exp) == (73, 73, 80, 79)
    write_reference(s, tmp_path / "back")
    assert read_reference(tmp_path / "back", cfg).equals(s)
    # byte for byte as written by their code, but for the ids they wrote as floats
    for name in (*FILES, GOAL_FILE):
        a = (d / name).read_text().split("\n")
        b = (tmp_path / "back" / name).read_text().split("\n")
        diff = [(x, y) for x, y in zip(a, b) if x != y]
        assert len(a) == len(b) and all(float(x) == float(y) for x, y in diff), name
        assert len(diff) == (8 if name == "links.txt" else 0), name


def test_stale_link_lists_are_derived_from_links_txt(tmp_path):
    files = dict(HAND)
    files["experiences.txt"] = files["experiences.txt"].replace(
        "0\n" + savetxt([0]) + "\n" + savetxt([1]), "0\n" + savetxt([0, 1, 5]) + "\n", 1
    )
    s = read_reference(write_hand(tmp_path / "ref", files), CFG)
    write_reference(s, tmp_path / "w")
    ex = (tmp_path / "w" / "experiences.txt").read_text().split("\n")
    assert ex[5] == savetxt([0]) and ex[6] == savetxt([1])


# ------------------------------------------------------------------ missing templates
def test_a_save_without_localviewcells_loads_but_cannot_be_merged(tmp_path):
    from torchratslam.maps.merge import merge_maps

    files = {k: v for k, v in HAND.items() if k != "localviewcells.txt"}
    s = load_state(write_hand(tmp_path / "ref", files), CFG)
    assert s.summary() == {"templates": 2, "experiences": 3, "links": 2}
    assert s.scalars[MISSING_KEY] == "localviewcells.txt"
    assert (s.current_vt, s.prev_vt) == (1, -1)  # from posecellvisual_templates.txt
    full = read_reference(write_hand(tmp_path / "full"), CFG)
    assert np.array_equal(s.exp_pose, full.exp_pose)  # plots / ICP / ATE work
    with pytest.raises(MapFormatError, match=r"localviewcells\.txt is missing"):
        merge_maps(full, s, 1)
    with pytest.raises(MapFormatError, match=r"localviewcells\.txt is missing"):
        merge_maps(s, full, 1)
    with pytest.raises(MapFormatError, match=r"localviewcells\.txt is missing"):
        conform(s, CFG)  # what a run continuing the map or a multisession run calls
    # written back, it stays without templates
    write_reference(s, tmp_path / "w")
    assert not (tmp_path / "w" / "localviewcells.txt").exists()
    assert read_reference(tmp_path / "w", CFG).equals(s)


# ------------------------------------------------------------------ malformed files
def _replace(name, old, new, count=1):
    files = dict(HAND)
    assert old in files[name], (name, old)
    files[name] = files[name].replace(old, new, count)
    return files


MALFORMED = [
    ("localviewcells.txt", "0\n0.35\n", "0\n[[1]]\n", 3, "expected a number"),
    ("localviewcells.txt", "0\n0.35\n", "0\n1e400\n", 3, "is 1e400"),
    ("localviewcells.txt", "0\n0.35\n", "0\nnan\n", 3, "is nan"),
    ("localviewcells.txt", "1.000000000000000056e-01", "[0,'a']", 4, "holds \"\\[0,'a'\\]\""),
    ("localviewcells.txt", "6\n", "1e300\n", 1, "not a size"),
    ("localviewcells.txt", "6\n", "7\n", 4, "template 0 has 6 values, expected 7"),
    ("localviewcells.txt", "6\n", "-3\n", 1, "not a size"),
    ("localviewcells.txt", "-\n1\n0\n", "-\n1\n", 10, "unexpected end of file"),
    ("localviewcells.txt", "-\n1\n0\n", "", 8, "no '-' line"),
    ("posecellvisual_templates.txt", "1\n2.5", "1e300\n2.5", 7, "not an id in 0..1"),
    ("posecellvisual_templates.txt", "1\n2.5", "0\n2.5", 7, "out of order"),
    ("posecellexperiences.txt", "7.0\n1\n", "7.0\n9\n", 8, "not an id in -1..1"),
    ("posecellexperiences.txt", "7.0\n1\n", "7.0\n0.5\n", 8, "not an id"),
    ("experiences.txt", "-0.9\n", "inf\n", 22, "pose is inf"),
    ("experiences.txt", "-\n2\n1\n", "-\n2\n1\nxyz\n", 34, "unexpected text"),
    ("experiences.txt", "-\n2\n1\n", "-\n7\n1\n", 32, "current_exp 7 is not an id"),
    ("links.txt", "1\n0\n3.5", "1\n99999999999999999999\n3.5", 5, "exp_from_id"),
    ("links.txt", "3.5\n1.0", "3.5\n-\n1.0", 7, "unexpected '-'"),
    ("links.txt", "0.0\n1\n7.0\n", "0.0\n1\n", 12, "unexpected end of file inside link 1"),
    ("links.txt", "1\n0\n3.5", "0\n0\n3.5", 4, "joins experience 0 to itself"),
    ("goal_list.txt", "", savetxt([0, 7]), 1, "not an experience id"),
    (
        "localviewcells.txt",
        "1.0\n0.25\n" + savetxt([0, 0.5, 0.25, 0.25, 0.5, 0]) + "\n",
        "",
        5,
        "1 templates end here but posecellvisual_templates.txt holds 2",
    ),
    (
        "experiences.txt",
        "2.0\n-0.9\n0.7\n2.5\n1\n\n\n0\n-1\n-1\n",
        "",
        21,
        "2 experiences end here but posecellexperiences.txt holds 3",
    ),
]


@pytest.mark.parametrize(("name", "old", "new", "line", "pattern"), MALFORMED)
def test_malformed_files_give_one_line_located_errors(tmp_path, name, old, new, line, pattern):
    write_hand(tmp_path / "ref", _replace(name, old, new))
    before = {p.name: p.read_bytes() for p in (tmp_path / "ref").iterdir()}
    with pytest.raises(MapFormatError, match=pattern) as err:
        read_reference(tmp_path / "ref", CFG)
    msg = str(err.value)
    assert "\n" not in msg and f"{name}, line {line}:" in msg, msg
    assert {p.name: p.read_bytes() for p in (tmp_path / "ref").iterdir()} == before


def test_missing_files_and_wrong_sizes(tmp_path):
    write_hand(tmp_path / "ref")
    with pytest.raises(MapFormatError, match=r"line 1: templates have 6 values but .* 4 x 2 = 8"):
        read_reference(tmp_path / "ref", {**CFG, "template_x_size": 4})
    (tmp_path / "ref" / "links.txt").unlink()
    with pytest.raises(MapFormatError, match=r"links\.txt is missing"):
        read_reference(tmp_path / "ref", CFG)
    (tmp_path / "ref" / "experiences.txt").unlink()
    with pytest.raises(InputError, match="holds no saved map"):
        load_state(tmp_path / "ref")
    (tmp_path / "bin").mkdir()
    for name in HAND:
        (tmp_path / "bin" / name).write_bytes(b"\xff\xfe\x00")
    with pytest.raises(MapFormatError, match="not UTF-8"):
        read_reference(tmp_path / "bin")


def test_export_refuses_a_directory_with_other_files(tmp_path):
    s = read_reference(write_hand(tmp_path / "ref"), CFG)
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "mine.txt").write_text("keep")
    with pytest.raises(InputError, match="other than a reference map"):
        write_reference(s, tmp_path / "x")
    assert (tmp_path / "x" / "mine.txt").read_text() == "keep"


def test_values_without_a_field_of_their_own_are_kept(tmp_path):
    """Goals, non-default experience fields, the pose cells' own template ids and the
    secondary tails come back on writing."""
    files = _replace("experiences.txt", "0\n-1\n-1\n-", "12.5\n0\n2\n-")
    files = {**files, "goal_list.txt": savetxt([2, 0])}
    files["posecellexperiences.txt"] = files["posecellexperiences.txt"].replace(
        "6.9\n1.0\n", "6.9\n0\n"
    )
    s = read_reference(write_hand(tmp_path / "ref", files), CFG)
    assert s.extra["ref.goal_list"].tolist() == [2, 0]
    assert s.extra["exp:ref_time_from_current"].tolist() == [0, 0, 12.5]
    assert s.extra["exp:pc_template"].tolist() == [0, 1, 0]
    texts = reference_texts(s)
    assert texts["goal_list.txt"] == savetxt([2, 0])
    assert texts["experiences.txt"].endswith("12.5\n0\n2\n-\n2\n1\n")
    assert texts["posecellexperiences.txt"].endswith("6.9\n0\n-\n2\n0\n")
    assert texts["posecellvisual_templates.txt"].endswith("-\n1\n\n")
    assert math.isclose(s.exp_pose[2, 0], -0.9)


def test_random_corruptions_give_only_located_map_format_errors(tmp_path):
    """Lines replaced, inserted or deleted, bytes flipped, files cut: the reader either
    reads a valid map or raises one MapFormatError line, never anything else."""
    import random

    rng = random.Random(13)
    tokens = ["", "-", "[[1]]", "1e400", "nan", "-inf", "-1", "1e300", "0.5", "a b", "9" * 30]
    tokens += ["[0,'a']", "1 2 3", "\x00", "2", "1.0"]
    outcomes = set()
    for it in range(150):
        files = dict(HAND)
        for _ in range(rng.randint(1, 3)):
            name = rng.choice(sorted(files))
            lines = files[name].split("\n")
            i, op = rng.randrange(len(lines)), rng.random()
            if op < 0.5:
                lines[i] = rng.choice(tokens)
            elif op < 0.7:
                del lines[i]
            elif op < 0.9:
                lines.insert(i, rng.choice(tokens))
            else:
                lines = "\n".join(lines)[: rng.randrange(len(files[name]) + 1)].split("\n")
            files[name] = "\n".join(lines)
        d = write_hand(tmp_path / f"m{it}", files)
        try:
            read_reference(d, CFG)
            outcomes.add("read")
        except MapFormatError as exc:
            assert "\n" not in str(exc) and str(d) in str(exc), str(exc)
            outcomes.add("error")
    assert outcomes == {"read", "error"}
