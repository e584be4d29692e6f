"""Filters of 000 section 4 on x = [x, y, vx, vy, ax, ay]: one filter per module.

kf.KalmanFilter, ekf.ExtendedKalmanFilter, ukf.UnscentedKalmanFilter share
``predict(dt)`` and ``update(z, R, measurement, gate=None) -> Innovation``;
model.py holds the motion model (000 eq. 14) and measurement models (000 eq. 15);
linalg.py the small inverse and solve (shared with host.wsn's Gauss-Newton).
Paper 001's filters: errorstate.ErrorStateFilter (the closed-loop error state on the
strapdown, lc/tc/fatci) and fuzzy.FuzzySystem (fatci's SISO fuzzy inference).
Paper 004's: hinf (the H-infinity filter, its gain from an LMI: cvxpy, the ``lmi`` extra,
imported when the gain is solved), lssvm.LsSvm (the outage bridge) and bp.BpNetwork (its
back-propagation baseline).
"""
from .ekf import ExtendedKalmanFilter
from .innovation import Innovation
from .kf import KalmanFilter
from .model import ACCELERATION, ConstantAcceleration, Linear, Ranges, lag_matrix, position_fix
from .ukf import UnscentedKalmanFilter

__all__ = ["ACCELERATION", "ConstantAcceleration", "ExtendedKalmanFilter", "Innovation",
           "KalmanFilter", "Linear", "Ranges", "UnscentedKalmanFilter", "lag_matrix",
           "position_fix"]
