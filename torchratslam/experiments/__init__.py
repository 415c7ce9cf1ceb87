"""Experiment runners: the demo and the tour experiments behind the CLI.

Never imported by the library.
"""

__all__: list[str] = []
