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

The frames here are synthetic 256x64 panoramas along a route (the generator of the
local-view benchmark, defined below), so the notebook runs without a dataset.""",
    ),
    (
        "code",
        """import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
import torch.nn.functional as F

from torchratslam.config import LocalViewParams
from torchratslam.local_view.view import LocalView


def smooth(x, sy, sx):
    \"\"\"Gaussian blur of (N, Y, X): circular along X, replicated along Y.\"\"\"

    def kernel(s):
        r = int(3 * s) + 1
        g = torch.exp(-(torch.arange(-r, r + 1, dtype=x.dtype) ** 2) / (2 * s * s))
        return g / g.sum(), r

    (gx, rx), (gy, ry) = kernel(sx), kernel(sy)
    n, y, w = x.shape
    x = torch.cat([x[..., -rx:], x, x[..., :rx]], -1)
    x = F.conv1d(x.reshape(-1, 1, x.shape[-1]), gx[None, None]).reshape(n, y, w)
    x = F.pad(x.transpose(1, 2).reshape(-1, 1, y), (ry, ry), mode="replicate")
    return F.conv1d(x, gy[None, None]).reshape(n, w, y).transpose(1, 2)


class Route:
    \"\"\"Smooth random panoramas along a 1D route (the local-view benchmark's generator).\"\"\"

    def __init__(self, length, y, x, *, knot=4.0, seed=0):
        g = torch.Generator().manual_seed(seed)
        self.knot = knot
        base = smooth(torch.randn(int(length / knot) + 3, y, x, generator=g), y / 8, x / 32)
        self.base = base / base.std() * 0.15
        self.grad = torch.linspace(0.75, 0.3, y)[:, None]

    def views(self, p):
        p = torch.as_tensor(p, dtype=torch.float32)
        j = (p / self.knot).floor().long()
        a = (p / self.knot - j)[:, None, None]
        return ((1 - a) * self.base[j] + a * self.base[j + 1] + self.grad).clamp(0, 1)


params = LocalViewParams(
    template_x_size=64, template_y_size=16, vt_panoramic=True, vt_step_match=1,
    vt_match_threshold=0.03,
)
route = Route(60.0, 16, 64, seed=3)


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
