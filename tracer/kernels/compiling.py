"""Compiling a render's kernels before it starts: in parallel where there are cores, and said.

numba compiles a function on its first call, one function at a time per process (it holds one
compiler lock). :func:`compile_all` takes a render's kernels with the argument types of their
calls and, where more than one is not in the disk cache yet and the machine has a second core,
compiles the largest in this process while a child process compiles the others into the same
cache, from which this process then loads them (``python -m tracer.kernels.compiling``, the
feature set and the argument types on its standard input). While anything compiles, one line
on a terminal says what and that it is kept for next time, with the seconds so far, redrawn
every second (a line every ten seconds elsewhere), so that no wait is silent for longer than
that.

Processes that need one build at the same time compile it once: the first holds a lock file
beside the cache entries while it compiles, the others wait for it and then load its entries.

Whether a kernel is in the cache is read from the existence of its index file, numba's
``IndexDataCacheFile._index_path`` (looked up with ``getattr``: without it every kernel counts
as missing, which costs only the parallelism).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

from .. import plugins
from . import build

try:
    import fcntl
except ImportError:  # not POSIX: builds are not locked across processes
    fcntl = None
from .templates import Template

# Seconds a compilation may run before the line says so (a cache load takes less).
QUIET_SECONDS = 1.0
# On a terminal the line is shown even for renders that show no progress of their own (the many
# renders of tracer stability and check), unless the command was asked to be quiet (``--quiet``
# sets this): a first use there compiles for minutes.
QUIET = False


@dataclass
class Call:
    """A kernel to compile: ``template`` (a :class:`Template`, built for ``features``) or a
    plain compiled function ``function``, for arguments ``args``."""

    args: tuple
    template: Template | None = None
    function: Any = None

    def dispatcher(self, features):
        return build(features).function(self.template) if self.template is not None else self.function

    def reference(self) -> tuple[str, str, bool]:
        """(module, name, is a template) by which a child process finds the same function."""
        source = self.template.py_func if self.template is not None else self.function.py_func
        return source.__module__, source.__name__, self.template is not None


def argument_types(args: tuple) -> tuple:
    import numba

    return tuple(numba.typeof(a) for a in args)


def _compiled(dispatcher, types: tuple) -> bool:
    return tuple(types) in getattr(dispatcher, "overloads", {})


def _cached(dispatcher) -> bool:
    """Whether the disk cache has an entry for this function (any signature)."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    path = getattr(cache_file, "_index_path", None)
    return bool(path) and os.path.exists(path)


def compile_all(features, calls: list[Call], what: str, progress: bool) -> float:
    """Compile (or load from the cache) every call's function for its argument types, the
    first call's in this process and the others, where two or more are missing from the cache,
    in a child process (module docstring). ``what`` names them on the progress line. Returns
    the seconds spent compiling (0 when everything was loaded)."""
    from .. import jit

    jobs = [(call, call.dispatcher(features), argument_types(call.args)) for call in calls]
    missing = [job for job in jobs if not _compiled(job[1], job[2]) and not _cached(job[1])]
    if not missing:
        for _, dispatcher, types in jobs:
            dispatcher.compile(types)
        return 0.0
    start = time.perf_counter()
    line = _ProgressLine(f"tracer: compiling the kernels for {what} (kept for the next runs)",
                         progress or (not QUIET and sys.stderr.isatty()))
    child = None
    try:
        with _exclusive(features, [job[1] for job in missing], line) as waited:
            if waited:  # another process compiled this build meanwhile: load what it wrote
                missing = [job for job in jobs if not _compiled(job[1], job[2]) and not _cached(job[1])]
            if len(missing) > 1 and _idle_core() and jit.CACHE:
                child = _start_child(features, [(call.reference(), types) for call, _, types in missing[1:]])
            if missing:
                missing[0][1].compile(missing[0][2])
            if child is not None:
                child.communicate()
            for _, dispatcher, types in jobs:  # loaded from the cache's entries, or compiled here
                dispatcher.compile(types)
    finally:
        if child is not None and child.poll() is None:
            child.kill()
            child.wait()
        line.close()
    return time.perf_counter() - start


@contextlib.contextmanager
def _exclusive(features, dispatchers: list, line: "_ProgressLine"):
    """Hold the build's lock (a file beside its cache entries, ``flock``) while compiling it, so
    that processes that need one build at once (the workers of a local cluster, two renders
    started together, a test suite's processes) compile it once: the others wait, then load what
    the first wrote. Yields whether it waited. Without a cache folder, or without ``fcntl``,
    nothing is locked (nothing would be shared)."""
    from .. import jit

    folder = next((getattr(getattr(d, "_cache", None), "cache_path", None) for d in dispatchers), None)
    if fcntl is None or not jit.CACHE or not folder:
        yield False
        return
    try:
        os.makedirs(folder, exist_ok=True)
        fd = os.open(os.path.join(folder, f"tracer-build-{features.key}.lock"), os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        yield False
        return
    try:
        waited = False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            line.text += "; another process is compiling them: waiting for it"
            fcntl.flock(fd, fcntl.LOCK_EX)
            waited = True
        yield waited
    finally:
        os.close(fd)  # releases the lock


def _idle_core() -> bool:
    """Whether a second core is free for a child compilation: the machine has one more core
    than the load of the last minute (a test suite in two processes keeps both busy, and a
    child then only competes with it)."""
    cores = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = 0.0
    return cores > 1 and load < cores - 0.5


def _start_child(features, work: list) -> subprocess.Popen | None:
    """A child process compiling ``work`` into the cache; None if it cannot start."""
    try:
        # The users' plug-ins are imported in the child first (from this process's import path),
        # so that they register there too.
        foreign = [module for module, _ in plugins.foreign(features.records())]
        payload = pickle.dumps((list(sys.path), foreign, features, work))
        child = subprocess.Popen([sys.executable, "-m", "tracer.kernels.compiling"], stdin=subprocess.PIPE,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        child.stdin.write(payload)
        child.stdin.close()
        return child
    except (OSError, pickle.PicklingError):
        return None


def _child() -> None:
    """The child's side: compile each function of the payload for its types (into the cache)."""
    import importlib

    path, modules, features, work = pickle.loads(sys.stdin.buffer.read())
    sys.path[:0] = [entry for entry in path if entry not in sys.path]
    for module in modules:
        importlib.import_module(module)
    for (module, name, is_template), types in work:
        function = getattr(importlib.import_module(module), name)
        dispatcher = build(features).function(function) if is_template else function
        dispatcher.compile(types)


class _ProgressLine:
    """One line on stderr that says ``text`` and the seconds so far, from QUIET_SECONDS on:
    redrawn every second on a terminal, printed every ten seconds elsewhere."""

    def __init__(self, text: str, enabled: bool):
        self.text = text
        self.start = time.perf_counter()
        self.done = threading.Event()
        self.tty = enabled and sys.stderr.isatty()
        self.shown = False
        self.thread = threading.Thread(target=self._run, daemon=True) if enabled else None
        if self.thread is not None:
            self.thread.start()

    def _run(self) -> None:
        period = 1.0 if self.tty else 10.0
        if self.done.wait(QUIET_SECONDS):
            return
        while True:
            elapsed = time.perf_counter() - self.start
            message = f"{self.text}: {elapsed:.0f} s"
            _say(("\r" + message) if self.tty else message + "\n")
            self.shown = True
            if self.done.wait(period):
                return

    def close(self) -> None:
        self.done.set()
        if self.thread is None:
            return
        self.thread.join()
        if self.shown:
            message = f"{self.text}: done in {time.perf_counter() - self.start:.1f} s"
            _say(("\r" + message if self.tty else message) + "\n")


def _say(text: str) -> None:
    """``text`` to stderr in one write: ``print`` writes a line's end apart from it, and a note
    printed by another thread (an interrupt's) could land between the two."""
    sys.stderr.write(text)
    sys.stderr.flush()


if __name__ == "__main__":
    _child()
