"""The posterior Cramer-Rao bound (lab.pcrb): its recursion equals the information of the
stacked batch problem (a dense solve over all states) and, the measurements being linear,
the Kalman filter's covariance; on the office path it is a sane figure."""
import numpy as np

from navtwin.emulator.scenario import load_scenario
from navtwin.host.filters.model import ConstantAcceleration
from navtwin.lab import pcrb
from navtwin.lab.run import truth


def _steps(rng, k):
    steps = []
    for _ in range(k):
        u = rng.normal(size=2)
        H = np.zeros((1, 6))
        H[0, :2] = u / np.linalg.norm(u)  # a range's Jacobian: a unit vector on position
        steps.append((float(rng.uniform(0.1, 0.3)), H, np.array([[rng.uniform(0.1, 0.5) ** 2]])))
    steps.append((0.0, steps[-1][1], steps[-1][2]))  # and a second one at the same time
    return steps


def test_recursion_equals_the_batch_information_and_the_kalman_covariance():
    rng = np.random.default_rng(7)
    model = ConstantAcceleration(5.0)  # a well-conditioned Q^-1 for the dense solve
    P0 = np.diag([0.2, 0.2, 0.02, 0.02, 0.1, 0.1]) ** 2
    steps = _steps(rng, 12)
    got = pcrb.information(model, np.linalg.inv(P0), steps)

    # dense: x_0..x_K stacked; prior on x_0, each transition's and measurement's information
    states = 1 + sum(dt > 0 for dt, _, _ in steps)
    n = 6 * states
    J = np.zeros((n, n))
    J[:6, :6] = np.linalg.inv(P0)
    k = 0
    P = P0.copy()  # and the Kalman filter's covariance beside it
    for dt, H, R in steps:
        if dt > 0:
            F, Qi = model.F(dt), np.linalg.inv(model.Q(dt))
            a, b = slice(6 * k, 6 * k + 6), slice(6 * k + 6, 6 * k + 12)
            J[a, a] += F.T @ Qi @ F
            J[a, b] -= F.T @ Qi
            J[b, a] -= Qi @ F
            J[b, b] += Qi
            k += 1
            P = F @ P @ F.T + model.Q(dt)
        s = slice(6 * k, 6 * k + 6)
        J[s, s] += H.T @ np.linalg.inv(R) @ H
        G = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        P = (np.eye(6) - G @ H) @ P
    assert k == states - 1
    last = np.linalg.inv(J)[-6:, -6:]
    # Tichavsky et al.'s form itself, J = D22 - D21 (J + D11)^-1 D12
    T = np.linalg.inv(P0)
    for dt, H, R in steps:
        Hi = H.T @ np.linalg.inv(R) @ H
        if dt == 0:
            T = T + Hi
            continue
        F, Qi = model.F(dt), np.linalg.inv(model.Q(dt))
        D11, D12 = F.T @ Qi @ F, -F.T @ Qi
        T = Qi + Hi - D12.T @ np.linalg.inv(T + D11) @ D12
    for name, want in (("batch", last), ("kalman", P), ("tichavsky", np.linalg.inv(T))):
        np.testing.assert_allclose(np.linalg.inv(got[-1]), want, rtol=1e-7, atol=1e-12, err_msg=name)


def test_office_bound_is_finite_and_below_the_range_noise():
    sc = load_scenario("office")
    tr = truth(sc)
    t, anchor = pcrb.exchanges(sc, 10.0)
    # one exchange per anchor per 100 ms cycle, in slot order
    assert len(t) == 400 and list(anchor[:4]) == [0, 1, 2, 3]
    np.testing.assert_allclose(np.diff(t[:4]), sc.ranging.slot_ms / 1e3)
    b = pcrb.position_bound(sc, {k: v[tr["t"] <= 10.0] for k, v in tr.items()}, 0.5, (0.2, 0.02, 0.1))
    assert np.isfinite(b["rms"]).all()
    # four ranges of sigma >= 0.3 m a cycle, smoothed by the motion model: a few decimetres
    assert 0.05 < b["rms"][-1] < 0.3 * np.sqrt(2)
