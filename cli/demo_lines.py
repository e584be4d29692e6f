"""``navtwin demo`` when stdout is not a terminal (``| tee lab.log``, CI): the lab's
:class:`~navtwin.lab.orchestrator.Watch` state as plain progress lines on stdout, in order
before the final table, so a log or a pipe keeps what a terminal would have shown."""
from __future__ import annotations

import sys

from navtwin.lab.orchestrator import PHASES, Watch


class ProgressLines(Watch):
    tick_s = 3.0

    def __init__(self) -> None:
        super().__init__(sys.stdout)
        self.total_s = 0.0

    def _print(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    def phase(self, name: str) -> None:
        self._print(PHASES[name])

    def started(self, info: dict) -> None:
        self.total_s = info["duration_s"]
        self._print(f"running {info['scenario']} (seed {info['seed']}) for "
                    f"{info['duration_s']:g} s in real time; run directory {info['dir']}")

    def tick(self, state: dict) -> None:
        emu, host, tracks = state["emulator"], state["host"], state["tracks"]
        parts = [f"{min(emu['virtual_s'], self.total_s):5.1f} / {self.total_s:g} s" if emu
                 else f"{state['elapsed_s']:5.1f} s of wall time"]
        if not host:
            parts.append("waiting for the host's first status line")
        else:
            parts.append("ports " + ", ".join(f"{name} {p['state']} {p['frames_per_s']:.0f}/s"
                                              for name, p in host["ports"].items()))
            errors = {k: sum(v.values()) for k, v in host.get("errors", {}).items() if v}
            if errors:
                parts.append("decode errors " + ", ".join(f"{k} {n}" for k, n in errors.items()))
        if tracks:
            parts.append("error now (m) " + ", ".join(f"{name} {e.last:.3f}"
                                                      for name, e in sorted(tracks.items())))
        if state.get("vehicles"):  # each car's best track now
            best = {v: min(t.items(), key=lambda kv: kv[1].mean) for v, t in state["vehicles"].items() if t}
            if best:
                parts.append("cars (best track, m) " + ", ".join(
                    f"{v} {name} {e.last:.3f}" for v, (name, e) in sorted(best.items())))
        if emu and emu.get("faults"):
            parts.append("live faults " + ", ".join(f["kind"] for f in emu["faults"]))
        self._print("; ".join(parts))
