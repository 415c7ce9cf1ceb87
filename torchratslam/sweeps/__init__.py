"""Parameter sweeps and automatic tuning.

* :func:`sweep` -- every combination of a sweep file (parameters x datasets x seeds x
  backends) -> one results table (CSV, Parquet with pyarrow) and figures; locally with a
  process pool, or on Ray (``ray=True`` / ``ray_address=``).
* :func:`tune` -- an Optuna study that searches parameters within ranges to minimise a
  metric (ATE by default), with a shared storage so several workers join one study.

Runs whose configs differ only in pose-cell module parameters (and experience-map
parameters) share one batched pose-cell network (:func:`runner.run_group`).
"""

from torchratslam.sweeps.spec import RunSpec, SweepSpec, expand, load_sweep
from torchratslam.sweeps.sweep import sweep
from torchratslam.sweeps.tune import tune

__all__ = ["RunSpec", "SweepSpec", "expand", "load_sweep", "sweep", "tune"]
