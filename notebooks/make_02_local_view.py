"""Generate notebooks/02_local_view.ipynb (run: python notebooks/make_02_local_view.py)."""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

CELLS = [
    (
        "md",
        """# Local view cells

The local view turns each camera frame into a small template (crop, grey, block
averaging, optional normalisation) and compares it, by mean absolute difference (MAD)
at every column offset, with every stored template. Below the threshold the view is
*familiar* (template id, offset, relative angle); above it a new template is learnt.

The frames here are synthetic 256x64 panoramas along a route
(`torchratslam.sim.views.ViewRoute`, also used by `benchmarks/bench_local_view.py`), so
the notebook runs without a dataset.""",
    ),
    (
        "code",
        """import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch

from torchratslam.config import LocalViewParams
from torchratslam.local_view.view import LocalView
from torchratslam.sim.views import ViewRoute

params = LocalViewParams(
    template_x_size=64, template_y_size=16, vt_panoramic=True, vt_step_match=1,
    vt_match_threshold=0.03,
)
route = ViewRoute(60.0, 16, 64, seed=3)


def image_at(position, turn=0, noise=0.005, seed=0):
    \"\"\"A 256x64 uint8 panorama at a route position, the camera turned by `turn` columns.\"\"\"
    g = torch.Generator().manual_seed(seed)
    v = torch.roll(route.views(torch.tensor([position]))[0], -turn, -1)
    v = (v + noise * torch.randn(v.shape, generator=g)).clamp(0, 1).numpy()
    return (np.kron(v, np.ones((4, 4))) * 255).astype(np.uint8)""",
    ),
    ("md", "## A few frames and their templates"),
    (
        "code",
        """lv = LocalView(params)
positions = np.arange(0.0, 40.0, 0.25)
matches = [lv.process(image_at(p, seed=i), frame_index=i) for i, p in enumerate(positions)]
print(f"{len(positions)} frames, {len(lv)} templates learnt")

fig, axes = plt.subplots(3, 2, figsize=(10, 4.5))
for row, i in zip(axes, (0, 40, 120)):
    row[0].imshow(image_at(positions[i], seed=i), cmap="gray", vmin=0, vmax=255)
    row[0].set_title(f"frame {i} (256x64)", fontsize=9)
    row[1].imshow(lv.preprocess(image_at(positions[i], seed=i)), cmap="gray", vmin=0, vmax=1)
    m = matches[i]
    row[1].set_title(f"template 64x16 -> id {m.template_id}, new={m.is_new}", fontsize=9)
    for ax in row:
        ax.set_xticks([])
        ax.set_yticks([])
fig.tight_layout()""",
    ),
    ("md", "## Match error over offsets: a familiar view and a novel one"),
    (
        "code",
        """familiar = lv.preprocess(image_at(20.1, turn=10, seed=99))  # revisited, turned
novel = lv.preprocess(image_at(55.0, seed=98))  # a place never seen
fam = lv.match(familiar)
nov = lv.match(novel)
print(f"familiar: template {fam[0]}, offset {fam[1]}, MAD {fam[2]:.4f}")
print(f"novel:    best template {nov[0]}, offset {nov[1]}, MAD {nov[2]:.4f}")
print(f"familiar relative angle: {lv.relative_rad(fam[1]):.3f} rad")

offsets = lv.offsets.numpy()
fig, ax = plt.subplots(figsize=(8, 3))
ax.plot(offsets, lv.errors(familiar, [fam[0]])[0].numpy(), label=f"familiar vs template {fam[0]}")
ax.plot(offsets, lv.errors(novel, [nov[0]])[0].numpy(), label=f"novel vs template {nov[0]}")
ax.axhline(params.vt_match_threshold, color="k", ls="--", lw=1, label="vt_match_threshold")
ax.set_xlabel("offset (columns)")
ax.set_ylabel("mean absolute difference")
ax.legend(fontsize=8)
fig.tight_layout()
assert fam[2] <= params.vt_match_threshold < nov[2]""",
    ),
    (
        "code",
        """out = os.environ.get("TORCHRATSLAM_NOTEBOOK_OUT")
if out:
    fig.savefig(Path(out) / "local_view_offsets.png", dpi=80)""",
    ),
]


def main() -> None:
    nb = new_notebook()
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    for kind, text in CELLS:
        nb.cells.append(new_markdown_cell(text) if kind == "md" else new_code_cell(text))
    path = Path(__file__).resolve().parent / "02_local_view.ipynb"
    nbformat.write(nb, path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
