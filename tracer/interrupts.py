"""Ctrl-C and SIGTERM: never lost, and held back while work must not be cut in half.

**Never lost.** Python runs a signal's handler in the main thread between two bytecodes,
wherever the main thread is, and the ``KeyboardInterrupt`` that the handler raises travels up
from there. In some places it travels no further: raised while a finalizer runs (an object's
``__del__``, a ``weakref.finalize`` or weakref callback, a generator's ``finally`` run by the
garbage collector, Dask's ``Future.__del__``, tqdm's ``__del__``) or inside a C library's
callback into Python (numba's LLVM callbacks through ctypes), it is printed as "Exception
ignored in ..." and dropped, and the program goes on as if no signal had come. Nothing in
Python says when a finalizer runs (the garbage collector runs them at any allocation), so no
code can avoid them. So the handler that :func:`watching` installs does two things: it
*records* the signal (``pending``) and then raises ``KeyboardInterrupt`` as Python's own does.
The raise stops the work at once wherever it can; the record survives when the raise is
dropped. The loops that do long work (the render loop between batches, a cluster's driver
while it waits for tasks) call :func:`check`, which raises ``KeyboardInterrupt`` again while a
signal is pending; the code that acts on an interrupt (keeps the finished work and stops)
calls :func:`clear`. A dropped interrupt so costs at most one batch, or one poll of a
cluster's tasks, of delay, and a command whose work ended before any check saw it ends with
the interrupted status all the same (``tracer.cli.main``).

**Held back.** Some places cannot take a ``KeyboardInterrupt`` at all: inside numba's compiler
(an interrupt that lands in LLVM's ctypes callbacks leaves the compiler broken and the program
dies with a RuntimeError), while a finished batch is merged into the film, or between writing
a finished render's EXR and its PNG. Within :func:`deferred`, the two signals are recorded in
a list instead of acting; the caller decides what to do once the block is done (and the
handler that was there before, :func:`watching`'s, is put back).

Handlers can be set in the main thread only; elsewhere both context managers do nothing.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

SIGNALS = (signal.SIGINT, signal.SIGTERM)

# The signals that :func:`watching`'s handler received and no code has acted on yet
# (:func:`clear`). A list, appended to by the handler (in the main thread, between bytecodes).
_pending: list[int] = []


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _record_and_raise(signum, frame) -> None:
    """The handler of :func:`watching`: record first (a raise may be dropped), then raise."""
    _pending.append(signum)
    raise KeyboardInterrupt


@contextlib.contextmanager
def watching() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM are recorded (:func:`pending`) and raise
    ``KeyboardInterrupt``, so that an interrupt dropped by a finalizer is still seen by the next
    :func:`check`. The handlers before are put back on leaving, and what is pending is cleared
    (the caller has seen it, with :func:`pending`, before leaving)."""
    if not _main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    for s in SIGNALS:
        signal.signal(s, _record_and_raise)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        clear()


def pending() -> bool:
    """Whether a signal arrived under :func:`watching` that no code has acted on yet."""
    return bool(_pending)


def check() -> None:
    """Raise ``KeyboardInterrupt`` if a signal is pending: the one place a long loop learns of
    an interrupt whose own ``KeyboardInterrupt`` a finalizer dropped. Call it between units of
    work that may be cut (batches, polls of a cluster), never inside one."""
    if _pending:
        raise KeyboardInterrupt


def clear() -> None:
    """The pending signals were acted on (the finished work is kept and the work stops)."""
    _pending.clear()


def leave_pending(signals: list[int]) -> None:
    """Signals that a :func:`deferred` block held back and its caller cannot act on there (the
    work is over, or must finish first): pending, as if :func:`watching` had recorded them, for
    the next :func:`check` or the command's end. Nothing outside :func:`watching`."""
    if _main_thread() and signal.getsignal(signal.SIGINT) is _record_and_raise:
        _pending.extend(signals)


@contextlib.contextmanager
def deferred(note: str | None = None) -> Iterator[list[int]]:
    """Within the block, SIGINT and SIGTERM are recorded in the yielded list instead of acting;
    ``note`` is printed to stderr when the first one arrives. Outside the main thread (where
    handlers cannot be set) the block runs unprotected and the list stays empty."""
    arrived: list[int] = []
    if not _main_thread():
        yield arrived
        return

    def record(signum, frame) -> None:
        if not arrived and note:
            sys.stderr.write(note + "\n")  # one write: a line of another thread cannot split it
            sys.stderr.flush()
        arrived.append(signum)

    previous = {s: signal.getsignal(s) for s in SIGNALS}
    for s in SIGNALS:
        signal.signal(s, record)
    try:
        yield arrived
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
