"""torchratslam: RatSLAM in PyTorch.

The torch front end (local view, pose cells, pipeline, readers, simulator, evaluation,
plots, CLI). The experience map and pose-graph backends live in the torch-free
``graph`` package.
"""

import logging

from torchratslam.config import RatSLAMConfig, load_config
from torchratslam.errors import ConfigError, InputError, MapFormatError, RatSLAMError

__version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
    "ConfigError",
    "InputError",
    "MapFormatError",
    "RatSLAM",
    "RatSLAMConfig",
    "RatSLAMError",
    "__version__",
    "load_config",
    "sweep",
    "tune",
]


def __getattr__(name: str):
    # Heavy modules load on first use, so ``import torchratslam`` stays cheap.
    if name == "RatSLAM":
        from torchratslam.pipeline import RatSLAM

        return RatSLAM
    if name in ("sweep", "tune"):  # parameter sweeps and Optuna studies
        from torchratslam import sweeps

        return getattr(sweeps, name)
    raise AttributeError(f"module 'torchratslam' has no attribute {name!r}")
