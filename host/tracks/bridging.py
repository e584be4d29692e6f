"""``hinf+lssvm`` and ``hinf+bp``: 004's bridging of WSN outages (sect. 3-4): the hinf
track while the WSN is present, and in an outage a model trained on its updates corrects the
INS every period as the filter would have.

Training (004 sect. 4.1, Figure 1). Each H-infinity update gives a pair: the input, the INS's
own increments over the period (dp_x, dp_y, dv_x, dv_y: 004's "estimation errors of position
and velocity measured by INS", eq. 3.10, read as what the INS alone measured over the period),
and the target, the update's correction (Delta r_x, Delta r_y, Delta v_x, Delta v_y, eq. 3.11).
The last ``window`` pairs are kept (004 sect. 5.2: a training set of 100 points).

Prediction (sect. 4.2, Figure 2). When an outage starts the model is fitted to the kept pairs
(at least ``min_pairs``); then every period T from the last fix's time the INS's increments
over the period go in and the predicted correction is fed back into the strapdown (at the
period's end time, host.tracks.relative), until a fix comes again.

``hinf+lssvm``: the LS-SVM (host.filters.lssvm), RBF kernel, sigma and eta 004's 1000 and
1000 (its Table 1's choice), or with ``tune`` chosen again at each fit by 004's two-subset
validation; with ``standardise`` on inputs scaled to their training spread. ``hinf+bp``: the back-propagation network (host.filters.bp) with the same inputs
and outputs, seeded.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import between, boolean, key, positive
from navtwin.host.filters import bp, lssvm

from .hinf import HinfSettings, HinfTrack


@dataclass(frozen=True)
class BridgeSettings(HinfSettings):
    window: int = key(100, "", "training pairs kept: the latest updates' (004 sect. 5.2: 100)",
                      between(4, 100_000))
    min_pairs: int = key(20, "", "fewer kept pairs when an outage starts: no bridging (the "
                         "strapdown coasts)", between(2, 100_000))


class BridgedTrack(HinfTrack):
    """The hinf track with an outage model; a subclass gives :meth:`fitted`."""

    Settings = BridgeSettings

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.pairs: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=self.settings.window)
        self.model = None
        self._bridged: float | None = None  # the end of the last bridged period; None: no outage

    def fitted(self, X: np.ndarray, Y: np.ndarray):
        """A model fitted to inputs X and targets Y (n x 4 each), with ``predict``."""
        raise NotImplementedError

    def trained(self, moved: np.ndarray, correction: np.ndarray) -> None:
        self.pairs.append((moved, correction))

    def fix(self, fix) -> None:
        super().fix(fix)
        self._bridged = None

    def coast(self, t: float) -> None:
        if self._bridged is None:  # the outage starts: fit to what the WSN taught
            self._bridged = self._last_fix.t
            self.model = None
            if len(self.pairs) >= self.settings.min_pairs:
                X, Y = (np.array(c) for c in zip(*self.pairs))
                self.model = self.fitted(X, Y)
                self.updates["fit"] += 1
        if self.model is None:
            return
        while t - self._bridged >= self.T:
            t0, t1 = self._bridged, self._bridged + self.T
            a, b = self.ins_at(t0), self.ins_at(t1)
            if a is None:  # the period fell out of the history (an IMU gap): skip it
                self._bridged = t1
                continue
            c = self.model.predict((b - a)[None, :])[0]
            self.correct(t1, c)
            self.updates["bridge"] += 1
            self._bridged = t1


@dataclass(frozen=True)
class LssvmSettings(BridgeSettings):
    sigma: float = key(lssvm.PAPER_SIGMA, "", "RBF kernel width (004 eq. 3.9; its Table 1: 1000)",
                       positive(hi=1e9))
    eta: float = key(lssvm.PAPER_ETA, "", "regularisation (004 eq. 3.2; its Table 1: 1000)",
                     positive(hi=1e12))
    tune: bool = key(False, "", "choose sigma and eta at each fit by 004's two-subset validation "
                     "over its Table 1 grid (else the two settings)", boolean())
    standardise: bool = key(False, "", "centre and scale each input by its training mean and "
                            "standard deviation before the kernel, as hinf+bp does (004 does not "
                            "say; at sigma 1000 raw inputs of metres leave the kernel flat)", boolean())


class HinfLssvmTrack(BridgedTrack):
    name = "hinf+lssvm"
    Settings = LssvmSettings

    def fitted(self, X: np.ndarray, Y: np.ndarray):
        s = self.settings
        if s.tune:
            return lssvm.select(X, Y, standardise=s.standardise).model
        return lssvm.LsSvm(s.sigma, s.eta, s.standardise).fit(X, Y)


@dataclass(frozen=True)
class BpSettings(BridgeSettings):
    hidden: int = key(bp.HIDDEN, "", "hidden neurons (tanh)", between(1, 10_000))
    epochs: int = key(bp.EPOCHS, "", "training epochs (full batch) at each fit", between(1, 1_000_000))
    learning_rate: float = key(bp.LR, "", "gradient-descent step (momentum as host.filters.bp's)",
                               positive(hi=10))
    seed: int = key(1, "", "seed of the network's initial weights", between(0, 2**63 - 1))


class HinfBpTrack(BridgedTrack):
    name = "hinf+bp"
    Settings = BpSettings

    def fitted(self, X: np.ndarray, Y: np.ndarray):
        s = self.settings
        return bp.BpNetwork(4, s.hidden, 4, s.seed).fit(X, Y, s.epochs, s.learning_rate)
