"""RSSI ranging: 003's log-distance path-loss model and its adaptive parameters (003 section
2.1, eqs. 1-8; docs/filters.md, "003's tracks").

The model (eq. 2, eq. 1 with d_0 = 1 m)::

    RSSI(d) = lambda - 10 n lg(d)            lambda = RSSI(1) (+ shadowing)
    d = 10^((lambda - RSSI) / (10 n))        its inversion (:func:`distance`)

Sign. Eqs. 1-2 write ``- 10 n lg d``, eqs. 3, 4 and 8 ``+ 10 n lg d``. The signal weakens
with distance and the paper states n between 2 and 4, so only the minus sign is consistent
with a positive n: it is the one used here throughout (eqs. 3, 4 and 8 read with it).

Adaptive parameters (:func:`anchor_parameters`, :func:`adaptive_parameters`):

* eqs. 3-4: anchor i hears two other anchors j, k at surveyed distances d_ij, d_ik, so
  RSSI_ij = lambda_i - 10 n_i lg d_ij and RSSI_ik likewise: two linear equations in
  (lambda_i, n_i). With more than two others heard, their least-squares solution (the same
  line through more points; with two, eqs. 3-4 exactly).
* eq. 5: e_i = (RSSI(d_i) - RSSI(d_1)) / sum_{i=2..m} (RSSI(d_i) - RSSI(d_1)), where RSSI(d_i)
  is the tag's reading of anchor i and anchor 1 is the "optimal" one. The paper leaves both
  open; read here: the optimal anchor is the one the tag hears strongest (the nearest, which
  the paper calls least affected), and the RSSI(d_i) are the tag's readings (not the
  anchors' of each other: those gave lambda_i, n_i). So e_1 = 0, e_i in [0, 1], sum e_i = 1.
  All readings equal (the denominator 0): every e_i = 1/m, so eqs. 6-7 weigh every anchor
  1/m (a choice of ours; the paper does not say).
* eqs. 6-7: lambda = sum_i (1 - e_i)/(m - 1) lambda_i, n likewise: weights that sum to 1,
  largest for the anchors the tag hears strongest.
"""
from __future__ import annotations

import numpy as np


def rssi(d, rssi_1m_dbm: float, n: float):
    """RSSI (dBm) at distance d (m) without shadowing (eq. 2)."""
    return rssi_1m_dbm - 10.0 * n * np.log10(d)


def distance(rssi_dbm, rssi_1m_dbm: float, n: float):
    """The distance (m) that the RSSI (dBm) implies (eq. 2 inverted)."""
    return 10.0 ** ((rssi_1m_dbm - np.asarray(rssi_dbm, float)) / (10.0 * n))


def distance_sigma(d, shadowing_db: float, n: float):
    """1 sigma (m) of the distance eq. 2 gives at distance d (m) when the RSSI has a shadowing
    of ``shadowing_db`` (1 sigma, dB): d = 10^((lambda - RSSI) / (10 n)) moves by
    dd/dRSSI = -d ln 10 / (10 n) per dB, so sigma_d = d ln 10 sigma_dB / (10 n) (to first
    order: the distance's error is log-normal, its sigma grows with d)."""
    return np.asarray(d, float) * np.log(10.0) * shadowing_db / (10.0 * n)


def anchor_parameters(positions, heard) -> tuple[np.ndarray, np.ndarray]:
    """Each anchor's (lambda_i, n_i) from its readings of the other anchors (eqs. 3-4).

    positions: (m, 2 or 3) surveyed anchor positions (m); heard: (m, m) RSSI (dBm) that anchor
    i reads of anchor j, NaN where none (the diagonal is ignored). Each anchor needs two
    others heard at distinct distances: else ValueError naming the anchor."""
    xyz = np.asarray(positions, float)
    heard = np.asarray(heard, float)
    m = len(xyz)
    lam, n = np.empty(m), np.empty(m)
    for i in range(m):
        others = [j for j in range(m) if j != i and np.isfinite(heard[i, j])]
        lg = np.log10([np.linalg.norm(xyz[j] - xyz[i]) for j in others])
        if len(others) < 2 or np.ptp(lg) == 0.0:
            raise ValueError(f"anchor row {i} hears {len(others)} other anchors at distinct "
                             "distances; eqs. 3-4 need two: give it readings of two anchors "
                             "at different distances")
        A = np.column_stack([np.ones_like(lg), -10.0 * lg])
        (lam[i], n[i]), *_ = np.linalg.lstsq(A, heard[i, others], rcond=None)
    return lam, n


def adjustment_factors(tag_rssi) -> np.ndarray:
    """e_i of eq. 5 from the tag's readings of the m anchors (dBm), the strongest the
    optimal anchor (e = 0); all equal: 1/m each."""
    r = np.asarray(tag_rssi, float)
    diff = r - r.max()
    total = diff.sum()
    if total == 0.0:
        return np.full(len(r), 1.0 / len(r))
    return diff / total


def adaptive_parameters(lam_i, n_i, tag_rssi) -> tuple[float, float]:
    """(lambda, n) of eqs. 6-7: the anchors' parameters weighted by (1 - e_i)/(m - 1)."""
    e = adjustment_factors(tag_rssi)
    m = len(e)
    if m < 2:
        raise ValueError(f"eqs. 6-7 weigh two or more anchors, got {m}: give the tag's readings "
                         "of at least two anchors")
    w = (1.0 - e) / (m - 1)
    return float(w.dot(lam_i)), float(w.dot(n_i))


class AnchorReadings:
    """What each anchor hears of the others (host.measurements.AnchorExchange), averaged per
    ordered pair in dBm: shadowing is normal in dB, so the mean converges on eq. 2's value and
    eqs. 3-4 fitted to it on the anchor's own (lambda_i, n_i). ``ids`` fixes the row order."""

    def __init__(self, ids) -> None:
        self.ids = tuple(ids)
        self._row = {a: i for i, a in enumerate(self.ids)}
        m = len(self.ids)
        self.sum = np.zeros((m, m))
        self.count = np.zeros((m, m), dtype=np.int64)

    def add(self, anchor: int, other: int, rssi_dbm: float) -> None:
        """One reading; a pair with an unknown anchor is ignored (not of this layout)."""
        i, j = self._row.get(anchor), self._row.get(other)
        if i is not None and j is not None and i != j:
            self.sum[i, j] += rssi_dbm
            self.count[i, j] += 1

    def heard(self) -> np.ndarray:
        """(m, m) mean readings, NaN where a pair has none."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.count > 0, self.sum / np.maximum(self.count, 1), np.nan)

    def parameters(self, positions) -> tuple[np.ndarray, np.ndarray] | None:
        """Each anchor's (lambda_i, n_i) (eqs. 3-4) from the mean readings, or None while an
        anchor has heard fewer than two others."""
        if np.any((self.count > 0).sum(axis=1) < 2):
            return None
        return anchor_parameters(positions, self.heard())
