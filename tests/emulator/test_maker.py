"""The world's maker process (emulator.maker): the events, air frames and ledger marks the
World makes alone, with live device faults injected and removed between blocks, and a child
that keeps none of its parent's descriptors."""
import contextlib
import dataclasses
import os

from navtwin.common.schema import build
from navtwin.emulator.faults import Fault
from navtwin.emulator.fleet import convoy
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.world import World

MS = 1_000_000


def _played(world: World, ahead: bool, starts: dict | None = None) -> tuple[list, list, dict]:
    """Events and air frames of *world*'s first 8 s taken in 130 ms slices (not on blocks),
    a link loss injected live at 1.3 s and removed at 2.6 s and a board reset of vehicle 2
    injected at 4.03 s, as the runner does: each within held, from the time held says. With
    *starts* (what a maker's held said), from those, the World having made as far first: the
    maker makes up to a block ahead of what was taken, so its held says a later time than a
    World that makes on demand."""
    events, air, held = [], [], {}
    with world.ahead() if ahead else contextlib.nullcontext():
        t, loss = 0, None
        while t < 8000 * MS:
            t += 130 * MS
            events += world.advance(t)
            air += world.air(t)
            if t not in (1300 * MS, 2600 * MS, 4030 * MS):
                continue
            with world.held() as made:
                if starts is not None:
                    made = starts[t]
                    while world._generated_ns < made:
                        world._make()
                held[t] = made
                s = made / 1e9
                if t == 1300 * MS:
                    loss = build(Fault, {"kind": "link_loss", "start_s": s}, (("fault", 0),))
                    world.inject(loss)
                elif t == 2600 * MS:
                    world.remove(loss)
                else:
                    world.inject(build(Fault, {"kind": "board_reset", "vehicle": 2, "start_s": s,
                                               "end_s": s + 0.4}, (("fault", 0),)))
    return events, air, held


def test_the_maker_gives_the_worlds_events_air_and_marks_with_live_faults():
    """A convoy of 3 on one coordinator (a shared channel, its drops counted by the child),
    with an anchor outage of its [[faults]] and live faults: the maker
    process gives what the World gives in one process, events, air frames, each mark with
    the parent's own fault object, the held times, and the channel's drop count."""
    sc = convoy(load_scenario("corridor-outage"), 3)
    sc = dataclasses.replace(sc, faults=(*sc.faults, build(Fault, {
        "kind": "anchor_outage", "anchor": 2, "start_s": 1.0, "end_s": 2.5}, (("fault", 0),))))
    alone, made = World(sc, 5), World(sc, 5)
    got = _played(made, ahead=True)
    want = _played(alone, ahead=False, starts=got[2])
    assert got == want
    events, air, starts = got
    # made up to a block ahead of what was taken (the child may not have made it yet)
    assert all(t < s <= t + 2 * World.BLOCK_NS and s % World.BLOCK_NS == 0
               for t, s in starts.items()) and len(starts) == 3
    marked = [m for e in events for m in e.marks]
    kinds = {m["kind"] for m in marked}
    assert {"anchor_outage", "board_reset"} <= kinds and air
    # the packets lost while the link was down (none when held said the same time twice)
    assert ("link_loss" in kinds) == (starts[1300 * MS] < starts[2600 * MS])
    assert all(m["fault"] is sc.faults[-1] for m in marked if m["kind"] == "anchor_outage")
    assert [c.dropped for c in made.channels.values()] == [c.dropped for c in alone.channels.values()]


def test_the_maker_keeps_none_of_its_parents_descriptors():
    """The child holds none of its parent's descriptors (a PTY master held there would keep
    its client from ever seeing the port hang up), only its socket; it ends with the block."""
    sc = load_scenario("office")
    world = World(sc, 1)
    master, slave = os.openpty()
    try:
        with world.ahead():
            world.advance(300 * MS)
            pid = world._maker.pid
            held = [os.readlink(f"/proc/{pid}/fd/{fd}") for fd in os.listdir(f"/proc/{pid}/fd")
                    if int(fd) > 2]
        # its socket, and the memory file of a block it may be writing
        assert sum(h.startswith("socket:") for h in held) == 1
        assert all(h.startswith(("socket:", "/memfd:navtwin-block-")) for h in held), held
        assert not os.path.exists(f"/proc/{pid}/fd")  # ended and reaped
    finally:
        os.close(master)
        os.close(slave)
