"""The audit: did the host lose only what the injected faults damaged?

The host's decisions are those of its decoders on the bytes it read, and its recording holds
exactly those bytes: replaying them gives the same frames (the architecture's rule: same
bytes, same estimates), so the audit decodes them again instead of trusting a log.

``navtwin audit EMULATOR_RECORDING HOST_RECORDING`` compares, per port both recorded, the
bytes the emulator delivered (``<port>.bin``, after its line faults) with the bytes the host
read, and the emulator's fault ledger (``faults.jsonl``, emulator.ledger) with what the
host's decoder made of them. Three checks, each of which can fail:

1. **intact -> accepted**: every frame of the delivered stream that no byte-changing
   injection touched, and that the host saw whole, was decoded by the host (same decoder,
   protocols.stream);
2. **rejected -> injected**: every byte the host's decoder rejected (garbage, bad CRC or
   checksum, truncated, ...) lies in a frame or run that an injection touched, or at an edge
   of what the host saw (it attached, or a cable was pulled, mid-frame);
3. **the ledger is accounted for**: every byte-changing ledger entry inside what the host saw
   overlaps bytes the host rejected (a damaged frame was not accepted as good), or is one of
   the bit flips of an undetectable frame (below); entries of kinds that only move bytes in
   time (latency, bandwidth, slicing) must touch accepted frames only.

Undetectable frames. An integrity check is a sum of the bytes: bit flips can cancel in it
(an XBee checksum is an 8-bit sum, so a flip of bit k 0 -> 1 in one byte and 1 -> 0 in
another leaves it valid; a CRC-16, one pattern in 65536). Such a frame is accepted as good by
any decoder, the host's too; no host can reject it. The ledger names the bits each flip
changed (``mask``), so the audit proves the collision instead of trusting it: a damaged frame
the host accepted, touched only by bit flips, whose bytes with the flips undone are again a
frame of the same length, is counted ``undetectable``, and its flips are accounted for. Any
other damaged frame the host accepted still fails check 3.

Wholeness. The host's recording is proven whole by its read columns (protocols.recording,
``Read``: the bytes its reader had read from the port before each read, counted as it read):
a read missing from the recording (a gap in ``read_offset``), recorded twice or out of order
fails the audit, naming the port and the index line. A recording without them (older
navtwin) is audited as before, with a note that its wholeness is not proven. The last reads
of a port have no later read to witness them: a run's end is not judged.

Alignment. The host's bytes of a port are located in the emulator's as a sequence of
slices (a host that attached late sees a suffix; one whose cable was pulled, pieces); bytes
the host read that the emulator never delivered fail the audit. Bytes the emulator delivered
that the host never read are reported, not judged: the frames in them are "unseen", counted
by cause where the host saw it (``unseen``): ``before_attach``, ``port_down`` (the host
reopened the port before its next read: unplugged, emulator restarted), ``second_reader``
(the host found bytes taken by another reader before its next read), ``after_last_read``,
and ``no_cause_seen`` (a PTY overflow, a reader that took bytes unseen; in a recording
without read columns, every gap between reads).

Each port is audited at the level of its own frames (its declaration's ``frames``, protocols.ports):
the xbee port at the API-frame level, in the API mode the emulator recorded at its
start (a run whose coordinator switched mode under the host is not auditable so).
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from itertools import accumulate
from pathlib import Path

from navtwin.emulator.faults import Fault
from navtwin.protocols.recording import Read, Recording
from navtwin.protocols import formats, ports as lab_ports
from navtwin.protocols.stream import DecodeError, Frame


class AuditError(ValueError):
    """Recordings that cannot be audited; one line naming the fix."""


def _decoder(port: str, escaped: bool):
    """A decoder of the port's own frames (the audit judges frames, not what they carry)."""
    return formats.get(lab_ports.get(port).frame_format).make(escaped=escaped)


def align(reads: list[bytes], emu: bytes) -> tuple[list[tuple[int, int, int]], int]:
    """``(host_offset, emu_offset, length)`` slices that map the host's *reads* (its
    recording's chunks, in order) into *emu*, and how many host bytes match nothing the
    emulator sent after the previous slice (foreign). One read is contiguous in the stream
    it was taken from (a tty read takes a prefix of its buffer), so each read is placed
    where it continues the last one, or else at its next occurrence."""
    out: list[list[int]] = []
    h = e = foreign = 0
    for data in reads:
        n = len(data)
        if emu[e:e + n] == data:
            at = e
        else:
            at = emu.find(data, e)
            if at < 0:
                foreign += n
                h += n
                continue
        if out and out[-1][0] + out[-1][2] == h and out[-1][1] + out[-1][2] == at:
            out[-1][2] += n  # continues the slice
        else:
            out.append([h, at, n])
        h, e = h + n, at + n
    return [tuple(x) for x in out], foreign


@dataclass
class PortAudit:
    port: str
    emulator_bytes: int = 0
    host_bytes: int = 0
    unseen_bytes: int = 0
    unseen: dict[str, int] = field(default_factory=dict)  # unseen bytes by cause
    frames: int = 0  # frames in the delivered stream, inside what the host saw
    intact: int = 0
    damaged: int = 0
    undetectable: int = 0  # damaged frames whose bit flips left the integrity check valid
    accepted: int = 0
    rejected_bytes: int = 0
    injections: int = 0  # byte-changing ledger entries inside what the host saw
    timing_injections: int = 0
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def _overlaps(ranges: list[tuple[int, int]], starts: list[int], lo: int, hi: int,
              ends: bool = False) -> bool:
    """Whether [lo, hi) meets a range of *ranges* (sorted by start). A removal is a point
    (p, p): it meets [lo, hi) when lo < p < hi, and with *ends* also at p == lo or p == hi
    (bytes removed at either end of a rejected run are its cause: a frame that lost its
    first or its last byte). With *ends* a range that starts at hi meets it too: a changed
    byte that cut the run short (a flip that made a start delimiter inside the frame ends
    the frame before it, so the rejected run stops just short of the byte that was hit)."""
    i = bisect.bisect_right(starts, hi)
    for a, b in reversed(ranges[max(0, i - 64):i]):  # ranges are short and sorted
        if a == b:
            if lo < a < hi or (ends and a in (lo, hi)):
                return True
        elif (a < hi and b > lo) or (ends and a == hi):
            return True
    return False


def wholeness(port: str, sizes: list[int], marks: list[Read]) -> list[str]:
    """The problems of a host's reads of *port* as recorded (their sizes and read columns, in
    index order): reads out of order, bytes read and not recorded, or recorded twice."""
    problems = []
    back = next((i for i in range(1, len(marks))
                 if any(a < b for a, b in zip(marks[i], marks[i - 1]))), None)
    if back is not None:
        problems.append(f"{port}: the host's reads are out of order in its recording: "
                        f"{port}.csv line {back + 2} holds the read at byte {marks[back].offset} "
                        f"of the port, after the read at byte {marks[back - 1].offset}")
    end, lost, gaps, twice = 0, 0, [], []
    for i in sorted(range(len(marks)), key=lambda i: marks[i].offset):
        if marks[i].offset > end:
            lost += marks[i].offset - end
            gaps.append((i, end))
        elif marks[i].offset < end:
            twice.append(i)
        end = max(end, marks[i].offset + sizes[i])
    if gaps:
        i, at = gaps[0]
        problems.append(f"{port}: {lost} bytes the host read are missing from its recording "
                        f"({len(gaps)} gaps; the first at byte {at} of the port, before "
                        f"{port}.csv line {i + 2})")
    if twice:
        problems.append(f"{port}: {len(twice)} reads repeat bytes the host's recording already "
                        f"holds (the first at {port}.csv line {twice[0] + 2})")
    return problems


def _unseen(emu_size: int, slices: list[tuple[int, int, int]], sizes: list[int],
            marks: list[Read] | None) -> dict[str, int]:
    """The emulator's bytes between the slices the host saw, by cause (module docstring): a
    gap's cause is what the host counted between the reads on either side of it."""
    starts = list(accumulate(sizes, initial=0))  # where each read starts in the host's bytes
    causes: dict[str, int] = {}

    def add(cause: str, n: int) -> None:
        if n:
            causes[cause] = causes.get(cause, 0) + n

    end = 0
    for k, (h, e, n) in enumerate(slices):
        if k == 0:
            add("before_attach", e)
        elif marks is None:
            add("no_cause_seen", e - end)
        else:
            i = bisect.bisect_left(starts, h)  # a slice starts with a read
            add(_cause(marks[i - 1], marks[i]), e - end)
        end = e + n
    add("after_last_read" if slices else "before_attach", emu_size - end)
    return causes


def _cause(before: Read, now: Read) -> str:
    """Why the host missed bytes between two of its reads, as far as it saw."""
    if now.reconnects > before.reconnects:
        return "port_down"
    return "second_reader" if now.contended > before.contended else "no_cause_seen"


def _changes_bytes(kind: str) -> bool:
    """Whether fault *kind* may change bytes (a kind no longer installed is taken to)."""
    return kind not in Fault.KINDS or getattr(Fault.KINDS.get(kind), "CHANGES_BYTES", True)


def audit_port(port: str, emu: bytes, reads: list[bytes], entries: list[dict],
               escaped: bool, marks: list[Read] | None = None) -> PortAudit:
    """The audit of one port (module docstring); *marks*: the reads' read columns, when the
    host's recording has them."""
    host = b"".join(reads)
    r = PortAudit(port, len(emu), len(host))
    sizes = [len(x) for x in reads]
    if marks is not None:
        r.problems += wholeness(port, sizes, marks)
    slices, foreign = align(reads, emu)
    if foreign:
        r.problems.append(f"{port}: the host read {foreign} bytes the emulator never sent "
                          "(are these recordings of the same run?)")
    seen = [(e, e + n) for _, e, n in slices]
    r.unseen_bytes = len(emu) - sum(n for _, _, n in slices)
    r.unseen = _unseen(len(emu), slices, sizes, marks)
    seen_starts = [a for a, _ in seen]

    def inside(lo: int, hi: int) -> bool:  # wholly inside one slice the host saw
        i = bisect.bisect_right(seen_starts, lo) - 1
        return i >= 0 and seen[i][0] <= lo and hi <= seen[i][1]

    changing = [e for e in entries if e["port"] == port and e.get("direction", "to_host") != "to_device"
                and e["start"] is not None and _changes_bytes(e["kind"])]
    timing = [e for e in entries if e["port"] == port and e.get("direction", "to_host") != "to_device"
              and e["start"] is not None and e not in changing]
    damage = sorted((e["start"], e["end"]) for e in changing)
    damage_starts = [a for a, _ in damage]

    # the delivered stream's frames, judged by the ledger
    intact, damaged = {}, {}
    for ev in _decoder(port, escaped).decode(emu):
        if isinstance(ev, Frame):
            lo, hi = ev.offset, ev.offset + len(ev.raw)
            if not inside(lo, hi):
                continue
            r.frames += 1
            if _overlaps(damage, damage_starts, lo, hi):
                r.damaged += 1
                damaged[lo] = hi
            else:
                intact[lo] = hi
    r.intact = len(intact)

    # what the host made of its bytes, in the emulator's offsets
    host_starts = [h for h, _, _ in slices]

    def to_emu(h: int) -> int:  # a foreign byte maps to the end of the slice before it
        i = bisect.bisect_right(host_starts, h) - 1
        if i < 0:
            return 0
        hs, es, n = slices[i]
        return es + min(h - hs, n)

    accepted, rejected = set(), []
    for ev in _decoder(port, escaped).decode(host):
        if isinstance(ev, Frame):
            accepted.add(to_emu(ev.offset))
        elif isinstance(ev, DecodeError) and ev.size:
            rejected.append((to_emu(ev.offset), to_emu(ev.offset + ev.size - 1) + 1))
    r.accepted = len(accepted)
    r.rejected_bytes = sum(b - a for a, b in rejected)
    undetectable = [(lo, hi) for lo, hi in damaged.items()
                    if lo in accepted and _collision(port, escaped, emu, lo, hi, changing)]
    r.undetectable = len(undetectable)

    missed = [lo for lo in intact if lo not in accepted]
    if missed:
        r.problems.append(f"{port}: {len(missed)} intact frames were not accepted by the host "
                          f"(first at emulator offset {missed[0]})")
    unexplained = [(a, b) for a, b in rejected if not _overlaps(damage, damage_starts, a, b, True)
                   and not _near_edge(seen, a, b)]
    if unexplained:
        a, b = unexplained[0]
        r.problems.append(f"{port}: the host rejected {sum(y - x for x, y in unexplained)} bytes "
                          f"no injection touched ({len(unexplained)} runs, first [{a}, {b}))")
    rejected.sort()
    rej_starts = [a for a, _ in rejected]
    for e in changing:
        if not inside(e["start"], max(e["end"], e["start"] + 1)):
            continue
        r.injections += 1
        # a removal (a point) is accounted for by a rejected run that holds it or ends there
        point = e["start"] == e["end"]
        if not _overlaps(rejected, rej_starts, e["start"] - point, e["end"] + point) and not any(
                lo <= e["start"] < hi for lo, hi in undetectable):
            r.problems.append(f"{port}: {e['kind']} at t={e['t_ns'] / 1e9:.3f} s changed bytes "
                              f"[{e['start']}, {e['end']}) but the host rejected none of them")
            break
    for e in timing:
        if inside(e["start"], max(e["end"], e["start"] + 1)):
            r.timing_injections += 1
    return r


def _collision(port: str, escaped: bool, emu: bytes, lo: int, hi: int, changing: list[dict]) -> bool:
    """Whether the damaged frame emu[lo:hi] is an undetectable one (module docstring): every
    entry touching it is a bit flip with its mask, and undoing them gives a frame again."""
    flips = [e for e in changing if e["start"] < hi and e["end"] > lo]
    if not all("mask" in e and e["end"] == e["start"] + 1 for e in flips):
        return False
    sent = bytearray(emu[lo:hi])
    for e in flips:
        sent[e["start"] - lo] ^= e["mask"]
    frames = [ev for ev in _decoder(port, escaped).decode(bytes(sent)) if isinstance(ev, Frame)]
    return len(frames) == 1 and frames[0].offset == 0 and len(frames[0].raw) == hi - lo


_EDGE = 256  # a frame cut by the edge of what the host saw is at most this long (API frame)


def _near_edge(seen: list[tuple[int, int]], a: int, b: int) -> bool:
    """Rejected bytes within a frame's length of where the host's view of the stream starts
    or ends (it attached, or the cable came back, mid-frame)."""
    return any(abs(a - lo) <= _EDGE or abs(b - hi) <= _EDGE for lo, hi in seen)


def audit(emulator_dir: str | Path, host_dir: str | Path) -> dict:
    """The audit of an emulator recording and a host recording of the same run (module
    docstring): per port, the counts and problems; ``ok`` when there are none."""
    emu, host = Recording(emulator_dir), Recording(host_dir)
    if emu.meta.get("source") != "navtwin emulate":
        raise AuditError(f"{emulator_dir}: not an emulator recording (source "
                         f"{emu.meta.get('source')!r}); give the emulator's recording directory first")
    if (host.meta.get("source") or "").startswith("navtwin emulate"):
        raise AuditError(f"{host_dir}: an emulator recording; give the host's recording directory second")
    entries = emu.faults()
    settings = emu.meta.get("ports", {})
    ports = [p for p in lab_ports.names() if emu.sizes.get(p) and host.sizes.get(p)]
    if not ports:
        raise AuditError("the recordings share no port with data; record the host on the "
                         "emulator's ports")
    results = []
    for p in ports:
        reads, marks = [], []
        for c in host.chunks(p):
            reads.append(c.data)
            marks.append(c.read)
        if host.reads[p] and None in marks:
            raise AuditError(f"{host_dir}/{p}.csv: a read without its read columns; a host "
                             f"recording has them on every read: re-record it")
        escaped = lab_ports.escaped(settings.get(p, {}))  # its API mode at the start
        results.append(audit_port(p, b"".join(c.data for c in emu.chunks(p)), reads, entries,
                                  escaped, marks if host.reads[p] else None))
    old = [p for p in ports if not host.reads[p]]
    notes = [f"{host_dir}: no read columns in {', '.join(f'{p}.csv' for p in old)} (an older "
             f"navtwin's recording): a read lost from it would count as unseen, so its "
             f"wholeness is not proven"] if old else []
    return {"ok": all(r.ok for r in results), "ledger_entries": len(entries), "notes": notes,
            "ports": {r.port: {k: v for k, v in vars(r).items() if k != "port"} for r in results}}


def report(result: dict) -> str:
    """One screen: a row per port, then the problems."""
    cols = ("frames", "intact", "damaged", "undetectable", "accepted", "rejected_bytes",
            "injections", "timing_injections", "unseen_bytes")
    lines = [f"{'port':8} " + " ".join(f"{c:>17}" for c in cols)]
    for port, r in result["ports"].items():
        lines.append(f"{port:8} " + " ".join(f"{r[c]:>17}" for c in cols))
    for port, r in result["ports"].items():
        if r.get("unseen"):
            lines.append(f"unseen {port}: " + ", ".join(f"{n} bytes {cause}"
                                                        for cause, n in r["unseen"].items()))
    problems = [p for r in result["ports"].values() for p in r["problems"]]
    lines.append(f"ledger: {result['ledger_entries']} entries")
    lines += [f"NOTE {n}" for n in result.get("notes", [])]
    lines += [f"FAIL {p}" for p in problems] or ["PASS: every intact frame was accepted, every "
                                                 "rejected byte was injected, every injection "
                                                 "was rejected"]
    return "\n".join(lines) + "\n"
