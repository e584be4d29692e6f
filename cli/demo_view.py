"""The live view of ``navtwin demo``: the lab's :class:`~navtwin.lab.orchestrator.Watch` state
drawn with rich on stderr, four times a second (stdout keeps the final table)."""
from __future__ import annotations

from rich.console import Console, Group
from rich.live import Live
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table
from rich.text import Text

from navtwin.lab import evaluate
from navtwin.lab.orchestrator import PHASES, Watch


def _m(v: float) -> str:
    return "" if v != v else f"{v:.3f}"  # NaN: nothing yet


class LiveView(Watch):
    tick_s = 0.25

    def __init__(self) -> None:
        super().__init__()
        self.console = Console(stderr=True)
        self.progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                                 TextColumn("{task.completed:5.1f} / {task.total:g} s of the scenario"),
                                 TimeElapsedColumn(), console=self.console)
        self.task = self.progress.add_task("starting", total=1.0)
        self.info: dict = {}
        self.frame: list = []  # the parts of the view last drawn
        self.live = Live(self.progress, console=self.console, refresh_per_second=4, transient=False)

    def __exit__(self, *exc) -> None:
        if self.info:  # the view started with the lab: a lab that never ran shows nothing
            self.live.stop()
            if not self.console.is_terminal:
                self.console.line()  # the last frame was printed without one

    def phase(self, name: str) -> None:
        if not self.info:  # before the view starts: a line of its own
            self.console.print(PHASES[name], style="dim")
            return
        self.frame.append(Text(PHASES[name], style="bold"))  # under the last frame
        self.live.update(Group(*self.frame))

    def started(self, info: dict) -> None:
        self.info = info
        self.progress.update(self.task, description=f"{info['scenario']} (seed {info['seed']})",
                             total=info["duration_s"])
        self.frame = [Text(f"run directory {info['dir']}", style="dim"), self.progress]
        self.live.update(Group(*self.frame))
        self.live.start()

    def tick(self, state: dict) -> None:
        emu, host = state["emulator"], state["host"]
        if emu:
            self.progress.update(self.task, completed=min(emu["virtual_s"], emu["duration_s"]))
        self.frame = parts = [Text(f"run directory {self.info.get('dir', '')}", style="dim"),
                              self.progress]
        if host:
            parts += [self._ports(host), Text(
                f"IMU {host['imu_per_s']:.0f}/s, exchanges {host['reports_per_s']:.0f}/s, "
                f"link {host['link_dbm']} dBm, host latency p50 "
                f"{host['latency'].get('p50_ms', 0):.2f} ms")]
        if state["tracks"]:
            parts.append(self._tracks(state["tracks"]))
        if state.get("vehicles"):
            parts.append(self._vehicles(state["vehicles"]))
        if emu and emu.get("faults"):
            parts.append(Text("live faults: " + ", ".join(
                f"{f['kind']} (id {f['id']})" for f in emu["faults"]), style="yellow"))
        self.live.update(Group(*parts))

    def _ports(self, host: dict) -> Table:
        t = Table(title=f"ports (host time {host['t_s']:.0f} s)", title_justify="left")
        for col in ("port", "state", "frames/s", "bytes", "errors"):
            t.add_column(col, justify="left" if col in ("port", "state", "errors") else "right")
        for name, p in host["ports"].items():
            errors = host.get("errors", {}).get(name, {})
            t.add_row(name, p["state"], f"{p['frames_per_s']:.1f}", f"{p['bytes']:,}",
                      ", ".join(f"{k} {v}" for k, v in errors.items()) or "-",
                      style=None if p["state"] == "open" else "red")
        return t

    def _tracks(self, tracks: dict) -> Table:
        t = Table(title="tracks: position error against truth (m)", title_justify="left")
        scenario = self.info.get("scenario")
        pub = evaluate.PAPER_FIGURES.get(scenario, {})
        for col in ("track", "now", "mean", "max", "estimates",
                    f"paper {pub['paper']} mean (max)" if evaluate.has_paper_means(scenario)
                    else "paper"):
            t.add_column(col, justify="left" if col == "track" else "right")
        for name, e in sorted(tracks.items()):
            t.add_row(name, _m(e.last), _m(e.mean), _m(e.max), str(e.n),
                      evaluate.paper_cell(self.info.get("scenario"), name))
        return t

    def _vehicles(self, vehicles: dict) -> Table:
        t = Table(title="cars: each one's best track against its own truth (m)", title_justify="left")
        for col in ("car", "best track", "now", "mean", "max", "estimates"):
            t.add_column(col, justify="left" if col in ("car", "best track") else "right")
        for v, tracks in sorted(vehicles.items()):
            if not tracks:
                t.add_row(str(v), "waiting", "-", "-", "-", "0")
                continue
            name, e = min(tracks.items(), key=lambda kv: kv[1].mean)
            t.add_row(str(v), name, _m(e.last), _m(e.mean), _m(e.max), str(e.n))
        return t
