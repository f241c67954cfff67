"""check_finite (clfza.solvers._driver): the one-pass sum decides finite images; NaN, +-inf
anywhere, and finite values whose sum overflows are decided as the value-by-value test decides
them."""

from __future__ import annotations

import numpy as np
import pytest

from clfza.errors import ClfzaError
from clfza.solvers._driver import check_finite


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_check_finite_agrees_with_isfinite(dtype):
    rng = np.random.default_rng(4)
    img = rng.standard_normal((3, 17, 19)).astype(dtype)
    assert check_finite("admm", img, 0.1) is img
    for bad in (np.nan, np.inf, -np.inf):
        for idx in ((0, 0, 0), (2, 16, 18), (1, 8, 3)):
            b = img.copy()
            b[idx] = bad
            with pytest.raises(ClfzaError, match="non-finite"):
                check_finite("admm", b, 0.1)
    b = img.copy()
    b[0, 0, 0], b[1, 1, 1] = np.inf, -np.inf  # the sum: NaN
    with pytest.raises(ClfzaError, match="non-finite"):
        check_finite("admm", b, 0.1)
    # finite values whose sum overflows: finite
    big = np.full((4, 4), np.finfo(dtype).max, dtype)
    assert check_finite("admm", big, 0.1) is big
    ints = np.arange(12).reshape(3, 4)
    assert check_finite("admm", ints, 0.1) is ints
