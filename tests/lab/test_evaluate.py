"""The accuracy figures against truth: NEES and paper 001's Table 1 statistics, checked
against direct computations (a dense solve per estimate, numpy on the raw columns)."""
import json

import numpy as np
import pytest
from scipy.stats import chi2

from navtwin.lab import evaluate


def _lines(rng, n=400):
    t = np.arange(n) * 0.1
    truth = {"t": np.arange(0, n * 0.1 + 1, 0.001)}
    truth["x"], truth["y"] = np.cos(truth["t"]), 0.5 * truth["t"]
    lines, covs, errs = [], [], []
    for k in range(n):
        A = rng.normal(size=(2, 2)) * 0.2
        P = A @ A.T + 0.01 * np.eye(2)
        e = rng.multivariate_normal([0, 0], P)
        cov = np.zeros((4, 4))
        cov[:2, :2] = P
        x, y = np.cos(t[k]) + e[0], 0.5 * t[k] + e[1]
        lines.append(json.dumps({"t": t[k], "vehicle": 1, "filter": "kf", "x": x, "y": y, "vx": 0,
                                 "vy": 0, "yaw": 0, "cov": cov.ravel().tolist(),
                                 "extrapolated": False}))
        covs.append(P)
        errs.append(e)
    return truth, lines, np.array(covs), np.array(errs)


def approx(v):
    return pytest.approx(v, rel=1e-9, abs=1e-12)


def test_nees_and_table_1_statistics_equal_a_direct_computation():
    rng = np.random.default_rng(3)
    truth, lines, covs, errs = _lines(rng)
    est = evaluate.load_estimates(lines)
    got = evaluate.position_errors(truth, est)["kf"]
    xy = evaluate.axis_errors(truth, est["kf"])
    assert np.allclose(xy, errs, atol=1e-9)  # truth is interpolated at 1 ms: exact to rounding
    q = np.array([e @ np.linalg.solve(P, e) for e, P in zip(xy, covs)])
    assert np.allclose(evaluate.nees(xy, est["kf"]["cov"]), q, rtol=1e-9)
    lo, hi = chi2.ppf([0.025, 0.975], 2)
    assert got["nees_mean"] == approx(q.mean())
    assert got["nees_in_band"] == approx(((q >= lo) & (q <= hi)).mean())
    r = np.hypot(*xy.T)
    for key, want in {"mean": r.mean(), "max": r.max(), "rms": np.sqrt((r ** 2).mean()),
                      "x_min": xy[:, 0].min(), "x_max": xy[:, 0].max(), "x_var": xy[:, 0].var(),
                      "y_min": xy[:, 1].min(), "y_max": xy[:, 1].max(),
                      "y_var": xy[:, 1].var()}.items():
        assert got[key] == approx(want), key
    # errors drawn from the estimates' own covariances: a consistent filter, NEES ~ chi2(2)
    assert abs(got["nees_mean"] - 2) < 0.4 and abs(got["nees_in_band"] - 0.95) < 0.04


def test_a_track_without_a_covariance_has_no_nees():
    rng = np.random.default_rng(4)
    truth, lines, _, _ = _lines(rng, 20)
    zero = [json.dumps({**json.loads(s), "cov": [0.0] * 16}) for s in lines]
    got = evaluate.position_errors(truth, evaluate.load_estimates(zero))["kf"]
    assert got["nees_mean"] is None and got["nees_in_band"] is None and got["n"] == 20

