"""What surrounds a run: the frames from what the caller gave, progress and callback, and
the garbage collector parked for the run."""

import gc

import numpy as np
import pytest

from torchratslam.errors import InputError
from torchratslam.messages import Frame
from torchratslam.pipeline.runner import RunProgress, open_frames, parked_gc


class Source:
    """A reader that says it has no odometry."""

    has_odometry = False
    name = "silent-reader"

    def __init__(self, n):
        self.n = n

    def __len__(self):
        return self.n

    def frames(self):
        return (Frame(k, float(k), np.zeros((2, 2), np.uint8)) for k in range(self.n))


def test_open_frames_takes_sources_iterables_and_specs():
    source = Source(5)
    data, it, total = open_frames(source, 3)
    assert data is source and [f.index for f in it] == [0, 1, 2] and total == 3
    _, it, total = open_frames(Source(2), 9)
    assert len(list(it)) == 2 and total == 2
    _, it, total = open_frames(iter([Frame(7, 0.0, None)]))
    assert [f.index for f in it] == [7] and total is None
    _, it, total = open_frames((Frame(k, 0.0, None) for k in range(10)), 4)
    assert len(list(it)) == 4 and total == 4
    data, it, total = open_frames("sim:loop", 2)
    assert [f.index for f in it] == [0, 1] and total == 2 and hasattr(data, "groundtruth")


def test_open_frames_refuses_what_it_cannot_read():
    with pytest.raises(InputError, match="got a float; it expects a data spec"):
        open_frames(1.5)
    with pytest.raises(InputError, match="max_frames must be >= 0, got -2"):
        open_frames(Source(3), -2)


def test_run_progress_counts_and_calls_back():
    seen = []
    report = RunProgress(3, show=False, callback=seen.append)
    for r in ("a", "b", "c"):
        report(r)
    report.close()
    assert report.n == 3 and seen == ["a", "b", "c"]


def test_parked_gc_freezes_only_for_the_duration():
    if not gc.isenabled() or gc.get_freeze_count():
        pytest.skip("the collector is off or objects are already frozen")
    with parked_gc():
        assert gc.get_freeze_count() > 0
    assert gc.get_freeze_count() == 0
    with pytest.raises(RuntimeError), parked_gc():
        raise RuntimeError
    assert gc.get_freeze_count() == 0


def test_a_plain_run_prints_nothing_a_bar_only_when_asked_or_in_a_notebook(capsys, monkeypatch):
    import sys
    import types

    from torchratslam import RatSLAM, load_config
    from torchratslam.pipeline.runner import in_notebook, show_progress

    config = load_config("virtual_tour", pc_dim_xy=11, template_x_size=16, template_y_size=4)
    frames = [Frame(k, float(k), np.full((4, 16), k, np.uint8), vtrans=0.1) for k in range(6)]
    capsys.readouterr()
    RatSLAM(config).run(frames)  # import and run: no bar
    out = capsys.readouterr()
    assert out.err == "" and out.out == ""
    RatSLAM(config).run(frames, progress="mapping part 1/2")  # asked: one labelled bar
    err = capsys.readouterr().err
    assert "mapping part 1/2" in err and "6/6" in err
    assert show_progress(True) == "frames" and show_progress(False) is None
    # an IPython kernel (a notebook) shows the bar by default; a terminal IPython does not
    shell = types.SimpleNamespace(config={})
    fake = types.ModuleType("IPython")
    fake.get_ipython = lambda: shell  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "IPython", fake)
    assert not in_notebook() and show_progress(None) is None
    shell.config = {"IPKernelApp": {"connection_file": "x.json"}}
    assert in_notebook() and show_progress(None) == "frames"
