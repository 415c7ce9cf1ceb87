"""A run's recorded options survive run.json: written, read back, the same options."""

from __future__ import annotations

import json
from dataclasses import asdict, fields

from torchratslam.experiments.run_options import RunOptions
from torchratslam.experiments.run_state import RunRecord, json_default


def test_options_round_trip_through_the_record():
    opts = RunOptions(
        config="/c.yaml",
        data="sim:loop",
        overrides={"exp_loops": "3"},
        max_frames=9,
        load=("/a/state", "/b/state"),
        max_speed=2.5,
        tum=True,
        rerun_save="x.rrd",
    )
    text = json.dumps(RunRecord(opts, {"k": 1}).to_json(), indent=1, default=json_default)
    record = json.loads(text)
    assert list(record) == ["format", "version", "run_id", "finished", "options", "config_flat"]
    assert list(record["options"]) == [f.name for f in fields(RunOptions)]
    assert record["options"]["load"] == ["/a/state", "/b/state"]
    assert RunOptions.from_record(record["options"]) == opts


def test_a_record_missing_later_keys_takes_the_defaults():
    full = asdict(RunOptions(config="c", data="d"))
    short = {k: v for k, v in full.items() if k not in ("max_speed", "tum", "rerun", "rerun_save")}
    assert RunOptions.from_record(short) == RunOptions(config="c", data="d")
