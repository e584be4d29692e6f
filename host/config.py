"""The lab computer's own configuration: its anchor survey, site, vehicle start and filters.

This is what the host knows about the lab without asking any device. It is read from TOML::

    [site]
    latitude_deg = 34.316          # geodetic latitude of the lab
    local_gravity = 9.7952         # m/s^2

    [[anchors]]                    # one table per anchor; ids as the gateway reports them
    id = 1
    x = 1.3                        # m, lab frame (x east, y north, z up)
    y = 1.6
    z = 0.0                        # optional, default 0

    [vehicle]
    start = [6.0, 1.8]             # m, where the vehicle stands at power-up
    heading_deg = 0.0              # initial heading, counter-clockwise from +x
    tag_height = 0.0               # m, tag above the anchors' z = 0 plane
    tag = 16                       # optional: only this tag id's exchanges are used
    router = "0013A20040A1B2D4"    # optional: only this radio's SINS stream is used
    gyro_range_dps = 300           # ADIS16350 range set by SENS/AVG: 300, 150 or 75

    [filters]
    enabled = ["sins", "wsn", "kf", "ekf", "ukf"]   # default for --filters
    # any other key is an EstimatorConfig field (alignment_s, wsn_method, range_bias_m = {1 = 0.3}, ...)

    [timing]
    hold_s = 0.02                  # reorder hold for ranges (docs/host.md, "time order")

Shipped configs (``host/configs/*.toml``) are named by the lab setup, e.g. ``office``;
:func:`load` takes such a name or a file path. Every problem is one line naming the file,
the key and the fix (:class:`ConfigError`).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from common.limits import (ANCHOR_IDS, GRAVITY_M_S2, LATITUDE_DEG, MAX_COORD_M, MAX_HEIGHT_M,
                              RANGE_BIAS_M, RANGE_SCALE, number_problem)

CONFIG_DIR = Path(__file__).resolve().parent / "configs"
DEFAULT = "office"
FILTER_NAMES = ("sins", "wsn", "kf", "ekf", "ukf")  # the estimator's names, in output order
_INF = math.inf
#: The range of every number a [filters] table may set: (lo, hi, lo excluded). Beyond them the
#: filters overflow (1e308), divide by zero (ukf_alpha 0) or never finish (output_period_s 1e-300).
ESTIMATOR_RANGES = {
    "altitude_m": (-1000, 10000, False),
    "x_azimuth_deg": (0, 360, False),
    "alignment_s": (0, 3600, True),
    "output_period_s": (0.001, 60, False),
    "range_sigma_m": (0, 100, True),
    "range_scale": (*RANGE_SCALE, False),
    "vrw_m_s_rt_hr": (0, 1000, True),
    "arw_deg_rt_hr": (0, 1000, True),
    "gyro_bias_instability_dps": (0, 100, False),
    "accel_sigma_m_s2": (0, 100, True),
    "tilt_inflation": (0, 1000, False),
    "jerk_psd": (0, 10000, True),
    "p0_sigma": (0, 100, True),  # each element
    "stationary_sigma": (0, 100, True),
    "reinit_sigma": (0, 100, True),
    "range_bias_m": (*RANGE_BIAS_M, False),  # each anchor's
    "gate_probability": (0, 1, True),  # below 1: the estimator refuses 1
    "gate_reopen_s": (0, 3600, True),
    "extrapolated_after_s": (0, 3600, True),
    "cycle_s": (0.001, 10, False),
    "max_lag_s": (0, 60, False),
    "max_range_m": (0, MAX_COORD_M, True),
    "fix_margin_m": (0, MAX_COORD_M, False),
    "ukf_alpha": (1e-4, 1, False),
    "ukf_beta": (0, 10, False),
    "ukf_kappa": (-3, 10, False),  # n + kappa > 0 for the UKF's n = 6; 3 - n = -3 is the usual
}


class ConfigError(ValueError):
    """A bad host configuration: the message is one line naming the problem and the fix."""


@dataclass(frozen=True)
class HostConfig:
    name: str
    anchors: dict[int, tuple[float, float, float]]
    latitude_deg: float = 0.0
    gravity: float = 9.80665
    start: tuple[float, float] = (0.0, 0.0)
    heading_deg: float = 0.0
    tag_height: float = 0.0
    tag: int | None = None
    router: int | None = None
    gyro_range_dps: int = 300
    filters: tuple[str, ...] = FILTER_NAMES
    estimator: dict[str, Any] = field(default_factory=dict)  # extra EstimatorConfig fields
    hold_s: float = 0.02

    def estimator_config(self, filters: tuple[str, ...] | None = None):
        """The :class:`host.estimator.EstimatorConfig` for *filters* (default: the config's)."""
        from .estimator import EstimatorConfig  # here: scipy is slow to import for --help

        return EstimatorConfig(
            anchors=dict(self.anchors), tag_height=self.tag_height,
            latitude_deg=self.latitude_deg, gravity=self.gravity,
            filters=tuple(filters or self.filters), start=self.start,
            heading0_rad=math.radians(self.heading_deg), gyro_range_dps=self.gyro_range_dps,
            **self.estimator)

    def to_dict(self) -> dict:
        """JSON-able form (a recording's meta); :func:`from_dict` reads it back exactly."""
        d = asdict(self)
        d["anchors"] = [{"id": i, "x": x, "y": y, "z": z}
                        for i, (x, y, z) in sorted(self.anchors.items())]
        d["start"] = list(self.start)
        d["filters"] = list(self.filters)
        d["router"] = None if self.router is None else f"{self.router:016X}"
        return d


def from_dict(d: dict, source: str = "config") -> HostConfig:
    """Inverse of :meth:`HostConfig.to_dict`, checked like a TOML file."""
    data = dict(d)
    name = data.pop("name", source)
    doc = {"site": {"latitude_deg": data.pop("latitude_deg", None),
                    "local_gravity": data.pop("gravity", None)},
           "anchors": data.pop("anchors", None),
           "vehicle": {k: data.pop(k, None) for k in ("start", "heading_deg", "tag_height", "tag",
                                                       "router", "gyro_range_dps")},
           "filters": {"enabled": data.pop("filters", None), **(data.pop("estimator", None) or {})},
           "timing": {"hold_s": data.pop("hold_s", None)}}
    if data:
        raise ConfigError(f"{source}: unknown key {sorted(data)[0]!r}; remove it")
    return _parse(_drop_none(doc), source, name)


def _drop_none(doc: dict) -> dict:
    return {k: ({kk: vv for kk, vv in v.items() if vv is not None} if isinstance(v, dict) else v)
            for k, v in doc.items() if v is not None}


def shipped() -> list[str]:
    """Names of the configs shipped in ``host/configs``."""
    return sorted(p.stem for p in CONFIG_DIR.glob("*.toml"))


def load(name_or_path: str | None = None) -> HostConfig:
    """A shipped config by name (default ``office``) or a TOML file by path."""
    spec = name_or_path or DEFAULT
    path = Path(spec)
    if not path.suffix and not path.exists():
        path = CONFIG_DIR / f"{spec}.toml"
        if not path.is_file():
            raise ConfigError(f"no host config named {spec!r}; use one of {', '.join(shipped())} "
                              f"or a path to a .toml file")
    try:
        text = path.read_text()
    except OSError as e:
        raise ConfigError(f"{path}: cannot read ({e.strerror}); check the path") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e}); fix the syntax") from None
    return _parse(doc, str(path), path.stem)


# -- checking -------------------------------------------------------------------------------

_SECTIONS = {
    "site": {"latitude_deg", "local_gravity"},
    "vehicle": {"start", "heading_deg", "tag_height", "tag", "router", "gyro_range_dps"},
    "timing": {"hold_s"},
}


def _number(where: str, value, lo: float = -_INF, hi: float = _INF, above: bool = False,
            integer: bool = False):
    problem = number_problem(value, lo, hi, integer=integer, above=above)
    if problem:
        raise ConfigError(f"{where} {problem}, not {value!r}")
    return value if integer else float(value)


def _integer(where: str, value, lo: int, hi: int) -> int:
    return _number(where, value, lo, hi, integer=True)


def _estimator_fields() -> dict[str, str]:
    """EstimatorConfig fields a [filters] table may set, with their type annotations."""
    from dataclasses import fields

    from .estimator import EstimatorConfig

    handled = {"anchors", "tag_height", "latitude_deg", "gravity", "filters", "start",
               "heading0_rad", "gyro_range_dps"}
    return {f.name: str(f.type) for f in fields(EstimatorConfig) if f.name not in handled}


def parse_filters(spec, where: str = "--filters") -> tuple[str, ...]:
    """``"all"`` or names (comma string or list of strings) -> names in the estimator's order."""
    names = spec.split(",") if isinstance(spec, str) else spec
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ConfigError(f"{where} must be a list of filter names like "
                          f'["kf", "ukf"], not {spec!r}')
    names = [n.strip() for n in names if n.strip()]
    if names == ["all"]:
        return FILTER_NAMES
    bad = [n for n in names if n not in FILTER_NAMES]
    if bad or not names:
        problem = f"unknown filter {bad[0]!r}" if bad else "no filter given"
        raise ConfigError(f"{where}: {problem}; use a comma list of "
                          f"{', '.join(FILTER_NAMES)} or all")
    return tuple(n for n in FILTER_NAMES if n in names)


def _parse(doc: dict, source: str, name: str) -> HostConfig:
    def err(msg: str) -> ConfigError:
        return ConfigError(f"{source}: {msg}")

    known = set(_SECTIONS) | {"anchors", "filters"}
    for key in doc:
        if key not in known:
            raise err(f"unknown section [{key}]; use {', '.join(sorted(known))}")
    for sec, keys in _SECTIONS.items():
        part = doc.get(sec, {})
        if not isinstance(part, dict):
            raise err(f"[{sec}] must be a table")
        for key in part:
            if key not in keys:
                raise err(f"unknown key {key!r} in [{sec}]; use {', '.join(sorted(keys))}")
    kw: dict[str, Any] = {"name": name}
    try:
        site, veh, timing = doc.get("site", {}), doc.get("vehicle", {}), doc.get("timing", {})
        if "latitude_deg" in site:
            kw["latitude_deg"] = _number("[site] latitude_deg", site["latitude_deg"], *LATITUDE_DEG)
        if "local_gravity" in site:
            kw["gravity"] = _number("[site] local_gravity", site["local_gravity"], *GRAVITY_M_S2)
        kw["anchors"] = _anchors(doc.get("anchors"))
        if "start" in veh:
            start = veh["start"]
            if not isinstance(start, list) or len(start) != 2:
                raise ConfigError(f"[vehicle] start must be [x, y] in metres, not {start!r}")
            kw["start"] = tuple(_number("[vehicle] start", v, -MAX_COORD_M, MAX_COORD_M)
                                for v in start)
        if "heading_deg" in veh:
            kw["heading_deg"] = _number("[vehicle] heading_deg", veh["heading_deg"], -360, 360)
        if "tag_height" in veh:
            kw["tag_height"] = _number("[vehicle] tag_height", veh["tag_height"], -MAX_HEIGHT_M,
                                       MAX_HEIGHT_M)
        if "tag" in veh:
            kw["tag"] = _integer("[vehicle] tag", veh["tag"], *ANCHOR_IDS)
        if "router" in veh:
            r = veh["router"]
            if not (isinstance(r, str) and len(r) == 16
                    and all(c in "0123456789abcdefABCDEF" for c in r)):
                raise ConfigError(f"[vehicle] router must be 16 hex digits (SH+SL), not {r!r}")
            kw["router"] = int(r, 16)
        if "gyro_range_dps" in veh:
            from protocols.adis16350 import GYRO_LSB_DPS  # here: numpy is slow to import for --help

            if veh["gyro_range_dps"] not in GYRO_LSB_DPS or isinstance(veh["gyro_range_dps"], bool):
                raise ConfigError(f"[vehicle] gyro_range_dps must be one of "
                                  f"{', '.join(map(str, GYRO_LSB_DPS))}, not {veh['gyro_range_dps']!r}")
            kw["gyro_range_dps"] = veh["gyro_range_dps"]
        if "hold_s" in timing:
            kw["hold_s"] = _number("[timing] hold_s", timing["hold_s"], 0.0, 1.0)
        if not isinstance(doc.get("filters", {}), dict):
            raise ConfigError("[filters] must be a table")
        filt = dict(doc.get("filters", {}))
        if "enabled" in filt:
            kw["filters"] = parse_filters(filt.pop("enabled"), "[filters] enabled")
        if filt:
            allowed = _estimator_fields()
            for key in filt:
                if key not in allowed:
                    raise ConfigError(f"unknown key {key!r} in [filters]; use enabled, "
                                      f"{', '.join(sorted(allowed))}")
            kw["estimator"] = {k: _estimator_value(k, v, allowed[k], kw["anchors"])
                               for k, v in filt.items()}
        config = HostConfig(**kw)
        try:  # the estimator's own checks judge its fields
            config.estimator_config()
        except (ValueError, TypeError) as e:
            raise ConfigError(f"[filters] {e}") from None
    except ConfigError as e:
        raise err(str(e)) from None
    return config


def _estimator_value(key: str, value, annotation: str, anchors: dict):
    """A TOML (or recording JSON) value of EstimatorConfig field *key* as the estimator takes
    it, checked against the field's type and ESTIMATOR_RANGES: arrays become tuples, tables
    keyed by anchor id get int keys."""
    where = f"[filters] {key}"
    if annotation == "str":
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string in quotes, not {value!r}")
        return value
    if key == "reference_anchor":
        if isinstance(value, bool) or value not in anchors:
            raise ConfigError(f"{where} must be one of the [[anchors]] ids "
                              f"{sorted(anchors)}, not {value!r}")
        return value
    if annotation == "float | None" and value is None:  # off; JSON null in a recording
        return None
    if annotation in ("float", "float | None"):
        return _number(where, value, *ESTIMATOR_RANGES[key])
    if annotation.startswith("tuple[float"):
        n = annotation.count("float")
        if not isinstance(value, list) or len(value) != n:
            raise ConfigError(f"{where} must be a list of {n} numbers, not {value!r}")
        return tuple(_number(f"{where}[{i}]", v, *ESTIMATOR_RANGES[key]) for i, v in enumerate(value))
    if annotation == "Mapping[int, float]":  # per anchor: {1 = 0.3, 2 = 0.25}
        if not isinstance(value, dict):
            raise ConfigError(f"{where} must be a table of anchor id = number like "
                              f"{{1 = 0.3, 2 = 0.25}}, not {value!r}")
        out = {}
        for k, v in value.items():
            aid = int(k) if str(k).isdigit() else None
            if aid not in anchors:
                raise ConfigError(f"{where} names anchor {k!r}, which is not in [[anchors]]; "
                                  f"use the ids {sorted(anchors)}")
            out[aid] = _number(f"{where} {aid}", v, *ESTIMATOR_RANGES[key])
        return out
    raise ConfigError(f"{where}: cannot be set in a config file; remove it")


def _anchors(items) -> dict[int, tuple[float, float, float]]:
    if not isinstance(items, list) or not items:
        raise ConfigError("[[anchors]] missing: give one table per anchor with id, x, y (and z)")
    out: dict[int, tuple[float, float, float]] = {}
    for n, a in enumerate(items, 1):
        if not isinstance(a, dict):
            raise ConfigError(f"anchor #{n} must be a table with id, x, y, z")
        extra = set(a) - {"id", "x", "y", "z"}
        if extra:
            raise ConfigError(f"unknown key {sorted(extra)[0]!r} in anchor #{n}; use id, x, y, z")
        for key in ("id", "x", "y"):
            if key not in a:
                raise ConfigError(f"anchor #{n} has no {key!r}")
        aid = _integer(f"anchor #{n} id", a["id"], *ANCHOR_IDS)
        if aid in out:
            raise ConfigError(f"anchor id {aid} appears twice; ids must be unique")
        out[aid] = (*(_number(f"anchor {aid} {k}", a[k], -MAX_COORD_M, MAX_COORD_M) for k in "xy"),
                    _number(f"anchor {aid} z", a.get("z", 0.0), -MAX_HEIGHT_M, MAX_HEIGHT_M))
    return out
