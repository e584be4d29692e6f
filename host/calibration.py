"""001's range calibration (sect. 3.2-3.3, eqs. 13-16) and the calibration file the host loads.

Procedure. The tag is placed at surveyed points (a *step table*: 001 steps it 0.6 m at a time
out to 18.6 m from an anchor) and rests at each while every anchor ranges it; the lab user
notes when it rested where. From each step's first ``exchanges`` completed exchanges per
anchor (001: 20) inside the step's window, with the surveyed distance d from the step's
position to the anchor (host config survey, the vehicle's tag height):

* f and c_i by least squares over all steps and anchors at once (001 eqs. 14-16):
  d~ = f d + c_i + e, one scale factor, one bias per anchor. The fit is made on the step
  means (001 averages the 20 measurements of a point); their residuals persist from one
  point to the next (multipath does), so the 95 % intervals are inflated by the effective
  sample size of an AR(1) fitted to each anchor's residual sequence along the walk.
* sigma(d): the sample standard deviation of each step's exchanges (20 -> 19 degrees of
  freedom) against d, a polynomial of degree ``sigma_degree`` (default 2) in d by least
  squares, evaluated within the calibrated span only (clamped at its ends) and never below
  1 mm. 001 fits degree 5 to one anchor's 31 points; with a few decimetres of noise on each
  point that degree follows the noise at the ends, so 2 is the default (``--sigma-degree``).

Times are the gateway's ``t_us`` (the anchors' network clock, seconds), what the lab's data
acquisition software stamps; the host never sees the emulator's truth.

Files (TOML, ``CALIBRATION_FORMAT``): the step table (:class:`StepTable`, written with
:func:`navtwin.common.schema.dump`) and the calibration (:meth:`Calibration.to_toml`)::

    format = "navtwin-calibration"
    version = 1
    scale = 1.049                      # f: reported = f d + c_i
    scale_ci95 = 0.004
    [bias_m]                           # c_i per anchor id, m
    1 = 0.251
    [bias_ci95_m]
    1 = 0.03
    [sigma]                            # range sd (m) = sum coefficients[k] d^k
    coefficients = [0.1, 0.01, 0.0]
    span_m = [0.6, 20.5]               # d outside is clamped to this

The host corrects each range d = (d~ - c_i) / f before the WSN fixes and the fusion tracks
use it (host.estimator); ``est.calibration`` is the loaded :class:`Calibration` (or None).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from navtwin.common.limits import ANCHOR_IDS, MAX_COORD_M, RANGE_BIAS_M, RANGE_SCALE
from navtwin.common import tomlfile
from navtwin.common.schema import REQUIRED, Check, Invalid, between, build, dump, each, key
from navtwin.protocols.nanoloc import distance, is_complete
from navtwin.protocols.stream import Frame, nanoloc_decoder

from .wsn import AnchorLayout, toa_fix

CALIBRATION_FORMAT = "navtwin-calibration"
VERSION = 1
CALIBRATION_DIR = Path(__file__).resolve().parent / "calibrations"
SIGMA_FLOOR_M = 0.001
T95 = 1.96  # two-sided 95 % of the normal: the fits have over a hundred step means


class CalibrationError(ValueError):
    """A bad calibration or step table file: one line naming the file, the problem, the fix."""

    def __init__(self, message: str) -> None:
        super().__init__(message.replace("\n", "\\n"))


# -- the step table --------------------------------------------------------------------------

@dataclass(frozen=True)
class Step:
    x: float = key(REQUIRED, "m", "surveyed tag position x", between(-MAX_COORD_M, MAX_COORD_M))
    y: float = key(REQUIRED, "m", "surveyed tag position y", between(-MAX_COORD_M, MAX_COORD_M))
    start_s: float = key(REQUIRED, "s", "the tag rests here from this gateway time (t_us / 1e6)",
                         between(0, 4294.967295))
    end_s: float = key(REQUIRED, "s", "until this gateway time", between(0, 4294.967295))

    def __post_init__(self):
        if self.end_s <= self.start_s:
            raise Invalid("end_s", f"{self.end_s:g} is not after start_s {self.start_s:g}; give "
                                   "the end of the rest")


@dataclass(frozen=True)
class StepTable:
    steps: tuple[Step, ...] = key(REQUIRED, "", "the surveyed points, in the order walked")
    exchanges: int = key(20, "", "exchanges per anchor used at each step (001: 20)", between(2, 10000))

    def __post_init__(self):
        if len(self.steps) < 3:
            raise Invalid("steps", f"lists {len(self.steps)} points; a fit of f and c_i needs "
                                   "at least 3, add [[steps]]")


def load_steps(path: str | Path) -> StepTable:
    """The step table at *path*, or a shipped one by name (host/calibrations/<name>-steps.toml)."""
    return build_file(path, "-steps", lambda doc, src: build(StepTable, doc))


def steps_toml(table: StepTable) -> str:
    return ("# 001 sect. 3.3: surveyed tag positions and when the tag rested there "
            "(host.calibration)\n" + dump(table))


# -- the calibration -------------------------------------------------------------------------

@dataclass(frozen=True)
class Calibration:
    """f, c_i and sigma(d) of a lab's ranges (module docstring); the host's interface."""

    scale: float
    bias: Mapping[int, float]  # anchor id -> c_i, m
    sigma_coefficients: tuple[float, ...]  # range sd polynomial in d, from d^0
    sigma_span_m: tuple[float, float]
    scale_ci95: float = 0.0
    bias_ci95: Mapping[int, float] = field(default_factory=dict)
    source: str = field(default="", compare=False)  # where it was read from (messages)

    def sigma(self, d):
        """Range standard deviation (m) at distance(s) *d* (m)."""
        lo, hi = self.sigma_span_m
        x = np.clip(np.asarray(d, dtype=float), lo, hi)
        s = np.maximum(np.polynomial.polynomial.polyval(x, self.sigma_coefficients), SIGMA_FLOOR_M)
        return float(s) if s.ndim == 0 else s

    def correct(self, anchor: int, reported: float) -> float:
        """001 eq. 14 inverted: the distance (m) from a reported one."""
        return (reported - self.bias.get(anchor, 0.0)) / self.scale

    def to_dict(self) -> dict:
        """The file's content as TOML-like data (a host recording's meta keeps it)."""
        return {"format": CALIBRATION_FORMAT, "version": VERSION, "scale": self.scale,
                "scale_ci95": self.scale_ci95,
                "bias_m": {str(a): c for a, c in sorted(self.bias.items())},
                "bias_ci95_m": {str(a): c for a, c in sorted(self.bias_ci95.items())},
                "sigma": {"coefficients": list(self.sigma_coefficients),
                          "span_m": list(self.sigma_span_m)}}

    def to_toml(self, header: str = "") -> str:
        d = self.to_dict()
        lines = [f"# {h}" for h in header.splitlines()] + [
            f'format = "{CALIBRATION_FORMAT}"', f"version = {VERSION}",
            f"scale = {_num(d['scale'])}", f"scale_ci95 = {_num(d['scale_ci95'])}", "", "[bias_m]"]
        lines += [f"{a} = {_num(c)}" for a, c in d["bias_m"].items()]
        lines += ["", "[bias_ci95_m]"] + [f"{a} = {_num(c)}" for a, c in d["bias_ci95_m"].items()]
        lines += ["", "[sigma]", "coefficients = [" + ", ".join(_num(c) for c in self.sigma_coefficients)
                  + "]", "span_m = [" + ", ".join(_num(c) for c in self.sigma_span_m) + "]"]
        return "\n".join(lines) + "\n"


def _num(v: float) -> str:
    """Six significant digits: the file is read by people, and no fit is better than that."""
    return repr(float(f"{v:.6g}"))


@dataclass(frozen=True)
class SigmaFit:
    """A calibration file's [sigma]: the range standard deviation as a polynomial in d."""
    coefficients: tuple[float, ...] = key(REQUIRED, "", "sigma(d) (m) as a polynomial in d, "
                                          "from d^0", Check(lambda v: 1 <= len(v) <= 8,
                                                            "must hold 1 to 8 numbers",
                                                            "re-run navtwin calibrate"),
                                          each(between(-100, 100)))
    span_m: tuple[float, float] = key(REQUIRED, "m", "the distances it was fitted over, "
                                      "[lo, hi]; d is clipped to them",
                                      each(between(0, MAX_COORD_M)))

    def __post_init__(self):
        if self.span_m[0] >= self.span_m[1]:
            raise Invalid("span_m", f"must be [lo, hi] with lo < hi (got {list(self.span_m)}); "
                                    "re-run navtwin calibrate")


@dataclass(frozen=True, kw_only=True)
class CalibrationFile:
    """What a calibration file holds (``navtwin calibrate`` writes it: Calibration.to_toml)."""
    format: str = key(REQUIRED, "", f'"{CALIBRATION_FORMAT}"')
    version: int = key(REQUIRED, "", f"{VERSION}")
    scale: float = key(REQUIRED, "", "f of 001 eq. 13", between(*RANGE_SCALE))
    scale_ci95: float = key(0.0, "", "95 % half-width of f", between(0, 1))
    bias_m: dict[int, float] = key(REQUIRED, "m", "c_i of 001 eq. 13 per anchor id",
                                   between(*RANGE_BIAS_M), ids=("anchor", ANCHOR_IDS))
    bias_ci95_m: dict[int, float] | None = key(None, "m", "95 % half-width of c_i per anchor id",
                                               between(0, 10), ids=("anchor", ANCHOR_IDS))
    sigma: SigmaFit = key(REQUIRED, "", "the range standard deviation sigma(d)")

    def __post_init__(self):
        if not self.bias_m:
            raise Invalid("bias_m", "is empty; give c_i per anchor id like 1 = 0.25")


def load(path: str | Path) -> Calibration:
    """The calibration file at *path*, or a shipped one by name (host/calibrations/<name>.toml)."""
    return build_file(path, "", parse)


def build_file(path: str | Path, suffix: str, make):
    """Read the TOML at *path* (or the shipped ``<name><suffix>.toml``) and *make* it; every
    problem a one-line CalibrationError."""
    path = Path(path)
    if not path.suffix and not path.is_file():
        path = CALIBRATION_DIR / f"{path}{suffix}.toml"
    doc = tomlfile.read(path, CalibrationError)
    try:
        return make(doc, str(path))
    except (Invalid, CalibrationError) as e:
        raise CalibrationError(f"{path}: {e}") from None


def parse(doc, source: str = "calibration") -> Calibration:
    """A calibration from its file's TOML data (:meth:`Calibration.to_dict`'s layout)."""
    if not isinstance(doc, dict) or doc.get("format") != CALIBRATION_FORMAT:
        raise CalibrationError(f'format is not "{CALIBRATION_FORMAT}"; give a file written by '
                               "navtwin calibrate")
    if doc.get("version") != VERSION:
        raise CalibrationError(f"version {doc.get('version')!r} is not {VERSION}; re-run navtwin "
                               "calibrate")
    f = build(CalibrationFile, doc)
    return Calibration(scale=f.scale, bias=f.bias_m, sigma_coefficients=f.sigma.coefficients,
                       sigma_span_m=f.sigma.span_m, scale_ci95=f.scale_ci95,
                       bias_ci95=f.bias_ci95_m or {}, source=source)


# -- the ranges ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Ranges:
    """The completed exchanges of a gateway stream: time (s, t_us unwrapped), anchor, metres."""

    t_s: np.ndarray
    anchor: np.ndarray
    distance: np.ndarray


def ranges(data: bytes) -> Ranges:
    """Decode the gateway's byte stream (garbage and bad frames skipped, as the host does)."""
    t, anchor, d = [], [], []
    for f in nanoloc_decoder().decode(data):
        if isinstance(f, Frame) and f.known and is_complete(f.fields["status"]):
            t.append(f.fields["t_us"])
            anchor.append(f.fields["anchor"])
            d.append(distance(*f.fields["tau"]))
    t_us = np.array(t, dtype=np.int64)
    wraps = np.concatenate(([0], np.cumsum(np.diff(t_us) < -2**31))) if len(t_us) else t_us
    return Ranges((t_us + wraps * 2**32) / 1e6, np.array(anchor, dtype=int), np.array(d, dtype=float))


# -- the fit ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class Result:
    """A fit and its figures: ``calibration``; ``points`` (step, anchor, d, mean, sd, n);
    mean |range error| before and after over every exchange used; WSN-only TOA fixes at the
    steps (one per cycle of the step's exchanges) against the surveyed points, before and
    after: max and variance of the position error."""

    calibration: Calibration
    points: np.ndarray
    range_error_m: tuple[float, float]
    wsn_max_m: tuple[float, float]
    wsn_variance_m2: tuple[float, float]
    wsn_mean_m: tuple[float, float]
    exchanges: int


def fit(r: Ranges, table: StepTable, anchors: Mapping[int, tuple[float, ...]], tag_height: float = 0.0,
        sigma_degree: int = 2) -> Result:
    """f, c_i and sigma(d) from the ranges of the step table's rests (module docstring)."""
    ids = sorted(anchors)
    layout = AnchorLayout(anchors, tag_height)
    used = []  # (step, anchor id, surveyed d, reported distances of the step)
    for k, step in enumerate(table.steps):
        inside = (r.t_s >= step.start_s) & (r.t_s < step.end_s)
        p = np.array([step.x, step.y])
        for j, a in enumerate(ids):
            got = r.distance[inside & (r.anchor == a)][:table.exchanges]
            if len(got) < 2:
                continue
            used.append((k, a, float(layout.ranges(p, np.array([j]))[0]), got))
    missing = [a for a in ids if sum(u[1] == a for u in used) < 2]
    if missing:
        raise CalibrationError(f"anchor {missing[0]} has completed exchanges at fewer than 2 steps "
                               "of the step table; check the table's times against the recording")
    d = np.array([u[2] for u in used])
    mean = np.array([u[3].mean() for u in used])
    sd = np.array([u[3].std(ddof=1) for u in used])
    n = np.array([len(u[3]) for u in used])
    who = np.array([u[1] for u in used])
    # 001 eqs. 15-16: the normal equations of S(f, c) = sum (d~ - f d - c_i)^2, in lstsq form
    A = np.column_stack([d] + [(who == a).astype(float) for a in ids])
    theta, *_ = np.linalg.lstsq(A, mean, rcond=None)
    scale_ok = between(*RANGE_SCALE)  # the limit a calibration file's scale has
    if not scale_ok.ok(float(theta[0])):
        raise CalibrationError(
            f"the fitted scale factor f = {theta[0]:.4g} {scale_ok.must} (what the host accepts): "
            "the ranges do not grow with the step table's distances, so the recording is no "
            "calibration walk of that table (the tag resting at each of its points in turn); "
            "record one, or give the steps and config it was made with")
    resid = mean - A @ theta
    dof = max(len(mean) - A.shape[1], 1)
    inflation = max((_ar1_inflation(resid[who == a]) for a in ids), default=1.0)
    cov = np.linalg.inv(A.T @ A) * (resid @ resid / dof) * inflation
    ci = T95 * np.sqrt(np.diag(cov))
    degree = min(sigma_degree, len(d) - 1)
    coeffs = np.polynomial.polynomial.polyfit(d, sd, degree, w=np.sqrt(n - 1))
    cal = Calibration(scale=float(theta[0]), bias={a: float(c) for a, c in zip(ids, theta[1:])},
                      sigma_coefficients=tuple(float(c) for c in coeffs),
                      sigma_span_m=(float(d.min()), float(d.max())), scale_ci95=float(ci[0]),
                      bias_ci95={a: float(c) for a, c in zip(ids, ci[1:])})
    before = np.concatenate([u[3] - u[2] for u in used])
    after = np.concatenate([cal.correct(u[1], u[3]) - u[2] for u in used])
    wsn = [_wsn_errors(layout, ids, table, used, corrected) for corrected in (None, cal)]
    points = np.rec.fromarrays([[u[0] for u in used], who, d, mean, sd, n],
                               names="step,anchor,d,mean,sd,n")
    return Result(cal, points, (float(np.abs(before).mean()), float(np.abs(after).mean())),
                  tuple(float(e.max()) for e in wsn), tuple(float(e.var()) for e in wsn),
                  tuple(float(e.mean()) for e in wsn), int(n.sum()))


def _ar1_inflation(e: np.ndarray) -> float:
    """Variance factor (1 + rho) / (1 - rho) of a mean of AR(1) residuals with lag-1
    correlation rho (>= 0): how much less than n independent points they are worth."""
    if len(e) < 3 or not np.any(e):
        return 1.0
    rho = float(np.clip(np.dot(e[1:], e[:-1]) / np.dot(e, e), 0.0, 0.95))
    return (1 + rho) / (1 - rho)


def _wsn_errors(layout: AnchorLayout, ids: list[int], table: StepTable, used, cal) -> np.ndarray:
    """Errors of TOA fixes from the k-th exchange of every anchor at each step."""
    errors = []
    by_step: dict[int, dict] = {}
    for k, a, _, got in used:
        by_step.setdefault(k, {})[a] = got if cal is None else cal.correct(a, got)
    for k, per in by_step.items():
        if len(per) < 3:
            continue
        step, names = table.steps[k], sorted(per)
        idx = layout.index(names)
        for m in range(min(len(per[a]) for a in names)):
            try:
                p, _, _ = toa_fix(layout, idx, np.array([per[a][m] for a in names]), 1.0)
            except np.linalg.LinAlgError:
                continue
            errors.append(math.hypot(p[0] - step.x, p[1] - step.y))
    return np.array(errors) if errors else np.array([math.nan])
