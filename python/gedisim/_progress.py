"""Progress of long operations as tqdm bars, when tqdm is installed; silent otherwise.

The extension calls ``callback(event, label, unit, n)`` from the thread doing the work (events ``start``,
``total``, ``advance``, ``note``, ``finish``; gedisim's ``ops::progress::Progress``).
"""

from __future__ import annotations

import threading
from typing import Callable, Optional

try:  # tqdm.auto: a widget in notebooks, text in terminals
    from tqdm.auto import tqdm
except ImportError:  # pragma: no cover - exercised without tqdm
    tqdm = None


class _Bars:
    def __init__(self) -> None:
        self.bar = None
        self.lock = threading.Lock()

    def __call__(self, event: str, label: str, unit: str, n: int) -> None:
        with self.lock:
            if event == "start":
                self._close()
                self.bar = tqdm(total=n or None, desc=label, unit=f" {unit}" if unit else "it", leave=False)
            elif self.bar is None:
                return
            elif event == "total":
                self.bar.total = n or None
                self.bar.refresh()
            elif event == "advance":
                self.bar.update(n)
            elif event == "note":
                self.bar.set_postfix_str(label, refresh=True)
            elif event == "finish":
                self._close()

    def _close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def progress_callback() -> Optional[Callable[[str, str, str, int], None]]:
    """A fresh set of bars, or None without tqdm."""
    return _Bars() if tqdm is not None else None
