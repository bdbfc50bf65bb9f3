"""Progress on stderr for the long commands: a counted bar (``prioik bench``) and a bar
over simulated seconds with rate and ETA (the scenario runs, ``tqdm``)."""

from __future__ import annotations

import sys
import time

__all__ = ["Progress", "simulated_time_bar"]


class Progress:
    """A progress bar on stderr (one line, redrawn; plain lines when not a terminal)."""

    def __init__(self, total: int, stream=None) -> None:
        self.total = max(1, total)
        self.done = 0
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.t0 = time.perf_counter()

    def step(self, what: str, advance: int = 1) -> None:
        self.done = min(self.total, self.done + advance)
        frac = self.done / self.total
        bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
        line = (f"[{bar}] {self.done}/{self.total} {time.perf_counter() - self.t0:6.1f}s "
                f"{what}")
        if self.tty:
            self.stream.write("\r" + line[:120].ljust(120))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def message(self, text: str) -> None:
        self.stream.write(("\n" if self.tty else "") + text + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def simulated_time_bar(desc: str, duration: float, enabled: bool):
    """``(bar, progress)``: a tqdm bar over simulated seconds and the callback a
    simulation calls with the simulated time; ``(None, None)`` when not ``enabled``."""
    if not enabled:
        return None, None
    from tqdm import tqdm
    bar = tqdm(total=round(duration, 3), desc=desc, unit="sim s", file=sys.stderr,
               leave=False, bar_format="{desc}: {n:.1f}/{total:.1f} s "
               "[{elapsed}<{remaining}, {rate_fmt}]")

    def progress(t):
        bar.update(round(t - bar.n, 6))

    return bar, progress
