"""Test-suite settings shared by every test module."""

import matplotlib
import pytest
import torch

matplotlib.use("Agg")


@pytest.fixture(autouse=True, scope="session")
def _one_torch_thread():
    """One intra-op thread: on a busy 2-core machine torch's default pool makes small
    pose-cell steps 100x slower, and results must not depend on the thread count."""
    torch.set_num_threads(1)
    yield
