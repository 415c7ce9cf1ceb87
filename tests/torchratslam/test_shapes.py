"""check_shape: named axes, fixed sizes, wildcards, and one-line errors."""

import numpy as np
import pytest
import torch

from torchratslam.errors import InputError, RatSLAMError
from torchratslam.shapes import check_shape


def test_named_axes_return_their_sizes():
    x = torch.zeros(2, 36, 21, 21)
    assert check_shape(x, "B TH Y X", name="activity") == {"B": 2, "TH": 36, "Y": 21, "X": 21}
    assert check_shape(x, ("B", 36, None, "X")) == {"B": 2, "X": 21}
    assert check_shape(np.zeros((5, 3)), "_ 3") == {}
    assert check_shape(np.zeros((5, 3)), (None, 3)) == {}
    assert check_shape(np.zeros(4), (4,)) == {}
    assert check_shape(np.zeros((4, 4)), "N N") == {"N": 4}
    assert check_shape(np.zeros(()), ()) == {}


@pytest.mark.parametrize(
    ("x", "spec", "pattern"),
    [
        (np.zeros((5, 4)), (None, 3), r"^odo: expected shape \(_, 3\), got \(5, 4\) \(axis 1"),
        (np.zeros(3), "B TH Y X", r"^odo: expected shape \(B, TH, Y, X\), got \(3,\) \(1 axes\)"),
        (np.zeros(3), (2,), r"^odo: expected shape \(2,\), got \(3,\)"),
        (np.zeros((3, 4)), "N N", r"axes named N have sizes 3 and 4"),
        ([1.0, 2.0], (2,), r"^odo: expected an array of shape \(2,\), got list"),
    ],
)
def test_a_mismatch_is_one_clear_input_error(x, spec, pattern):
    with pytest.raises(InputError, match=pattern) as err:
        check_shape(x, spec, name="odo")
    assert isinstance(err.value, RatSLAMError)
    assert "\n" not in str(err.value)


def test_every_size_is_checked_against_a_brute_force_comparison():
    rng = np.random.default_rng(0)
    for _ in range(200):
        shape = tuple(int(v) for v in rng.integers(1, 4, size=int(rng.integers(0, 4))))
        spec = tuple(int(v) for v in rng.integers(1, 4, size=int(rng.integers(0, 4))))
        ok = shape == spec
        if ok:
            assert check_shape(np.zeros(shape), spec) == {}
        else:
            with pytest.raises(InputError):
                check_shape(np.zeros(shape), spec)


def test_a_bad_spec_entry_is_a_type_error():
    with pytest.raises(TypeError, match="shape spec"):
        check_shape(np.zeros(3), (1.5,))  # type: ignore[arg-type]
