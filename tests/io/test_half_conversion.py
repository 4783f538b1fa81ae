"""The loader's float32 -> float16 conversion (native/cpu/half.h, software so that Clang 14 builds it): equal to the
F16C instruction on all 2^32 float bit patterns (NaNs included, ~3 s on two cores), and to numpy's astype(float16)
on every non-NaN pattern of a stride through them plus the rounding edges."""

from __future__ import annotations

import numpy as np
import pytest

from gbviewer import _native


def test_equal_to_f16c_on_every_float():
    bad = _native.testing.half_mismatches(0, 2**32)
    if bad == -1:
        pytest.skip("this CPU has no F16C (or is not x86-64)")
    assert bad == 0


def test_equal_to_numpy_through_the_loader():
    bits = np.concatenate(
        [
            np.arange(0, 2**32, 65537, dtype=np.uint64).astype(np.uint32),
            np.array(
                [
                    0x477FEFFF,
                    0x477FF000,
                    0x33000000,
                    0x33000001,
                    0x387FFFFF,
                    0x38800000,
                    0x38FFF000,
                    0x37FFE000,
                    0x7F800000,
                ],
                np.uint32,
            ),
        ]
    )
    values = bits.view(np.float32)
    values = np.concatenate([values, -values])
    values = values[np.isfinite(values)]  # the loader drops non-finite rows; its range check drops |v| > max_sh
    rows = len(values)
    table = np.zeros((rows, 17), np.float32)
    table[:, 3] = values  # f_dc_0; the quaternion (columns 10-13) the identity
    table[:, 10] = 1.0
    sh = np.zeros((rows, 1, 3), np.float16)
    out = [np.zeros(rows * n, np.float32) for n in (3, 3, 4, 1)]
    keep = np.zeros(rows, np.uint8)
    cols = np.arange(14, dtype=np.int32)
    _native.io.scatter_inria(table, cols, *out, sh, None, None, keep, float("inf"))
    with np.errstate(over="ignore"):  # 65520 and above become infinity, as they should
        expected = values.astype(np.float16)
    np.testing.assert_array_equal(sh[:, 0, 0].view(np.uint16), expected.view(np.uint16))
