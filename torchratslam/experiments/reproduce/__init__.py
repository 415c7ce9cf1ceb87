"""``torchratslam reproduce``: every experiment of the four papers, one command each.

Each experiment is an :class:`Experiment` (an id such as ``"multisession/virtual-tour"``,
the paper, a title and a function that runs it and returns a :class:`Report`); the
catalogue (:mod:`.catalogue`) lists them in one static place. A report holds rows of
the paper's number beside ours, the figures written, and what differs and why;
:func:`~.report.write_report` writes ``report.json`` and ``report.md``.
"""

from torchratslam.experiments.reproduce.report import (
    Experiment,
    ExperimentContext,
    Report,
    Row,
    write_report,
)

__all__ = ["Experiment", "ExperimentContext", "Report", "Row", "write_report"]
