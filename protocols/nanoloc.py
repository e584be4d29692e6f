"""The nanoLOC gateway ranging report (wire-formats.md section 3).

| offset | size | field          | value                                                    |
|--------|------|----------------|----------------------------------------------------------|
| 0      | 2    | sync           | ``4E 4C`` ("NL")                                         |
| 2      | 1    | type           | ``01`` = ranging report, ``02`` = wide ranging report    |
|        |      |                | (below; others reserved, skipped by len)                 |
| 3      | 1    | len            | ``1A`` (26) for type 01                                  |
| 4      | 2    | seq            | gateway report counter, wraps                            |
| 6      | 4    | t_us           | anchor-network time of the exchange, us, wraps           |
| 10     | 1    | anchor         | anchor id (1..254)                                       |
| 11     | 1    | tag            | tag id (1..254)                                          |
| 12     | 1    | status         | bits 0..3 tau1..tau4 valid; 0x40 timeout; 0x80 value err |
| 13     | 1    | rssi           | dBm at the anchor, signed                                |
| 14     | 16   | tau1..tau4     | unsigned durations, ps, each in its measuring node's clock|
| 30     | 2    | crc            | CRC-16/CCITT-FALSE over bytes 2..29                       |

Distance, exactly as the lab computer computes it: d = c (tau1 - tau2 + tau3 - tau4) / 4.

Wide ranging report (type 02, len ``1C`` = 28, 34 bytes): the same fields with ``anchor`` and
``tag`` 16-bit big-endian (1..65534), for fields of more than 254 nodes (common.anchorgrid;
004's training areas hold 1402). The gateway writes it exactly when some anchor or tag id of
its network exceeds 254; a reader that knows only type 01 skips it by len, as the reserved
types, so the extension is compatible.
"""
import numpy as np
from construct import Array, Int8sb, Int8ub, Int16ub, Int32ub, Struct, Terminated

from .crcframe import crc_framed, encode, encode_rows
from .fast import packer_for, rows_packer

SYNC = b"\x4e\x4c"
TYPE_RANGING = 0x01
TYPE_WIDE_RANGING = 0x02
FRAME_SIZE = 32
WIDE_FRAME_SIZE = 34
#: the ids a type 01 report carries; larger ones need the wide report (type 02)
NARROW_IDS = (1, 254)
SPEED_OF_LIGHT = 299_792_458.0  # m/s
PS = 1e-12

STATUS_COMPLETE = 0x0F  # tau1..tau4 valid
STATUS_TIMEOUT = 0x40  # no response from the tag
STATUS_VALUE_ERROR = 0x80



def _ranging(node_id) -> Struct:
    """The ranging report's payload with anchor and tag ids of the field type *node_id*."""
    return Struct(
        "seq" / Int16ub,
        "t_us" / Int32ub,
        "anchor" / node_id,
        "tag" / node_id,
        "status" / Int8ub,
        "rssi" / Int8sb,
        "tau" / Array(4, Int32ub),
        Terminated,
    )


Ranging = _ranging(Int8ub)
WideRanging = _ranging(Int16ub)
#: the payload layout of each report type
LAYOUTS = {TYPE_RANGING: Ranging, TYPE_WIDE_RANGING: WideRanging}

NanolocFrame = crc_framed(SYNC, LAYOUTS)


def distance(tau1: int, tau2: int, tau3: int, tau4: int) -> float:
    """Four-timestamp (symmetric double-sided) distance in metres, taus in picoseconds."""
    return SPEED_OF_LIGHT * (tau1 - tau2 + tau3 - tau4) * PS / 4.0


def single_sided_distance(tau1: int, tau2: int) -> float:
    """One-leg distance c (tau1 - tau2) / 2: keeps the crystal-offset bias the exchange cancels."""
    return SPEED_OF_LIGHT * (tau1 - tau2) * PS / 2.0


def is_complete(status: int) -> bool:
    return status & 0xCF == STATUS_COMPLETE


_PACK = {t: packer_for(st) for t, st in LAYOUTS.items()}


def build_report(*, seq, t_us, anchor, tag, status, rssi, tau, wide: bool = False) -> bytes:
    """The 32-byte report, or with *wide* the 34-byte type 02 (fast path; equal to
    ``NanolocFrame.build``). Counters wrap."""
    ftype = TYPE_WIDE_RANGING if wide else TYPE_RANGING
    return encode(SYNC, ftype, _PACK[ftype](seq & 0xFFFF, t_us & 0xFFFFFFFF, anchor, tag, status, rssi, *tau))


_ROWS = {t: rows_packer(st) for t, st in LAYOUTS.items()}


def build_reports(*, seq, t_us, anchor, tag, status, rssi, tau, wide: bool = False) -> np.ndarray:
    """The reports of a block, one an (n, 32) uint8 row ((n, 34) with *wide*): each field an
    (n,) array, *tau* (n, 4) (= :func:`build_report` of each row). Counters wrap."""
    ftype = TYPE_WIDE_RANGING if wide else TYPE_RANGING
    return encode_rows(SYNC, ftype, _ROWS[ftype](np.asarray(seq) & 0xFFFF,
                                                 np.asarray(t_us) & 0xFFFFFFFF, anchor, tag,
                                                 status, rssi, tau))
