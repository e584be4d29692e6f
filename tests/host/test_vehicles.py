"""A lab with several vehicles: each vehicle's SINS stream and exchanges reach its own
estimator, routed by its radio and tag, and its estimates say which vehicle they are."""
import dataclasses
import json
import math

import pytest

from navtwin.host import config as host_config
from navtwin.host.config import ConfigError, Vehicle
from navtwin.host.output import estimate_line
from navtwin.host.pipeline import Pipeline

from ..helpers import OFFICE
from .synthetic import ROUTER64, synthetic_chunks

ROUTER2 = 0x0013A20040A1C0DE
ONE = Vehicle(start=(6.0, 1.8), tag=0x10, router=f"{ROUTER64:016X}")
TWO = Vehicle(start=(3.0, 4.0), tag=0x11, router=f"{ROUTER2:016X}")


def config(*vehicles):
    return dataclasses.replace(OFFICE, lab=dataclasses.replace(OFFICE.lab, vehicles=vehicles))


def run(cfg, chunks):
    pipe = Pipeline(cfg, ("sins", "wsn", "ekf"))
    lines = []
    for port, data, t_ns in chunks:
        lines += map(estimate_line, pipe.feed(port, data, t_ns))
    lines += map(estimate_line, pipe.finish())
    return pipe, lines


def merged(first, *others):
    """Chunks of several labs in arrival order; *first*'s stamps kept, the others' moved on
    by a nanosecond where they meet one already taken (stamps are unique)."""
    taken = {t for _, _, t in first}
    out = list(first)
    for chunks in others:
        for p, d, t in chunks:
            while t in taken:
                t += 1
            taken.add(t)
            out.append((p, d, t))
    return sorted(out, key=lambda c: c[2])


def test_each_vehicle_gets_its_own_stream_and_the_first_is_unchanged_by_the_second():
    both = config(ONE, TWO)
    first = list(synthetic_chunks(both, 12.0, seed=5))
    # vehicle 2 stands elsewhere, on another radio; one gateway reports vehicle 1's tag only,
    # so the anchor network's counter stays one sequence
    second = list(synthetic_chunks(both, 12.0, seed=6, router64=ROUTER2, vehicle=2,
                                   ranging=False, start_s=0.055))
    _, alone = run(config(ONE), merged(first))
    pipe, lines = run(both, merged(first, second))
    v1 = [x for x in lines if '"vehicle":1,' in x]
    v2 = [x for x in lines if '"vehicle":2,' in x]
    assert v1 == alone  # vehicle 2's bytes change nothing of vehicle 1's estimates
    assert len(v2) > 0 and len(v1) + len(v2) == len(lines)
    st = pipe.stats()
    assert [v["router"] for v in st["vehicles"]] == [f"{ROUTER64:016X}", f"{ROUTER2:016X}"]
    assert st["counts"]["imu"] == 2 * 1200 and st["counts"].get("imu_other_router", 0) == 0
    # each vehicle's strapdown stands where its config says: 12 s of a standing, noisy IMU
    last = {(e["vehicle"], e["filter"]): e for e in map(json.loads, lines)}
    for n, v in ((1, ONE), (2, TWO)):
        e = last[(n, "sins")]
        assert math.dist((e["x"], e["y"]), v.start) < 0.5, (n, e)
    assert (2, "wsn") not in last  # no exchange of tag 0x11: no WSN fix for vehicle 2


def test_exchanges_of_a_tag_no_vehicle_has_are_counted_not_used():
    both = config(ONE, TWO)
    stray = list(synthetic_chunks(both, 3.0, seed=7, tag=0x12))
    pipe, lines = run(both, stray)
    assert pipe.counts["reports_other_tag"] == pipe.counts["reports"] > 0
    assert pipe.counts.get("ranges", 0) == 0


@pytest.mark.parametrize("vehicles, message", [
    ((ONE, dataclasses.replace(TWO, tag=None)), r"\[\[vehicles\]\] #2 tag is needed"),
    ((ONE, dataclasses.replace(TWO, router=ONE.router)), r"router .* repeats one"),
])
def test_several_vehicles_each_need_their_own_tag_and_router(vehicles, message):
    with pytest.raises(host_config.Invalid, match=message):
        config(*vehicles)


def test_vehicles_tables_load_round_trip_and_refuse_both_forms(tmp_path):
    text = (host_config.CONFIG_DIR / "office.toml").read_text()
    head = text[:text.index("[vehicle]")]
    two = head + ('[[vehicles]]\nstart = [6.0, 1.8]\ntag = 16\nrouter = "0013A20040A1B2D4"\n\n'
                  '[[vehicles]]\nstart = [3.0, 4.0]\ntag = 17\nrouter = "0013A20040A1C0DE"\n')
    path = tmp_path / "two.toml"
    path.write_text(two)
    cfg = host_config.load(str(path))
    assert [v.start for v in cfg.vehicles] == [(6.0, 1.8), (3.0, 4.0)]
    assert host_config.from_dict(cfg.to_dict()) == dataclasses.replace(cfg, name=cfg.name)
    assert cfg.estimator_config(vehicle=2).start == (3.0, 4.0)
    path.write_text(two + "\n[vehicle]\nstart = [1.0, 1.0]\n")
    with pytest.raises(ConfigError, match=r"both \[vehicle\] and \[\[vehicles\]\] given"):
        host_config.load(str(path))
