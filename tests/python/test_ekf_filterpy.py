"""One predict/update of our EKF kernels equals filterpy's ExtendedKalmanFilter (independent)."""
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from reference_py.ekf import joseph_update, predict_covariance
from reference_py.fmath import F64


def _random_case(rng, n):
    a = rng.normal(size=(n, n))
    P = a @ a.T + n * np.eye(n) * 0.1
    F = np.eye(n)
    F[0, :] = rng.normal(size=n)
    F[0, 0] = rng.uniform(0.5, 1.0)
    Q = np.diag(rng.uniform(1e-6, 1e-2, size=n))
    H = rng.normal(size=(1, n))
    R = rng.uniform(1e-3, 1.0)
    x = rng.normal(size=n)
    z = float((H @ (F @ x))[0]) + rng.normal(scale=0.3)
    return x, P, F, Q, H, R, z


def _ours(x, P, F, Q, H, R, z, gate2=1e30, step=None):
    n = len(x)
    col = lambda v: F64.arr([v])  # noqa: E731
    Pm = [[col(P[i, j]) for j in range(n)] for i in range(n)]
    Pp = predict_covariance(Pm, [col(F[0, j]) for j in range(n)], [col(Q[i, i]) for i in range(n)])
    xp = F @ x
    innov = col(z - float((H @ xp)[0]))
    upd = joseph_update(F64, [col(v) for v in xp], Pp, [col(h) for h in H[0]], innov, col(R),
                        col(gate2), step=None if step is None else col(step))
    return (np.array([v[0] for v in upd.x]),
            np.array([[upd.P[i][j][0] for j in range(n)] for i in range(n)]), upd)


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("n", (1, 2, 3, 4))
def test_matches_filterpy(seed, n):
    rng = np.random.default_rng(seed * 10 + n)
    x, P, F, Q, H, R, z = _random_case(rng, n)
    kf = ExtendedKalmanFilter(dim_x=n, dim_z=1)
    kf.x = x.reshape(n, 1).copy()
    kf.P = P.copy()
    kf.F = F.copy()
    kf.Q = Q.copy()
    kf.R = np.array([[R]])
    kf.predict()
    kf.update(np.array([z]), HJacobian=lambda _x: H, Hx=lambda xx: H @ xx)
    ours_x, ours_P, _ = _ours(x, P, F, Q, H, R, z)
    np.testing.assert_allclose(ours_x, kf.x[:, 0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ours_P, kf.P, rtol=1e-12, atol=1e-12)
    assert np.array_equal(ours_P, ours_P.T)   # symmetric by construction, bit for bit


def test_gate_rejects_outlier_and_keeps_prior():
    rng = np.random.default_rng(3)
    x, P, F, Q, H, R, z = _random_case(rng, 3)
    _, _, upd = _ours(x, P, F, Q, H, R, z + 1e3, gate2=36.0)
    assert not upd.accepted[0]
    np.testing.assert_array_equal(np.array([v[0] for v in upd.x]), F @ x)


@pytest.mark.parametrize("seed", range(20))
def test_step_bound_shortens_the_whole_update(seed):
    """Model III's step bound (ekf.bound_step): where the update moves a parameter x[1:] by more
    than the bound, the whole update, the state x[0] included, is filterpy's update shortened by
    bound / largest parameter change; below the bound it is filterpy's update itself."""
    rng = np.random.default_rng(500 + seed)
    x, P, F, Q, H, R, z = _random_case(rng, 3)
    xp = F @ x
    free, _, _ = _ours(x, P, F, Q, H, R, z)
    largest = float(np.max(np.abs(free[1:] - xp[1:])))
    tight = 0.25 * largest
    bounded, _, _ = _ours(x, P, F, Q, H, R, z, step=tight)
    np.testing.assert_allclose(bounded, xp + (free - xp) * (tight / largest), rtol=1e-12,
                               atol=1e-14)
    assert abs(abs(bounded[1:] - xp[1:]).max() - tight) <= 1e-12 * max(1.0, tight)
    # z moved by a quarter of its unbounded change, in the same direction
    assert (bounded[0] - xp[0]) * (free[0] - xp[0]) > 0.0
    loose, _, _ = _ours(x, P, F, Q, H, R, z, step=2.0 * largest)
    np.testing.assert_array_equal(loose, free)
