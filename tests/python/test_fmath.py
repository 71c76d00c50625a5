"""The portable exp and tanh: accurate, and built so C can repeat them bit for bit."""
import numpy as np
import pytest

from reference_py.fmath import F32, F64


def _ulps(a, b, itype):
    return np.abs(a.view(itype).astype(np.int64) - b.view(itype).astype(np.int64))


@pytest.mark.parametrize("R,itype,max_ulp", [(F64, np.int64, 2), (F32, np.int32, 4)])
def test_exp_accuracy(R, itype, max_ulp):
    x = R.arr(np.linspace(-60.0, 60.0, 400001))
    got = R.exp(x)
    ref = np.exp(x.astype(np.float64)).astype(R.dtype)
    assert got.dtype == R.dtype
    assert _ulps(got, ref, itype).max() <= max_ulp


@pytest.mark.parametrize("R", [F64, F32])
def test_exp_special_points_and_clamp(R):
    assert R.exp(R.arr([0.0]))[0] == 1.0
    big = R.exp(R.arr([1e6, -1e6]))
    assert np.all(np.isfinite(big)) and big[0] > 1e30 and 0.0 < big[1] < 1e-30


@pytest.mark.parametrize("R", [F64, F32])
def test_tanh(R):
    x = R.arr(np.linspace(-40.0, 40.0, 100001))
    t = R.tanh(x)
    assert t.dtype == R.dtype
    assert np.max(np.abs(t.astype(np.float64) - np.tanh(x.astype(np.float64)))) < (
        4e-7 if R is F32 else 1e-15)
    assert np.array_equal(t, -R.tanh(-x))        # odd, exactly
    assert R.tanh(R.arr([25.0]))[0] == 1.0 and R.tanh(R.arr([0.0]))[0] == 0.0


def test_float32_path_never_promotes():
    x = F32.arr([0.3, -2.0, 11.0])
    assert F32.exp(x).dtype == np.float32 and F32.tanh(x).dtype == np.float32
