"""hypothesis strategies: valid frames of each format, garbage, chunkings."""
from hypothesis import strategies as st

from navtwin.protocols import nanoloc, sins, xbee

u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
u64 = st.integers(0, 2**64 - 1)
#: bytes that are sync or escape bytes of some format, so garbage keeps tripping the framers
SPECIAL = [0x7E, 0x7D, 0x11, 0x13, 0xA5, 0x5A, 0x4E, 0x4C, 0x01, 0x18, 0x1A, 0x00, 0xFF]
garbage_bytes = st.lists(st.one_of(u8, st.sampled_from(SPECIAL)), min_size=0, max_size=60).map(bytes)


@st.composite
def sins_frames(draw):
    if draw(st.booleans()):  # a wide sample frame (type 03): 32-bit inertial words
        i32 = st.integers(-(1 << 31), (1 << 31) - 1)
        return sins.build_wide_sample(draw(u16), draw(u16), draw(st.tuples(i32, i32, i32)),
                                      draw(st.tuples(i32, i32, i32)), draw(st.tuples(u16, u16, u16)),
                                      draw(u16))
    return sins.build_sample(draw(u16), draw(st.lists(u16, min_size=11, max_size=11)))


@st.composite
def nanoloc_frames(draw):
    return nanoloc.build_report(seq=draw(u16), t_us=draw(st.integers(0, 2**32 - 1)),
                                anchor=draw(st.integers(1, 254)), tag=draw(st.integers(1, 254)),
                                status=draw(st.sampled_from([0x0F, 0x40, 0x80, 0x07])),
                                rssi=draw(st.integers(-128, 127)),
                                tau=draw(st.lists(st.integers(0, 2**32 - 1), min_size=4, max_size=4)))


def _data(n):
    return st.binary(min_size=0, max_size=n)


_cmd = st.binary(min_size=2, max_size=2)
XBEE_FIELDS = {
    0x08: st.fixed_dictionaries({"frame_id": u8, "command": _cmd, "parameter": _data(8)}),
    0x09: st.fixed_dictionaries({"frame_id": u8, "command": _cmd, "parameter": _data(8)}),
    0x10: st.fixed_dictionaries({"frame_id": u8, "dest64": u64, "dest16": u16, "radius": u8,
                                 "options": u8, "data": _data(84)}),
    0x11: st.fixed_dictionaries({"frame_id": u8, "dest64": u64, "dest16": u16, "src_endpoint": u8,
                                 "dest_endpoint": u8, "cluster": u16, "profile": u16, "radius": u8,
                                 "options": u8, "data": _data(84)}),
    0x17: st.fixed_dictionaries({"frame_id": u8, "dest64": u64, "dest16": u16, "options": u8,
                                 "command": _cmd, "parameter": _data(8)}),
    0x88: st.fixed_dictionaries({"frame_id": u8, "command": _cmd, "status": u8, "value": _data(20)}),
    0x8A: st.fixed_dictionaries({"status": u8}),
    0x8B: st.fixed_dictionaries({"frame_id": u8, "dest16": u16, "retries": u8, "delivery": u8,
                                 "discovery": u8}),
    0x90: st.fixed_dictionaries({"src64": u64, "src16": u16, "options": u8, "data": _data(84)}),
    0x91: st.fixed_dictionaries({"src64": u64, "src16": u16, "src_endpoint": u8, "dest_endpoint": u8,
                                 "cluster": u16, "profile": u16, "options": u8, "data": _data(84)}),
    0x95: st.fixed_dictionaries({"src64": u64, "src16": u16, "options": u8, "remote16": u16,
                                 "remote64": u64,
                                 "ni": st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E),
                                               max_size=20),
                                 "parent16": u16, "device_type": st.integers(0, 2),
                                 "source_event": st.integers(1, 3), "profile": u16,
                                 "manufacturer": u16,
                                 "device_type_id": st.none() | st.integers(0, 2**32 - 1)}),
    0x97: st.fixed_dictionaries({"frame_id": u8, "src64": u64, "src16": u16, "command": _cmd,
                                 "status": u8, "value": _data(20)}),
}
UNKNOWN_TYPES = [t for t in range(256) if t not in XBEE_FIELDS]


@st.composite
def xbee_frame_data(draw):
    """Frame data (type + fields) of a declared or an unknown type."""
    if draw(st.integers(0, 9)) == 0:
        return bytes([draw(st.sampled_from(UNKNOWN_TYPES))]) + draw(_data(40))
    ftype = draw(st.sampled_from(sorted(XBEE_FIELDS)))
    return xbee.frame_data(ftype, **draw(XBEE_FIELDS[ftype]))


def xbee_frames(escaped: bool):
    return xbee_frame_data().map(lambda d: xbee.wrap(d, escaped))


FORMATS = {
    "sins": sins_frames(),
    "nanoloc": nanoloc_frames(),
    "xbee-api1": xbee_frames(False),
    "xbee-api2": xbee_frames(True),
}


@st.composite
def chunked(draw, data: bytes):
    """*data* cut at random points."""
    cuts = sorted(set(draw(st.lists(st.integers(0, len(data)), max_size=12))))
    bounds = [0, *cuts, len(data)]
    return [data[a:b] for a, b in zip(bounds, bounds[1:])]
