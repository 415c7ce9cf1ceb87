"""Kept for imports written before the writer moved: the project's one atomic writer is
:mod:`ratslam_graph.atomic`."""

from ratslam_graph.atomic import write_directory_atomically

__all__ = ["write_directory_atomically"]
