"""Every ``torchratslam ...`` command of README.md runs as written.

The commands are taken from README.md's fenced blocks and inline code, in order, and run
in one scratch folder (so ``out/s1`` written by one command is read by the next). They run
as written, with two documented exceptions, both listed here:

* ``SMALL``: a mapping command (``run``) gets ``--max-frames`` so that the suite stays
  fast; the data, config and every other option are the README's;
* ``run --resume OUT``: the README says it continues a stopped run, so the command before
  it that wrote OUT is stopped at frame ``STOP_AT`` by a real SIGINT (Ctrl-C) first.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
from pathlib import Path

import pytest

from torchratslam.cli import main

README = Path(__file__).resolve().parent.parent / "README.md"

SMALL = {"run": ["--max-frames", "40"]}
"""Options appended to a command of this subcommand (a long run made short)."""
STOP_AT = 25
"""The frame at which the run before a ``run --resume`` of its OUT is stopped."""


def readme_commands(text: str) -> list[str]:
    """The ``torchratslam ...`` commands of a markdown text, in order: lines of fenced
    blocks (with ``\\`` continuations joined, ``#`` comments dropped) and inline code."""
    found: list[tuple[int, str]] = []
    fences = list(re.finditer(r"```[^\n]*\n(.*?)```", text, re.S))
    for m in fences:
        block = m.group(1).replace("\\\n", " ")
        for line in block.splitlines():
            line = " ".join(line.split("  #")[0].split())
            if line.startswith("torchratslam "):
                found.append((m.start(), line))
    outside = text
    for m in reversed(fences):
        outside = outside[: m.start()] + " " * (m.end() - m.start()) + outside[m.end() :]
    for m in re.finditer(r"`(torchratslam [^`]+)`", outside):
        found.append((m.start(), m.group(1).strip()))
    return [c for _, c in sorted(found)]


def test_the_extraction_finds_fenced_and_inline_commands():
    text = (
        "Try `torchratslam --help`.\n```bash\ntorchratslam run --config a \\\n"
        "  --data b --out c   # a comment\nmake demo\n```\nand `pip install x`.\n"
    )
    assert readme_commands(text) == [
        "torchratslam --help",
        "torchratslam run --config a --data b --out c",
    ]


class _Stopping:
    """A reader that sends this process a real SIGINT when frame ``at`` is read."""

    def __init__(self, data, at):
        self.data, self.at = data, at

    def __getattr__(self, name):
        return getattr(self.data, name)

    def __len__(self):
        return len(self.data)

    def frames(self):
        for k, f in enumerate(self.data.frames()):
            if k == self.at:
                os.kill(os.getpid(), signal.SIGINT)
            yield f


def _out_of(argv: list[str]) -> str | None:
    return argv[argv.index("--out") + 1] if "--out" in argv else None


@pytest.mark.slow
def test_every_readme_command_runs_as_written(tmp_path, monkeypatch, capsys):
    from torchratslam.readers import datasets

    commands = [shlex.split(c)[1:] for c in readme_commands(README.read_text())]
    assert len(commands) >= 4, commands  # the README shows how to run, load and resume
    resumed = {a[a.index("--resume") + 1] for a in commands if "--resume" in a}
    monkeypatch.chdir(tmp_path)
    real_open = datasets.open_data
    for argv in commands:
        sub = next((a for a in argv if not a.startswith("-")), None)
        if "--resume" not in argv and "--help" not in argv:
            argv = [*argv, *SMALL.get(sub or "", [])]
        stop = sub == "run" and _out_of(argv) in resumed
        if stop:
            monkeypatch.setattr(
                datasets, "open_data", lambda *a, **k: _Stopping(real_open(*a, **k), STOP_AT)
            )
        try:
            code = main(argv)
        except SystemExit as exc:  # --help
            code = int(exc.code or 0)
        finally:
            monkeypatch.setattr(datasets, "open_data", real_open)
        err = capsys.readouterr().err
        if stop:
            assert code == 130 and f"stopped at frame {STOP_AT}" in err, (argv, err)
        else:
            assert code == 0, (argv, err)
