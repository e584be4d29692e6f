"""The lab computer's own configuration: its anchor survey, site, vehicle start and tracks.

This is what the host knows about the lab without asking any device. It is read from TOML
and declared on the schema (common.schema: every key with its unit, meaning and checks,
written once; docs/host.md's key table is generated from it, :func:`markdown_table`): the
[site], [vehicle] and [filters] tables are the estimator's settings (host.settings), of
which :meth:`HostConfig.estimator_config` makes each vehicle's EstimatorConfig; the other
sections are declared here::

    [site]
    latitude_deg = 34.316          # geodetic latitude of the lab
    local_gravity = 9.7952         # m/s^2

    [[anchors]]                    # one table per anchor; ids as the gateway reports them
    id = 1
    x = 1.3                        # m, lab frame (x east, y north, z up)
    y = 1.6
    z = 0.0                        # optional, default 0

    [[anchor_grids]]               # and/or a field of anchors on a grid (common.anchorgrid),
    first_id = 1001                # the scenario's own tables; ids unique across both
    origin = [320.0, 160.0]
    spacing_m = 5.0
    count = [21, 21]

    [vehicle]                      # or [[vehicles]], one table per vehicle (below)
    start = [6.0, 1.8]             # m, where the vehicle stands at power-up
    heading_deg = 0.0              # initial heading, counter-clockwise from +x
    tag_height = 0.0               # m, tag above the anchors' z = 0 plane
    tag = 16                       # optional: only this tag id's exchanges are used
    router = "0013A20040A1B2D4"    # optional: only this radio's SINS stream is used
    gyro_range_dps = 300           # ADIS16350 range set by SENS/AVG: 300, 150 or 75

    [filters]
    enabled = ["sins", "wsn", "kf", "ekf", "ukf"]   # default for --filters
    alignment_s = 8.0              # the estimator's shared settings (host.settings.Tuning)
    range_bias_m = {1 = 0.3}       # c_i of 001 per anchor id

    [filters.ukf]                  # a track's own settings (its Settings class, host.tracks)
    tight = "toa"                  # the UKF's range measurement (the EKF's: [filters.ekf])
    alpha = 1.0

    [filters.tracks]               # settings every track that declares them takes (a track's
    gyro_arw_deg_rt_hr = 0.004     # own section wins), e.g. the IMU of 003's three tracks

    [timing]
    hold_s = 0.02                  # reorder hold for ranges (docs/host.md, "time order")

    [calibration]                  # optional: 001's f, c_i, sigma(d) (host.calibration)
    file = "corridor"              # a shipped calibration or a path (relative to this file)

    [output]                       # optional: what each estimate line gives besides x, y
    geodetic = true                # also lat, lon (deg) and h (m) of the estimate's x, y

Vehicles. ``[vehicle]`` is the lab's one vehicle; a lab with several lists them as
``[[vehicles]]`` tables of the same keys (not both). Vehicles are numbered from 1 in that
order (the ``vehicle`` of each estimate line); with more than one, each names its ``tag``
and ``router``, which route the exchanges and SINS streams to it, and the ``sins`` port
(a direct RS-232 line) is vehicle 1's.

Shipped configs (``host/configs/*.toml``) are named by the lab setup, e.g. ``office``;
:func:`load` takes such a name or a file path. Every problem is one line naming the file,
the key and the fix (:class:`ConfigError`).
"""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from pathlib import Path

from navtwin.common.limits import ANCHOR_IDS, MAX_COORD_M, MAX_HEIGHT_M, RANGE_BIAS_M
from navtwin.common import tomlfile
from navtwin.common.anchorgrid import AnchorGrid, expand
from navtwin.common.geodesy import LocalFrame
from navtwin.common.extras import require
from navtwin.common.schema import REQUIRED, Invalid, between, boolean, build, dump_document, key, plain, rows

from . import calibration as range_calibration
from . import tracks
from .calibration import Calibration, CalibrationError
from .settings import EstimatorConfig, Site, Tuning, Vehicle

CONFIG_DIR = Path(__file__).resolve().parent / "configs"
DEFAULT = "office"
#: The built-in track names, for host/cli.py's --filters help (the CLI layer can ask
#: host.tracks.names() instead, which also lists the registered tracks).


class ConfigError(ValueError):
    """A bad host configuration: the message is one line naming the problem and the fix (a
    newline in a path or value it quotes is shown as ``\\n``)."""

    def __init__(self, message: str) -> None:
        super().__init__(message.replace("\n", "\\n"))


@dataclass(frozen=True)
class Anchor:
    id: int = key(REQUIRED, "", "anchor id as the gateway reports it", between(*ANCHOR_IDS))
    x: float = key(REQUIRED, "m", "lab frame (x east, y north)", between(-MAX_COORD_M, MAX_COORD_M))
    y: float = key(REQUIRED, "m", "lab frame", between(-MAX_COORD_M, MAX_COORD_M))
    z: float = key(0.0, "m", "height, the tag's datum", between(-MAX_HEIGHT_M, MAX_HEIGHT_M))


@dataclass(frozen=True)
class Timing:
    hold_s: float = key(0.02, "s", "reorder hold for ranges (docs/host.md, time order)",
                        between(0.0, 1.0))


@dataclass(frozen=True)
class Output:
    """[output]: what each estimate line gives besides its x, y (host.output)."""

    geodetic: bool = key(False, "", "each estimate line also gives lat, lon (deg) "
                         "and h (m, WGS-84) of its x, y on the floor (z = 0), through the area's "
                         "frame: [site] and [filters] x_azimuth_deg (common.geodesy)",
                         boolean("write geodetic = true"))


@dataclass(frozen=True)
class Lab:
    """The sections other than [filters]."""

    anchors: tuple[Anchor, ...] = key((), "", "the anchor survey")
    anchor_grids: tuple[AnchorGrid, ...] | None = key(None, "", "fields of anchors on a grid")
    site: Site = Site()
    vehicles: tuple[Vehicle, ...] = key((Vehicle(),), "", "the vehicles, 1 first ([vehicle] "
                                        "for one)")
    timing: Timing = Timing()
    output: Output = Output()

    def __post_init__(self):
        if len(self.vehicles) > 1:
            for field_ in ("tag", "router"):
                values = [getattr(v, field_) for v in self.vehicles]
                if None in values:
                    n = values.index(None) + 1
                    raise Invalid(f"[[vehicles]] #{n} {field_}", "is needed when there are several "
                                  f"vehicles (it routes their data); give each vehicle its {field_}")
                if len(set(values)) < len(values):
                    raise Invalid(f"[[vehicles]] {field_}", f"{values} repeats one; give each "
                                  f"vehicle its own {field_}")


@dataclass(frozen=True)
class HostConfig:
    name: str
    lab: Lab
    filters: tuple[str, ...] = tracks.DEFAULT
    tuning: Tuning = Tuning()  # the estimator's shared settings
    range_bias_m: dict[int, float] = field(default_factory=dict)
    settings: dict[str, object] = field(default_factory=dict)  # track name -> its Settings
    calibration: Calibration | None = None  # replaces range_scale and range_bias_m

    # the lab's words, as the pipeline and the service use them
    @functools.cached_property
    def anchors(self) -> dict[int, tuple[float, float, float]]:
        """Every anchor's position by id: the [[anchors]] tables, then the [[anchor_grids]]'
        nodes (a grid's planar z, none, is the anchors' z = 0 plane)."""
        out = {a.id: (a.x, a.y, a.z) for a in self.lab.anchors}
        out.update((i, (x, y, 0.0 if z is None else z)) for i, x, y, z in expand(self.lab.anchor_grids or ()))
        return out

    latitude_deg = property(lambda self: self.lab.site.latitude_deg)
    local_gravity = property(lambda self: self.lab.site.local_gravity)
    vehicles = property(lambda self: self.lab.vehicles)
    hold_s = property(lambda self: self.lab.timing.hold_s)

    @property
    def output_frame(self) -> LocalFrame | None:
        """The area's frame on the earth when [output] geodetic asks for lat, lon, h in the
        estimate lines (host.output.estimate_line), else None."""
        if not self.lab.output.geodetic:
            return None
        site = self.lab.site
        return LocalFrame(site.latitude_deg, site.longitude_deg, site.height_m,
                          self.tuning.x_azimuth_deg)

    def estimator_config(self, filters: tuple[str, ...] | None = None,
                         vehicle: int = 1) -> EstimatorConfig:
        """The :class:`navtwin.host.settings.EstimatorConfig` of vehicle *vehicle* (numbered
        from 1) for *filters* (default: the config's): made of the [site], that vehicle's and
        the [filters] tables, checked once there."""
        return EstimatorConfig.of(
            self.lab.site, self.vehicles[vehicle - 1], self.tuning, anchors=self.anchors,
            range_bias_m=dict(self.range_bias_m), filters=tuple(filters or self.filters),
            settings=dict(self.settings), vehicle=vehicle, calibration=self.calibration)

    def to_dict(self) -> dict:
        """JSON-able form, the TOML file's layout (a recording's meta); :func:`from_dict`
        reads it back exactly."""
        doc = plain(self.lab)
        if not doc["anchors"]:  # a field of grids only
            del doc["anchors"]
        if len(self.vehicles) == 1:  # the one-vehicle layout: [vehicle]
            doc["vehicle"] = doc.pop("vehicles")[0]
        filters = {"enabled": list(self.filters), **plain(self.tuning)}
        if self.range_bias_m:
            filters["range_bias_m"] = {str(a): c for a, c in sorted(self.range_bias_m.items())}
        for name, s in self.settings.items():
            filters[name] = plain(s)
        out = {"name": self.name, **doc, "filters": filters}
        if self.calibration is not None:  # inline: a recording replays without the file
            out["calibration"] = self.calibration.to_dict()
        return out

    def to_toml(self) -> str:
        """The config as a TOML file that :func:`load` reads back equal but for its name (the
        file's): the lab writes the configs of the hosts it starts."""
        return dump_document({k: v for k, v in self.to_dict().items() if k != "name"})


def with_calibration(config: HostConfig, calibration: Calibration) -> HostConfig:
    """*config* with *calibration* (``navtwin host --calibration``) replacing its range
    correction, checked as a [calibration] section is."""
    unknown = sorted(set(calibration.bias) - set(config.anchors))
    if unknown:
        raise ConfigError(f"{calibration.source} calibrates anchor {unknown[0]}, which is not in "
                          f"the config's [[anchors]]; use the calibration of this lab")
    tuning = dataclasses.replace(config.tuning, range_scale=1.0)
    return _checked(dataclasses.replace(config, tuning=tuning, range_bias_m={},
                                        calibration=calibration))


def _checked(config: HostConfig) -> HostConfig:
    """*config*, once the estimator's own checks have judged what spans sections (3 anchors
    at least, a track's keys that need the calibration)."""
    try:
        config.estimator_config()
    except (ValueError, TypeError) as e:
        raise ConfigError(f"[filters] {e}") from None
    return config


#: [filters] keys of the first recorded layout that now live in a track's own section.
_MOVED = {"ukf_alpha": ("ukf", "alpha"), "ukf_beta": ("ukf", "beta"), "ukf_kappa": ("ukf", "kappa"),
          "vrw_m_s_rt_hr": ("sins", "vrw_m_s_rt_hr")}
_FLAT_VEHICLE = ("start", "heading_deg", "tag_height", "tag", "router", "gyro_range_dps")


def _from_flat(d: dict) -> dict:
    """The layout host recordings had before the config had sections (navtwin 0.1: one flat
    table, ``filters`` the enabled list, ``estimator`` the [filters] keys) in today's."""
    filters: dict = {"enabled": d["filters"]}
    for k, v in (d.get("estimator") or {}).items():
        track, name = _MOVED.get(k, (None, k))
        (filters.setdefault(track, {}) if track else filters)[name] = v
    site = {new: d[old] for old, new in (("latitude_deg", "latitude_deg"), ("gravity", "local_gravity"))
            if old in d}
    out = {"name": d.get("name"), "site": site, "anchors": d.get("anchors"),
           "vehicle": {k: d[k] for k in _FLAT_VEHICLE if d.get(k) is not None}, "filters": filters}
    if "hold_s" in d:
        out["timing"] = {"hold_s": d["hold_s"]}
    return out


#: The tracks that ``tight`` in [filters] set, in the layout before it moved to their sections.
_SHARED_TIGHT = ("ekf", "ukf")


def _from_shared_tight(filt: dict) -> dict:
    """The [filters] of the layout with ``tight`` shared (configs and host recordings written
    before issue 18, the flat navtwin 0.1 layout too) in today's: ``tight = X`` there meant X
    for both the EKF and the UKF, so it goes to [filters.ekf] and [filters.ukf], where a
    ``tight`` of their own wins."""
    filt = dict(filt)
    if "tight" in filt:
        shared = filt.pop("tight")
        for track in _SHARED_TIGHT:
            own = filt.get(track, {})
            if isinstance(own, dict):  # else the track's section is refused as not a table
                filt[track] = {"tight": shared, **own}
    return filt


def _track_settings(filt: dict) -> dict:
    """Each track's Settings from its own [filters.NAME] over [filters.tracks], the keys that
    every track declaring them takes (003's three tracks share their IMU's figures); a shared
    key no track declares is refused. Pops what it takes from *filt*."""
    shared = filt.pop("tracks", {})
    if not isinstance(shared, dict):
        raise ConfigError("[filters.tracks] must be a table")
    settings, taken = {}, set()
    for track in tracks.names():
        cls = tracks.get(track)
        own = filt.pop(track, None)
        mine = {k: v for k, v in shared.items() if k in {f.name for f in dataclasses.fields(cls.Settings)}} \
            if dataclasses.is_dataclass(cls.Settings) else {}
        taken |= mine.keys()
        if own is None and not mine:
            continue
        if own is not None and not isinstance(own, dict):
            mine = own  # refused by build with the track's own key path
        else:
            mine = {**mine, **(own or {})}
        settings[track] = build(cls.Settings, mine, (("filters", 0), (track, 0)))
    unknown = sorted(shared.keys() - taken)
    if unknown:
        raise ConfigError(f"[filters.tracks] {unknown[0]} is a setting of no track; "
                          "write it in the section of the track that has it ([filters.NAME])")
    return settings


def from_dict(d: dict, source: str = "config") -> HostConfig:
    """Inverse of :meth:`HostConfig.to_dict`, checked like a TOML file; a config recorded in
    the first layout (navtwin 0.1) is read too, so older host recordings still replay."""
    if not isinstance(d, dict):
        raise ConfigError(f"{source}: must be a table of the config's sections; re-record it")
    data = _from_flat(d) if isinstance(d.get("filters"), list) else dict(d)
    name = data.pop("name", source)
    return _parse(data, source, str(name))


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
    return _parse(tomlfile.read(path, ConfigError), str(path), path.stem, path.parent)


# -- checking -------------------------------------------------------------------------------

def parse_filters(spec, where: str = "filters") -> tuple[str, ...]:
    """``"all"`` or track names (comma string or list of strings) -> names in output order
    (host.tracks.names())."""
    known = tracks.names()
    names = spec.split(",") if isinstance(spec, str) else spec
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ConfigError(f"{where} must be a list of filter names like "
                          f'["kf", "ukf"], not {spec!r}')
    names = [n.strip() for n in names if n.strip()]
    if names == ["all"]:
        names = list(known)
    bad = [n for n in names if n not in known]
    if bad or not names:
        problem = f"unknown filter {bad[0]!r}" if bad else "no filter given"
        raise ConfigError(f"{where}: {problem}; use a comma list of {', '.join(known)} or all")
    chosen = tuple(n for n in known if n in names)
    for n in chosen:  # MissingExtra's one line, before a run begins
        for module, extra in tracks.get(n).requires:
            require(module, extra, n)
    return chosen


def _parse(doc: dict, source: str, name: str, directory: Path | None = None) -> HostConfig:
    try:
        return _config(doc, name, directory)
    except (ConfigError, Invalid, CalibrationError) as e:
        raise ConfigError(f"{source}: {e}") from None


def _calibration(table, directory: Path | None) -> Calibration:
    """``[calibration]``: ``file = NAME|PATH`` (relative to the config's directory), or the
    calibration itself inline (a recording's meta)."""
    if not isinstance(table, dict):
        raise ConfigError('[calibration] must be a table like file = "corridor"')
    if "file" not in table:
        return range_calibration.parse(table, "[calibration]")
    if set(table) != {"file"} or not isinstance(table["file"], str) or not table["file"]:
        raise ConfigError('[calibration] file must be the only key, a calibration name or path '
                          'in quotes like file = "corridor"')
    path = Path(table["file"])
    if directory is not None and path.suffix and not path.is_absolute():
        path = directory / path
    return range_calibration.load(path)


def _config(doc: dict, name: str, directory: Path | None = None) -> HostConfig:
    known = [f.name for f in dataclasses.fields(Lab)] + ["vehicle", "filters", "calibration"]
    for section in doc:
        if section not in known:
            raise ConfigError(f"unknown section [{section}]; use {', '.join(sorted(known))}")
    if "anchors" not in doc and "anchor_grids" not in doc:
        raise ConfigError("[[anchors]] missing: give one table per anchor with id, x, y (and z), "
                          "or [[anchor_grids]]")
    lab = Lab(anchors=_anchors(doc["anchors"]) if "anchors" in doc else (), anchor_grids=_grids(doc),
              vehicles=_vehicles(doc),
              **{f.name: build(type(f.default), doc[f.name], ((f.name, 0),))
                 for f in dataclasses.fields(Lab) if f.name in ("site", "timing", "output")
                 and f.name in doc})
    filt = doc.get("filters", {})
    if not isinstance(filt, dict):
        raise ConfigError("[filters] must be a table")
    filt = _from_shared_tight(filt)
    anchors = {a.id for a in lab.anchors}
    for k, g in enumerate(lab.anchor_grids or ()):
        if clash := anchors.intersection(g.ids):
            raise ConfigError(f"[[anchor_grids]] #{k + 1} first_id reuses anchor id {min(clash)} of "
                              "[[anchors]]; give the grid its own id range")
    anchors.update(i for g in lab.anchor_grids or () for i in g.ids)
    kw: dict = {}
    if "enabled" in filt:
        kw["filters"] = parse_filters(filt.pop("enabled"), "[filters] enabled")
    if "range_bias_m" in filt:
        kw["range_bias_m"] = _range_bias(filt.pop("range_bias_m"), anchors)
    settings = _track_settings(filt)
    tuning = build(Tuning, filt, (("filters", 0),))
    if tuning.reference_anchor not in anchors:
        raise ConfigError(f"[filters] reference_anchor must be one of the [[anchors]] ids "
                          f"{sorted(anchors)}, not {tuning.reference_anchor}")
    if "calibration" in doc:
        kw["calibration"] = _calibration(doc["calibration"], directory)
        if "range_bias_m" in kw or tuning.range_scale != 1.0:
            raise ConfigError("[filters] range_scale or range_bias_m is set beside [calibration], "
                              "which gives both; remove them or the [calibration] section")
    config = HostConfig(name=name, lab=lab, tuning=tuning, settings=settings,
                        **{k: v for k, v in kw.items() if k != "calibration"})
    if "calibration" in kw:
        return with_calibration(config, kw["calibration"])
    return _checked(config)


def _anchors(items) -> tuple[Anchor, ...]:
    """The [[anchors]] tables, named by id in messages once the id is good."""
    if not isinstance(items, list) or not items:
        raise ConfigError("[[anchors]] missing: give one table per anchor with id, x, y (and z)")
    out: list[Anchor] = []
    for n, item in enumerate(items, 1):
        try:
            a = build(Anchor, item, (("anchors", n),))
        except Invalid as e:
            aid = item.get("id") if isinstance(item, dict) else None
            who = f"anchor {aid}" if e.where.split()[-1] != "id" and isinstance(aid, int) \
                and not isinstance(aid, bool) else f"anchor #{n}"
            at = e.where.split()[-1] if e.where.startswith("[[anchors]] #") and \
                len(e.where.split()) > 2 else ""
            raise ConfigError(f"{who} {at} {e.problem}".replace("  ", " ")) from None
        if any(b.id == a.id for b in out):
            raise ConfigError(f"anchor id {a.id} appears twice; ids must be unique")
        out.append(a)
    return tuple(out)


def _grids(doc: dict) -> tuple[AnchorGrid, ...] | None:
    """The [[anchor_grids]] tables, their ids unique among them (common.anchorgrid.expand)."""
    if "anchor_grids" not in doc:
        return None
    items = doc["anchor_grids"]
    if not isinstance(items, list) or not items or not all(isinstance(g, dict) for g in items):
        raise ConfigError("anchor_grids must be an array of tables; write each grid as [[anchor_grids]]")
    grids = tuple(build(AnchorGrid, item, (("anchor_grids", n),)) for n, item in enumerate(items, 1))
    expand(grids)
    return grids


def _vehicles(doc: dict) -> tuple[Vehicle, ...]:
    """``[vehicle]`` (one) or ``[[vehicles]]`` (one table each), not both."""
    if "vehicle" in doc and "vehicles" in doc:
        raise ConfigError("both [vehicle] and [[vehicles]] given; write one vehicle as [vehicle] "
                          "or every vehicle as [[vehicles]]")
    if "vehicles" not in doc:
        return (build(Vehicle, doc.get("vehicle", {}), (("vehicle", 0),)),)
    items = doc["vehicles"]
    if not isinstance(items, list) or not items or not all(isinstance(v, dict) for v in items):
        raise ConfigError("vehicles must be an array of tables; write each vehicle as [[vehicles]]")
    return tuple(build(Vehicle, item, (("vehicles", n),)) for n, item in enumerate(items, 1))


@dataclass(frozen=True)
class _RangeBias:
    range_bias_m: dict[int, float] = key(REQUIRED, "m", "c_i of 001 per anchor id",
                                         between(*RANGE_BIAS_M), ids=("anchor", ANCHOR_IDS))


def _range_bias(value, anchors: set[int]) -> dict[int, float]:
    """``range_bias_m = {1 = 0.3, 2 = 0.25}``: c_i of 001 per anchor id of [[anchors]]."""
    out = build(_RangeBias, {"range_bias_m": value}, (("filters", 0),)).range_bias_m
    for aid in out:
        if aid not in anchors:
            raise ConfigError(f"[filters] range_bias_m names anchor {str(aid)!r}, which is not in "
                              f"[[anchors]]; use the ids {sorted(anchors)}")
    return out


# -- documentation -------------------------------------------------------------------------

def markdown_table() -> str:
    """docs/host.md's table of every host config key: the sections, [filters] (shared), then
    each built-in track's [filters.<name>]."""
    lines = ["| key | unit | default | valid | meaning |", "|---|---|---|---|---|"]
    extra = [("filters.enabled", "", "sins,wsn,kf,ekf,ukf", "track names (host.tracks)", "the tracks to run"),
             ("filters.range_bias_m", "m", "{}", f"per anchor id, in [{RANGE_BIAS_M[0]}, "
              f"{RANGE_BIAS_M[1]}]", "c_i of 001: distance = (reported - c_i) / f"),
             ("calibration.file", "", "none", "a name in host/calibrations or a path",
              "001's calibration (navtwin calibrate): its f and c_i replace range_scale and "
              "range_bias_m, its sigma(d) is est.calibration.sigma")]
    all_rows = rows(Lab) + extra + rows(Tuning, "filters.")
    for track in tracks.BUILT_IN:
        all_rows += rows(tracks.get(track).Settings, f"filters.{track}.")
    for name, unit, default, valid, doc in all_rows:
        lines.append(f"| `{name}` | {unit} | `{default}` | {valid} | {doc} |")
    return "\n".join(lines) + "\n"
