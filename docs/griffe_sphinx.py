"""A griffe extension for the API reference: the docstrings' Sphinx habits, in Markdown.

* ``:class:`~torchratslam.pipeline.RatSLAM``` (any role) becomes ``RatSLAM`` as code
  (the full dotted name without ``~``), as Sphinx would show it;
* ``Example:`` (singular) becomes ``Examples:``, so doctest lines render as code.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|meth|func|mod|attr|data|exc|obj|const):`(~?)([^`]+)`")
_EXAMPLE = re.compile(r"^(\s*)Example:\s*$", re.MULTILINE)


def _role(m: re.Match[str]) -> str:
    name = m.group(2)
    if m.group(1):
        name = name.rsplit(".", 1)[-1]
    return f"`{name}`"


def markdown(text: str) -> str:
    """The docstring with Sphinx roles and ``Example:`` rewritten."""
    return _EXAMPLE.sub(r"\1Examples:", _ROLE.sub(_role, text))


class SphinxToMarkdown(griffe.Extension):
    """Rewrites every object's docstring with :func:`markdown` before it is parsed."""

    def on_object(self, *, obj: Any, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown(obj.docstring.value)
