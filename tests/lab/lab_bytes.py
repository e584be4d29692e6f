"""The lab computer's bytes from the emulated office lab, made in memory (:mod:`navtwin.lab.run`)."""
from navtwin.lab.run import lab_chunks

#: A sample's 0x90 frame starts on the coordinator's UART at least 5.6 ms (board UART and
#: radio) after the board sent it, a report about 5 ms after its exchange: a run of N s and
#: this margin holds exactly N x 100 samples and N x 40 reports.
MARGIN_S = 0.0055


def office(seconds: float, seed: int) -> list[tuple[str, bytes, int]]:
    """``(port, bytes, arrival ns)`` of the office lab's first *seconds* (whole seconds) with
    *seed*: its SINS samples over the radio (``xbee``) and its ``nanoloc`` reports."""
    return list(lab_chunks("office", seed, duration=seconds + MARGIN_S)[1])
