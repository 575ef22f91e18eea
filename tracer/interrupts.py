"""Holding Ctrl-C and SIGTERM back while work must not be cut in half.

Python raises ``KeyboardInterrupt`` wherever the main thread happens to be, and some places
cannot take it: inside numba's compiler (an interrupt that lands in LLVM's ctypes callbacks
leaves the compiler broken and the program dies with a RuntimeError), or between writing a
finished render's EXR and its PNG. Within :func:`deferred`, the two signals are recorded
instead; the caller decides what to do once the block is done.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def deferred(note: str | None = None) -> Iterator[list[int]]:
    """Within the block, SIGINT and SIGTERM are recorded in the yielded list instead of acting;
    ``note`` is printed to stderr when the first one arrives. Outside the main thread (where
    handlers cannot be set) the block runs unprotected and the list stays empty."""
    arrived: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield arrived
        return

    def record(signum, frame) -> None:
        if not arrived and note:
            print(note, file=sys.stderr, flush=True)
        arrived.append(signum)

    previous = {s: signal.getsignal(s) for s in SIGNALS}
    for s in SIGNALS:
        signal.signal(s, record)
    try:
        yield arrived
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
