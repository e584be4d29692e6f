"""Read the lab computer's XBee coordinator with digi-xbee and rebuild the SINS frames
carried in its 0x90 Receive Packets."""
import sys
import threading

from digi.xbee.devices import XBeeDevice
from navtwin.protocols.stream import Frame, sins_decoder

dev = XBeeDevice(sys.argv[1], 115200)
dev.open()                       # reads AP, HV, VR, SH, SL, NI, MY, CE
try:
    print("role", dev.get_role(), "address", dev.get_64bit_addr(), "node", dev.get_node_id())
    for at in ("VR", "HV", "AP", "BD", "ID", "CH"):
        print(at, dev.get_parameter(at).hex())

    chain, frames, got = sins_decoder(), [], threading.Event()

    def received(msg):           # one 0x90 frame: a chunk of the SINS byte stream
        frames.extend(e for e in chain.feed(bytes(msg.data)) if isinstance(e, Frame))
        if len(frames) >= 100:
            got.set()
        if len(frames) < 3:
            print("0x90 from", msg.remote_device.get_64bit_addr(), len(msg.data), "bytes")

    dev.add_data_received_callback(received)
    assert got.wait(10), "no SINS frames in 10 s"
    seqs = [f.fields["seq"] for f in frames[:100]]
    print(len(seqs), "SINS frames, seq", seqs[0], "to", seqs[-1])
finally:
    dev.close()
