"""The project's exception hierarchy.

Every error the library raises on purpose derives from :class:`RatSLAMError`, so a
caller (the CLI in particular) can catch one root class and print a one-line message.
The root lives in ``graph`` because ``graph`` is the bottom layer: ``torchratslam``
imports it, never the other way round.

A message that names an option names it for both callers with :func:`option`: the
command line's flag and the Python argument. ``str(error)`` (what a Python caller sees)
shows the argument; :meth:`RatSLAMError.cli_message` (what the command line prints)
shows the flag. Neither sees the other's spelling.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable

_OPTION = re.compile(r"\[\[([^|\]]*)\|([^\]]*)\]\]")


def option(flag: str, argument: str) -> str:
    """An option named in an error message for both callers: ``flag`` on the command
    line (``"--overwrite"``), ``argument`` in Python (``"overwrite=True"``)."""
    return f"[[{flag}|{argument}]]"


def for_python(text: str) -> str:
    """``text`` with every :func:`option` as its Python argument."""
    return _OPTION.sub(r"\2", text)


def for_cli(text: str) -> str:
    """``text`` with every :func:`option` as its command-line flag."""
    return _OPTION.sub(r"\1", text)


class RatSLAMError(Exception):
    """Root of every error raised deliberately by graph and torchratslam.

    ``str()`` names options as Python arguments, :meth:`cli_message` as flags (see
    :func:`option`)."""

    def __str__(self) -> str:
        return for_python(super().__str__())

    def cli_message(self) -> str:
        """The message as the command line prints it: options named by their flags."""
        return for_cli(super().__str__())


class ConfigError(RatSLAMError, ValueError):
    """A parameter is unknown, of the wrong type, or out of range."""


class InputError(RatSLAMError, ValueError):
    """Input data (images, odometry, files) is missing, malformed or inconsistent."""


class MapFormatError(RatSLAMError, ValueError):
    """A saved map or pose-graph file is corrupt, truncated, of an unknown version,
    or incompatible with the configuration it is used with."""


class GraphError(RatSLAMError):
    """The experience graph or a pose-graph backend cannot do what was asked."""


def nearest(name: str, candidates: Iterable[str]) -> str | None:
    """Return the candidate closest to ``name`` (for 'did you mean' hints), or None."""
    matches = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.5)
    return matches[0] if matches else None


def unknown_name_message(kind: str, name: str, candidates: Iterable[str]) -> str:
    """One-line message for an unknown key or registry name, with the nearest valid one."""
    candidates = sorted(candidates)
    guess = nearest(name, candidates)
    hint = f"; did you mean {guess!r}?" if guess else ""
    if guess and len(candidates) > 12:  # a long list adds noise once there is a good guess
        return f"unknown {kind} {name!r}{hint}"
    return f"unknown {kind} {name!r}{hint} (valid: {', '.join(candidates)})"
