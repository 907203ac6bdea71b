"""A progress bar for long work: tqdm's when it is installed, else one
line on stderr redrawn."""

import sys

__all__ = ["Bar"]


class Bar:
    """tqdm when installed, else one line on stderr redrawn."""

    def __init__(self, label: str):
        try:
            from tqdm.auto import tqdm  # type: ignore

            self._t = tqdm(total=100, desc=label, unit="%")
        except ImportError:
            self._t = None
        self._last = 0

    def update(self, fraction: float, state: str = "") -> None:
        pct = int(round(100 * max(0.0, min(1.0, fraction))))
        if self._t is not None:
            self._t.update(pct - self._last)
            self._t.set_postfix_str(state)
        else:
            sys.stderr.write(f"\r[{'#' * (pct * 30 // 100):<30}] {pct:3d} % {state:<10}")
            sys.stderr.flush()
        self._last = pct

    def close(self) -> None:
        if self._t is not None:
            self._t.close()
        else:
            sys.stderr.write("\n")
