"""Test vectors copied from shared/specs/wire-formats.md and shared/reference/xbee-api-facts.md."""

def h(s: str) -> bytes:
    return bytes.fromhex(s)


SINS_LEVEL = h("A5 5A 01 18 00 01 8A AA 80 00 80 00 80 00 80 00 80 00 81 8C 80 00 80 00 80 00 80 00 89 F0")
SINS_SEQ_WRAP = h("A5 5A 01 18 FF FF 8A AA 84 44 80 00 BB BC 80 00 BE 73 81 8C 8F BB 80 00 80 00 80 00 11 EC")
NANOLOC_5M = h("4E 4C 01 1A 00 07 00 12 D6 87 01 10 0F C2 05 F6 63 4C 05 F5 E1 00 05 F6 63 4C 05 F5 E1 00 52 B2")

#: Digi's worked examples, API mode 1: name -> (frame, type, fields that must parse out)
XBEE_API1 = {
    "transmit_request": (h("7E 00 16 10 01 00 13 A2 00 40 0A 01 27 FF FE 00 00 54 78 44 61 74 61 30 41 13"),
                         0x10, {"frame_id": 1, "dest64": 0x0013A200400A0127, "dest16": 0xFFFE,
                                "radius": 0, "options": 0, "data": b"TxData0A"}),
    "at_query_nj": (h("7E 00 04 08 52 4E 4A 0D"), 0x08,
                    {"frame_id": 0x52, "command": b"NJ", "parameter": b""}),
    "at_set_bd": (h("7E 00 06 08 01 42 44 04 B0 BC"), 0x08,
                  {"frame_id": 1, "command": b"BD", "parameter": b"\x04\xb0"}),
    "at_queue_bd": (h("7E 00 05 09 01 42 44 07 68"), 0x09,
                    {"frame_id": 1, "command": b"BD", "parameter": b"\x07"}),
    "at_response": (h("7E 00 05 88 01 42 44 00 F0"), 0x88,
                    {"frame_id": 1, "command": b"BD", "status": 0, "value": b""}),
    "modem_coordinator_started": (h("7E 00 02 8A 06 6F"), 0x8A, {"status": 6}),
    "modem_hardware_reset": (h("7E 00 02 8A 00 75"), 0x8A, {"status": 0}),
    "modem_joined": (h("7E 00 02 8A 02 73"), 0x8A, {"status": 2}),
    "modem_watchdog": (h("7E 00 02 8A 01 74"), 0x8A, {"status": 1}),
    "transmit_status": (h("7E 00 07 8B 01 7D 84 00 00 01 71"), 0x8B,
                        {"frame_id": 1, "dest16": 0x7D84, "retries": 0, "delivery": 0, "discovery": 1}),
    # the manual prints length 0x11; the true length is 0x12 (doc erratum)
    "receive_packet": (h("7E 00 12 90 00 13 A2 00 40 52 2B AA 7D 84 01 52 78 44 61 74 61 0D"), 0x90,
                       {"src64": 0x0013A20040522BAA, "src16": 0x7D84, "options": 1, "data": b"RxData"}),
    "explicit_rx": (h("7E 00 18 91 00 13 A2 00 40 52 2B AA 7D 84 E0 E0 22 11 C1 05 02 52 78 44 61 74 61 52"),
                    0x91, {"src64": 0x0013A20040522BAA, "src16": 0x7D84, "src_endpoint": 0xE0,
                           "dest_endpoint": 0xE0, "cluster": 0x2211, "profile": 0xC105, "options": 2,
                           "data": b"RxData"}),
    "remote_at_request": (h("7E 00 10 17 01 00 13 A2 00 40 40 11 22 FF FE 02 42 48 01 F5"), 0x17,
                          {"frame_id": 1, "dest64": 0x0013A20040401122, "dest16": 0xFFFE, "options": 2,
                           "command": b"BH", "parameter": b"\x01"}),
    "remote_at_response": (h("7E 00 13 97 55 00 13 A2 00 40 52 2B AA 7D 84 53 4C 00 40 52 2B AA F0"), 0x97,
                           {"frame_id": 0x55, "src64": 0x0013A20040522BAA, "src16": 0x7D84,
                            "command": b"SL", "status": 0, "value": h("40 52 2B AA")}),
    "node_identification": (h("7E 00 20 95 00 13 A2 00 40 52 2B AA 7D 84 02 7D 84 00 13 A2 00 40 52 2B AA"
                              " 20 00 FF FE 01 01 C1 05 10 1E 1B"), 0x95,
                            {"src64": 0x0013A20040522BAA, "src16": 0x7D84, "options": 2,
                             "remote16": 0x7D84, "remote64": 0x0013A20040522BAA, "ni": " ",
                             "parent16": 0xFFFE, "device_type": 1, "source_event": 1,
                             "profile": 0xC105, "manufacturer": 0x101E, "device_type_id": None}),
    "node_identification_capture": (
        h("7e 00 27 95 00 13 a2 00 40 aa d0 06 f9 5d 02 f9 5d 00 13 a2 00 40 aa d0 06 52 4f 54 45 41 44"
          " 4f 52 00 ff fe 01 01 c1 05 10 1e 7f"), 0x95, {"ni": "ROTEADOR", "device_type": 1}),
}

#: Digi's API mode 2 examples: (escaped frame, the API 1 frame it encodes)
XBEE_API2 = {
    "transmit_request": (h("7E 00 16 10 01 00 7D 33 A2 00 40 0A 01 27 FF FE 00 00 54 78 44 61 74 61 30 41 7D 33"),
                         XBEE_API1["transmit_request"][0]),
    "doc_example": (h("7E 00 02 23 7D 31 CB"), h("7E 00 02 23 11 CB")),
}
