"""mkdocs hooks: the Notebooks section of the nav lists every notebook in notebooks/.

A notebook added to ``notebooks/`` (numbered ``NN_name.ipynb``) appears in the site
without editing ``mkdocs.yml``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def on_config(config: Any, **kwargs: Any) -> Any:
    docs = Path(config["docs_dir"])
    books = sorted((docs / "notebooks").glob("[0-9]*.ipynb"))
    entries = []
    for nb in books:
        number, _, rest = nb.stem.partition("_")
        entries.append({f"{number} {rest.replace('_', ' ')}": f"notebooks/{nb.name}"})
    for item in config["nav"] or []:
        if isinstance(item, dict) and "Notebooks" in item:
            item["Notebooks"] = entries
    return config
