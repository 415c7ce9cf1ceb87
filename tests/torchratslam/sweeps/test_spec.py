"""Sweep files: expansion order and counts, value ranges, stable ids, bad input."""

import itertools

import pytest

from torchratslam.errors import ConfigError, InputError
from torchratslam.sweeps.spec import from_dict, load_sweep, parse_values, with_seed


def test_grid_expands_every_combination_in_order():
    raw = {
        "base": "virtual_tour",
        "parameters": {"vt_match_threshold": [0.03, 0.05], "exp_loops": [5, 10, 20]},
        "datasets": ["sim:loop?laps=1", {"data": "sim:lab_tour", "max_frames": 7}],
        "max_frames": 11,
        "seeds": [0, 3],
        "backends": ["alpha", "gtsam"],
    }
    runs = from_dict(raw).runs()
    expected = [
        (ds, seed, be, th, loops)
        for ds, seed, be, th, loops in itertools.product(
            ["sim:loop?laps=1", "sim:lab_tour"],
            [0, 3],
            ["alpha", "gtsam"],
            [0.03, 0.05],
            [5, 10, 20],
        )
    ]
    assert len(runs) == len(expected) == 48
    for i, (run, (ds, seed, be, th, loops)) in enumerate(zip(runs, expected)):
        assert run.index == i
        assert (run.dataset, run.seed, run.backend) == (ds, seed, be)
        assert run.params == {"vt_match_threshold": th, "exp_loops": loops}
        assert run.max_frames == (7 if ds == "sim:lab_tour" else 11)
        assert run.data == with_seed(ds, seed)
        cfg = run.config()
        assert cfg.local_view.vt_match_threshold == th
        assert cfg.experience_map.exp_loops == loops
        assert cfg.experience_map.exp_backend == be
    assert len({r.run_id for r in runs}) == 48
    # the same file gives the same ids
    assert [r.run_id for r in from_dict(raw).runs()] == [r.run_id for r in runs]


def test_list_mode_zips_values():
    runs = from_dict(
        {"mode": "list", "parameters": {"exp_loops": [1, 2, 3], "exp_correction": [0.1, 0.2, 0.3]}}
    ).runs()
    assert [r.params for r in runs] == [
        {"exp_loops": a, "exp_correction": b} for a, b in [(1, 0.1), (2, 0.2), (3, 0.3)]
    ]
    with pytest.raises(ConfigError, match="equally long"):
        from_dict({"mode": "list", "parameters": {"exp_loops": [1, 2], "exp_correction": [0.1]}})


def test_value_ranges():
    assert parse_values("k", {"start": 0.1, "stop": 0.4, "num": 4}) == [0.1, 0.2, 0.3, 0.4]
    assert parse_values("k", {"start": 10, "stop": 40, "num": 4}) == [10, 20, 30, 40]
    logs = parse_values("k", {"start": 0.01, "stop": 1.0, "num": 3, "log": True})
    assert logs == pytest.approx([0.01, 0.1, 1.0])
    assert parse_values("k", {"values": [1, 2]}) == [1, 2]
    assert parse_values("k", 5) == [5]
    with pytest.raises(ConfigError, match="empty"):
        parse_values("k", [])
    with pytest.raises(ConfigError, match="missing"):
        parse_values("k", {"start": 1})


def test_seed_goes_to_simulator_specs_only():
    assert with_seed("sim:loop", 4) == "sim:loop?seed=4"
    assert with_seed("sim:loop?laps=1", 4) == "sim:loop?laps=1&seed=4"
    assert with_seed("data/lab", 4) == "data/lab"


@pytest.mark.parametrize(
    "raw, match",
    [
        ({"parameters": {"vt_match_thresold": [0.1]}}, "vt_match_threshold"),
        ({"parameters": {"exp_loops": [-1]}}, "exp_loops"),
        ({"backends": ["nope"]}, "backend"),
        ({"seeds": ["a"]}, "seeds"),
        ({"colour": 1}, "unknown key"),
        ({"max_frames": 0}, "max_frames"),
    ],
)
def test_bad_sweeps_are_one_clear_error(raw, match):
    with pytest.raises(ConfigError, match=match):
        from_dict(raw)


def test_load_sweep_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_sweep(tmp_path / "missing.yaml")
    p = tmp_path / "s.yaml"
    p.write_text("parameters: {exp_loops: [1, 2]}\ndatasets: [sim:loop]\nmax_frames: 5\n")
    runs = load_sweep(p).runs()
    assert [r.params["exp_loops"] for r in runs] == [1, 2] and runs[0].max_frames == 5
    p.write_text("parameters: [\n")
    with pytest.raises(ConfigError, match="YAML"):
        load_sweep(p)


def test_example_sweep_file_is_valid():
    root = __import__("pathlib").Path(__file__).resolve().parents[3]
    runs = load_sweep(root / "examples" / "sweep_loop.yaml").runs()
    assert len(runs) == 3 * 4 * 2
