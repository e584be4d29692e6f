"""The SINS DSP board (TMS320C6713 + MAX3111E): reads the ADIS16350 every 10 ms of its own
clock and writes one SINS frame (wire-formats.md section 1) on its RS-232 line: a sample
frame, or a wide sample frame when the IMU speaks 32-bit words (``[imu] words``,
emulator.imu_words).

Frame k is written from true time ``t_k = start + round(k period / (1 + ppm 1e-6))`` (the
board's crystal; an absolute schedule) with seq = k mod 65536; its registers are read over
SPI ``spi_read_us`` earlier, so they hold the sensor's latest sample at that moment.

With a magnetometer (emulator.magnetometer, ``every`` > 0) the board also reads it at the
SPI read of every frame whose seq is a multiple of ``every`` and writes its magnetometer
frame (same seq) right after that sample frame, so the stream interleaves the two types.

Board faults (emulator.faults, ACTS_ON "board"): while one is ``off`` the board writes
nothing; its first frame after counts from 0 again (seq = k - k0, k0 the tick it came back
at), as after power-up, and on the same crystal schedule.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.protocols.fast import frames_of
from navtwin.protocols.sins import build_magnetometer
from navtwin.protocols.serial import char_ns

from .alike import alike
from .clock import Clock


@dataclass(slots=True)
class BoardEffects:
    """What board faults change in a block's frames: ``off`` (bool per frame), in place."""

    off: np.ndarray


class Board:
    def __init__(self, spec, ppm: float, imu, faults=(), magnetometer=None, every: int = 0) -> None:
        self.clock = Clock(ppm, spec.period_ms * 1e6, round(spec.start_ms * 1e6))
        self.spi_read_ns = round(spec.spi_read_us * 1e3)
        self.char_ns = char_ns(spec.baud)
        self.imu = imu
        self.magnetometer = magnetometer  # read with every ``every``-th frame (0: none)
        self.every = every
        self.faults = tuple(faults)
        self._k0 = 0  # the tick of the last power-up: frame k counts k - k0
        self._off = False  # the last frame of the previous block was not written
        self._last_k = -1  # the tick of the last frame written
        self._cause = None  # the board fault that last had it off

    def frames(self, lo_ns: int, hi_ns: int) -> tuple[np.ndarray, list[bytes], dict]:
        """Write start times and bytes of the frames with lo_ns <= t_k < hi_ns (the IMU must
        have generated its samples up to hi_ns), and the ledger marks by frame index: the
        first frame after a reset says which fault and how many frames were not written."""
        return Board.frames_together([self], lo_ns, hi_ns)[0]

    @staticmethod
    def frames_together(boards: list[Board], lo_ns: int, hi_ns: int) -> list[tuple]:
        """:meth:`frames` of each of *boards*, each one's as alone: the boards that write on
        the same schedule from IMUs that run alike (a sweep's seeds of one vehicle,
        emulator.imu.Adis16350.key) read their registers and build their frames along one
        seed axis."""
        planned = [b._schedule(lo_ns, hi_ns) for b in boards]
        out: list = [None] * len(boards)
        for members in alike([None if b.imu.key is None else
                              (b.imu.key, b.spi_read_ns, t.tobytes(), seq.tobytes())
                              for b, (t, seq, _) in zip(boards, planned)]):
            first = boards[members[0]]
            t, seq, _ = planned[members[0]]
            words = first.imu.read_together([boards[i].imu for i in members], t - first.spi_read_ns)
            rows = frames_of(first.imu.words.frames(np.tile(seq, len(members)),
                                                    words.reshape(-1, words.shape[-1])))
            for k, i in enumerate(members):
                b, marks = boards[i], planned[i][2]
                frames = rows[k * len(t):(k + 1) * len(t)]
                out[i] = b._with_magnetometer(t, seq, frames, marks) if b.every else (t, frames, marks)
        return out

    def _schedule(self, lo_ns: int, hi_ns: int) -> tuple[np.ndarray, np.ndarray, dict]:
        """(write start, seq) of the frames with lo_ns <= t_k < hi_ns that the board writes
        (not while a board fault has it off), and the ledger marks by frame index."""
        k = self.clock.ticks_between(lo_ns, hi_ns)
        t = self.clock.tick(k)
        effect = BoardEffects(np.zeros(len(k), dtype=bool))
        marks: dict[int, tuple] = {}
        for f in self.faults:
            on = f.active(t)
            f.act(effect, on)
            if on.any():
                self._cause = f
        if effect.off.any() or self._off:
            on = ~effect.off
            back = on & np.concatenate(([self._off], effect.off[:-1]))  # first frame after off
            k0 = np.maximum.accumulate(np.where(back, k, self._k0))
            written = k[on]
            for j in np.flatnonzero(back).tolist():
                kept = int(on[:j].sum())  # its index among the frames written
                before = int(written[kept - 1]) if kept else self._last_k
                marks[kept] = ({"kind": self._cause.KIND, "fault": self._cause, "t_ns": int(t[j]),
                                "missing": int(k[j]) - before - 1},)
            if len(k):
                self._k0, self._off = int(k0[-1]), bool(effect.off[-1])
            k, t, seq = k[on], t[on], (k - k0)[on]
        else:
            seq = k - self._k0
        if len(k):
            self._last_k = int(k[-1])  # the last frame written
        return t, seq, marks

    def _with_magnetometer(self, t, seq, frames, marks):
        """The sample frames with a magnetometer frame after each one whose seq is a
        multiple of ``every`` (it starts as the sample frame's last stop bit ends); the
        marks re-indexed to the sample frames' new places."""
        picked = np.flatnonzero(seq % self.every == 0)
        field = self.magnetometer.read(t[picked] - self.spi_read_ns).tolist()
        after = dict(zip(picked.tolist(), (build_magnetometer(int(seq[i]), f)
                                           for i, f in zip(picked.tolist(), field))))
        frame_ns = round(self.imu.words.frame_size * self.char_ns)
        times, out, moved = [], [], {}
        for i, (start, frame) in enumerate(zip(t.tolist(), frames)):
            moved[i] = len(out)
            times.append(start)
            out.append(frame)
            if i in after:
                times.append(start + frame_ns)
                out.append(after[i])
        return (np.array(times, dtype=np.int64), out,
                {moved[i]: m for i, m in marks.items()})

    def byte_times(self, starts: np.ndarray, sizes) -> np.ndarray:
        """True times, in stream order, at which each byte of the frames starting at
        *starts* (of *sizes* bytes) has been completely received at the far end of the line."""
        sizes = np.asarray(sizes, dtype=np.int64)
        first = np.repeat(np.cumsum(sizes) - sizes, sizes)  # each byte's frame's first byte
        within = np.arange(int(sizes.sum())) - first + 1  # 1.. within its frame
        return np.repeat(starts, sizes) + np.rint(within * self.char_ns).astype(np.int64)

    def next_start(self, after_ns: int) -> int:
        """Start of the first frame at or after *after_ns* (the schedule is known ahead)."""
        lo = max(after_ns, self.clock.t0_ns)  # before the first frame (a late start_ms): it
        return int(self.clock.tick(int(self.clock.ticks_between(lo, lo + 2 * round(
            self.clock.true_period_ns) + 2)[0])))
