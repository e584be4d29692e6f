"""``centroid`` and ``wcl``: 003's RSSI centroid and weighted-centroid fixes and the
magnetometer heading aiding the geodetic SINS through 003's error-state filter (003 sections
2.1-2.2 and 3, eqs. 9-24; docs/filters.md, "003's tracks").

Filter: host.tracks.geodetic (the geodetic strapdown, the 16 states of eqs. 16 and 22, the
phi-angle F of eq. 13 and 21, closed loop).

Fix. Each TDMA cycle (host.wsn.CycleGrouper, ``cycle_s``) of the gateway's reports gives,
from each completed exchange's RSSI byte, a distance by the path-loss model inverted (003
eq. 2, host.rssi.distance, with ``rssi_1m_dbm`` and ``path_loss_exponent``); the three
strongest anchors' distances, made horizontal with the tag height (r_h^2 = d^2 - dz^2), give
the fix: the centroid of 003's three circle points A, B, C (eqs. 9-10, ``centroid``) or their
weighted centroid (eqs. 11-12, ``wcl``; host.centroid). A cycle with fewer than three RSSI
distances, or whose fix is refused, gives no update (counted by reason).

Path loss. With ``adaptive_path_loss`` the cycle's distances use 003's adaptive parameters:
each anchor's (lambda_i, n_i) fitted to its mean readings of the other anchors (eqs. 3-4;
host.rssi.AnchorReadings, from the AnchorExchanges of the scenario's anchor exchanges), weighed
by the tag's readings of this cycle (eqs. 5-7), the distance by eq. 8. Until every anchor has
heard two others (or without anchor exchanges at all) the configured ``rssi_1m_dbm`` and
``path_loss_exponent`` stand in, counted ``path_loss_unfitted``; so they do for a cycle whose
adaptive (lambda, n) leaves the model's range (n in [1, 6]: a fit to a few noisy readings can
give an n near 0, every distance infinite), counted ``path_loss_implausible``.

Position measurement (eqs. 17-20, in their linear map): z = p_SINS - p_fix (area x, y),
H = [lead I on dV_E, dV_N; d(x, y)/d(dL, dlambda) on dL, dlambda] (host.tracks.geodetic).
003 writes the measurement as the range differences to node 0 of both positions (eqs.
19-20) with three range-error states (eq. 17). Both positions are points: to first order
those differences are G (p_SINS - p_fix), G the differences' gradient at the position, so
the paper's z is this z times G; with the fix a single point, the three states of eq. 17
(the errors of the fix's ranges) are not separable from the fix's position error, which R
carries instead. R: from the RSSI physics, each slant range's sigma_d = d ln 10
``shadowing_db`` / (10 n) (host.rssi.distance_sigma), through the fix's Jacobian in the
ranges (host.centroid.fix_covariance), plus ``fix_sigma_m``^2 I for the centroid's own error
(003 gives its fix no covariance).

Heading (eqs. 22-24), with ``magnetometer``: each magnetometer sample (at most one per
``heading_period_s``) gives psi_mag = host.magnetometer.yaw_from_field, tilt-compensated with
the strapdown's roll and pitch and corrected by ``[site] declination_deg``; z = psi_SINS -
psi_mag (wrapped), H = d psi / d phi (-1 on phi_U, the tilt's share on phi_E, phi_N) and -1
on the magnetometer heading's error state dpsi_mag (a random walk, ``mag_bias_sigma_deg`` at
the start, ``mag_bias_rw_deg_rt_hr``); R = ``mag_heading_sigma_deg``^2.

After a discontinuity the track starts again at its own next fix (the estimator's WSN fixes
too, where there are any).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import between, boolean, key, positive
from navtwin.host import centroid, rssi
from navtwin.host.magnetometer import yaw_from_field
from navtwin.host.measurements import AnchorExchange, Exchange, Fix, MagSample
from navtwin.host.wsn import CycleGrouper
from navtwin.protocols.nanoloc import is_complete

from .geodetic import GeodeticSettings, GeodeticTrack


#: The path-loss model's range, for the configured model and the adaptive one alike.
PLAUSIBLE_RSSI_1M, PLAUSIBLE_N = (-120.0, 20.0), (1.0, 6.0)


@dataclass(frozen=True)
class CentroidSettings(GeodeticSettings):
    rssi_1m_dbm: float = key(-45.0, "dBm", "RSSI(1 m) of the path-loss model (003 eq. 2's "
                             "RSSI(1), eq. 8's lambda)", between(*PLAUSIBLE_RSSI_1M))
    path_loss_exponent: float = key(2.0, "", "path-loss exponent n of 003 eq. 2", between(*PLAUSIBLE_N))
    shadowing_db: float = key(2.0, "dB", "RSSI shadowing, 1 sigma (003 eq. 1's sigma): each "
                              "range's sigma_d = d ln10 sigma / (10 n), R of the fix", positive(hi=100))
    fix_sigma_m: float = key(1.5, "m", "the centroid's own error, 1 sigma per axis: added to the "
                             "fix's R from the ranges (003 gives none)", positive(hi=1e3))
    adaptive_path_loss: bool = key(False, "", "003 eqs. 3-8: each anchor's path loss fitted to "
                                   "its readings of the others (the scenario's anchor exchanges), "
                                   "weighed per cycle by the tag's readings; until every anchor "
                                   "heard two others, rssi_1m_dbm and path_loss_exponent",
                                   boolean())
    magnetometer: bool = key(True, "", "take the magnetometer's heading (003 eqs. 22-24)",
                             boolean())
    mag_heading_sigma_deg: float = key(2.0, "deg", "magnetometer heading, 1 sigma: R of eq. 24",
                                   positive(hi=180))
    heading_period_s: float = key(1.0, "s", "at most one heading update per this",
                                  between(0, 3600))
    mag_bias_sigma_deg: float = key(2.0, "deg", "the magnetometer heading's error at the start "
                                    "(eq. 22's state), 1 sigma", positive(hi=180))
    mag_bias_rw_deg_rt_hr: float = key(1.0, "deg/sqrt(h)", "its random walk", between(0, 1e4))


class CentroidTrack(GeodeticTrack):
    name = "centroid"
    Settings = CentroidSettings
    #: The fix of three anchors' circles (host.centroid): eqs. 9-10.
    locate = staticmethod(centroid.centroid)

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.grouper = CycleGrouper(len(ctx.layout.ids), ctx.cfg.cycle_s)
        self._t_heading: float | None = None
        self.heard = rssi.AnchorReadings(ctx.layout.ids)  # the anchors' readings of each other
        self._fitted: tuple | None = None  # (lambda_i, n_i) of eqs. 3-4, None: refit

    def magnetometer_psd(self) -> float:
        return (math.radians(self.settings.mag_bias_rw_deg_rt_hr) / 60.0) ** 2

    def magnetometer_p0(self) -> float:
        return math.radians(self.settings.mag_bias_sigma_deg)

    def handlers(self) -> dict:
        taken = {**super().handlers(), Exchange: self.exchange}
        if self.settings.adaptive_path_loss:
            taken[AnchorExchange] = self.anchor_exchange
        if self.settings.magnetometer:
            taken[MagSample] = self.heading
        return taken

    def restart(self, device: str, t: float) -> None:
        super().restart(device, t)
        if device == "anchors":  # no cycle spans a restart
            self.grouper = CycleGrouper(len(self.ctx.layout.ids), self.ctx.cfg.cycle_s)

    def anchor_exchange(self, rec: AnchorExchange) -> None:
        if is_complete(rec.status):
            self.heard.add(rec.anchor, rec.other, rec.rssi)
            self._fitted = None

    def exchange(self, rec: Exchange) -> None:
        # the cycle keeps the RSSI (the grouper's "distances"): with adaptive parameters the
        # distances depend on the whole cycle's readings (eqs. 5-7); a timed-out or incomplete
        # exchange's RSSI byte measured no reply
        for cycle in self.grouper.add(rec.t, rec.anchor, float(rec.rssi) if is_complete(rec.status) else None):
            self.cycle(cycle)

    def path_loss(self, anchors, readings) -> tuple[float, float]:
        """(lambda, n) of this cycle: eqs. 5-7 over the anchors' fitted parameters
        (adaptive_path_loss, once every anchor heard two others) or the configured ones."""
        s = self.settings
        if s.adaptive_path_loss:
            layout = self.ctx.layout
            if self._fitted is None:
                xyz = np.column_stack((layout.xy, layout.z))
                self._fitted = self.heard.parameters(xyz) or ()
            if self._fitted:
                idx = layout.index(anchors)
                lam, n = rssi.adaptive_parameters(self._fitted[0][idx], self._fitted[1][idx], readings)
                # a fit to few noisy readings can leave the model's range (an n near 0 sends
                # every distance to infinity): the configured model until the means settle
                if PLAUSIBLE_N[0] <= n <= PLAUSIBLE_N[1] and PLAUSIBLE_RSSI_1M[0] <= lam <= PLAUSIBLE_RSSI_1M[1]:
                    return lam, n
                self.rejections["path_loss_implausible"] += 1
                return s.rssi_1m_dbm, s.path_loss_exponent
            self.rejections["path_loss_unfitted"] += 1
        return s.rssi_1m_dbm, s.path_loss_exponent

    def cycle(self, cycle) -> None:
        """A closed cycle's fix of its three strongest anchors, and the update it gives."""
        if len(cycle.distances) < 3:
            self.rejections["few_anchors"] += 1
            return
        s = self.settings
        readings = np.asarray(cycle.distances)  # dBm (exchange)
        lam, n = self.path_loss(cycle.valid_anchors, readings)
        distances = rssi.distance(readings, lam, n)  # eq. 8 (eq. 2 inverted)
        nearest = np.argsort(distances, kind="stable")[:3]
        anchors = tuple(cycle.valid_anchors[k] for k in nearest)
        layout = self.ctx.layout
        idx = layout.index(anchors)
        slant = distances[nearest]
        horizontal = np.sqrt(np.maximum(slant**2 - layout.dz[idx] ** 2, 0.0))
        res = self.locate(layout.xy[idx], horizontal)
        if res.p is None:
            self.rejections[res.reason] += 1
            return
        # a slant range's sigma, made horizontal: dr_h = d / r_h dd
        sigma = (rssi.distance_sigma(slant, s.shadowing_db, n)
                 * slant / np.maximum(horizontal, 1e-3))
        cov = centroid.fix_covariance(self.locate, layout.xy[idx], horizontal, sigma, s.fix_sigma_m)
        self.fix(Fix(cycle.t, res.p, cov, anchors, 0.0))

    def fix(self, fix: Fix) -> None:
        if self.pending:  # start again at this fix, if it is not older than the discontinuity
            self.offer_fix(fix)
            return
        if fix is self.reinit_fix or not self.ready(fix.t):
            return
        p, lead = self.position_at(fix.t)
        self._update("fix", fix.t, p - fix.p, self.position_rows(lead), fix.cov, 2)

    def heading(self, rec: MagSample) -> None:
        """003 eqs. 23-24: the strapdown's yaw against the magnetometer's (module docstring)."""
        s, cfg = self.settings, self.ctx.cfg
        if not self.ready(rec.t) or (self._t_heading is not None
                                     and rec.t - self._t_heading < s.heading_period_s):
            return
        roll, pitch, _ = self.nav.euler
        psi_mag = yaw_from_field(rec.field, cfg.declination_deg, cfg.x_azimuth_deg, roll, pitch)
        z = self.area_yaw() - psi_mag
        z = math.atan2(math.sin(z), math.cos(z))
        # yaw = atan2(C_10, C_00) with C -> (I - phi x) C: d yaw = -phi_U + (C_00 phi_E + C_10 phi_N) C_20 / D
        C = self.nav.dcm()
        c00, c10, c20 = C[0][0], C[1][0], C[2][0]
        D = c00 * c00 + c10 * c10
        H = np.zeros((1, 16))
        H[0, 3], H[0, 4], H[0, 5], H[0, 15] = c00 * c20 / D, c10 * c20 / D, -1.0, -1.0
        self._t_heading = rec.t
        R = np.array([[math.radians(s.mag_heading_sigma_deg) ** 2]])
        self._update("heading", rec.t, np.array([z]), H, R, 1)


class WclTrack(CentroidTrack):
    name = "wcl"
    #: The weighted centroid (host.centroid): eqs. 11-12.
    locate = staticmethod(centroid.weighted_centroid)
