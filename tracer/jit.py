"""The one way tracer compiles its per-lane code: numba's ``njit`` with fixed options.

The estimator runs loops over lanes in compiled code instead of ~100 whole-array numpy passes
(see the documentation's results page on performance): one pass per batch, no temporaries. Options:

- caching: compiled machine code is kept beside the sources (``__pycache__``), or under
  ``NUMBA_CACHE_DIR`` when that is set, else in the user's cache folder, so only the first run
  after an install or an edit pays for compilation (about 50 s). If none of these folders is
  writable (a read-only install with no writable HOME), kernels are compiled in memory on each
  run and one note line on stderr says so; a damaged cache entry (a truncated or garbage
  ``.nbi`` index or ``.nbc`` data file) is a cache miss: recompiled and rewritten, with one note;
- ``nogil=True``: render threads run the kernels on both cores at once;
- ``error_model="numpy"``: x / 0 gives inf or nan as in numpy instead of raising, so a
  degenerate sample is caught by the render loop's non-finite guard;
- ``inline="always"``: small per-lane functions are inlined into the kernels before numba's
  own optimizations (measured: 370 -> 200 ns a lane for MIS shading); ``jit_called`` leaves
  the large solid-angle light techniques as calls, to keep the first compilation short.

Floating-point semantics stay IEEE (no ``fastmath``): results match numpy to rounding.

numba keys a cached function to its own source file only (a known limitation, stated in numba's
user guide under the ``cache`` option, user/jit.rst, and in developer/caching.rst), so a kernel
that inlined a function from another module would survive an edit of that module, stale.
tracer's cache entries are therefore keyed to the digest of all of tracer's sources,
subpackages included: any edit recompiles everything.

numba offers no documented way to add files to a function's cache key. The one documented
lever on locators, ``NUMBA_CACHE_LOCATOR_CLASSES`` (numba >= 0.62, reference/envvars.rst), is
read from the environment for the whole process and replaces the locator list of every cached
function, ours or not, so a library cannot use it without changing other numba users' caching.
This module instead adds, ahead of numba's own locators, subclasses that claim only files
inside this package; other functions fall through to numba's locators as before. That relies
on numba internals (``CacheImpl._locator_classes``, ``_SourceFileBackedLocatorMixin``, the
``from_function`` / ``get_source_stamp`` hooks), read in numba's source for every release from
0.60 to 0.68; pyproject.toml pins numba to that range, and tests/test_jit_cache.py checks end to
end that an edit of an inlined module in a subpackage recompiles its caller.

Failures of the cache must not stop a render, but numba lets two of them through: with no
writable cache folder, ``njit(cache=True)`` raises ``RuntimeError`` ("no locator available")
when a module defines its kernels, so every command that imports them dies; and a damaged
index or data file raises (``UnpicklingError``, ``EOFError``, ...) from the dispatcher's
compile on every later run, since numba neither recompiles nor rewrites the entry. So ``jit``
below compiles without numba's ``cache`` option and attaches the cache itself, as numba's
``Dispatcher.enable_caching`` does: it sets the dispatcher's ``_cache`` attribute to a
subclass of ``FunctionCache`` whose ``load_overload`` turns any error into a miss (and
``flush``, which writes an empty index, so that the save after the recompile does not trip
over the damaged index again) and whose ``save_overload`` turns an error into a note. If no
locator is usable, the dispatcher keeps the ``NullCache`` it was built with. The reason in
the note comes from the stamped locators' ``ensure_cache_path``, which numba's
``from_function`` calls to test a folder and which raises ``OSError`` when it is not
writable. Relied on, and identical in numba 0.60.0, 0.63.1 and 0.68.1 (read for this), where
``Cache`` and ``IndexDataCacheFile`` did not change at all: ``caching.FunctionCache`` (its
constructor taking the Python function; ``load_overload``, ``save_overload``, ``flush``,
``cache_path``), the ``RuntimeError`` from its constructor when no locator applies,
``_CacheLocator.ensure_cache_path`` and ``get_cache_path``, and ``Dispatcher._cache`` /
``py_func``. Each is looked up with ``getattr``; without them tracer caches nothing.
"""

from __future__ import annotations

import functools
import hashlib
import os
import sys
import threading
from pathlib import Path

from numba import njit

PACKAGE = Path(__file__).resolve().parent

# ``TRACER_INLINE=never``: compile every per-lane helper to be called instead of inlined into its
# callers by numba (``inline="never"``; LLVM may still inline it). The same code and the same
# bits (IEEE semantics either way; tests/test_jit_cache.py compares a render of each), but the
# first compilation takes about a third less time and the kernels run slower (measured on
# cornell's shared MIS build, 2026-12-03, an idle 2-core machine: 101 s -> 66 s to compile,
# 2.4 s -> 3.6 s to render 256x256 at 64 spp). For a test suite that compiles dozens of builds
# to render small images; renders keep the default, ``always``. Read when tracer is imported;
# part of the cache entries' stamp, so the two kinds of entry never load for each other.
INLINE_VARIABLE = "TRACER_INLINE"
INLINE = os.environ.get(INLINE_VARIABLE, "always")
_INLINE_REFUSED = INLINE not in ("always", "never")
if _INLINE_REFUSED:
    INLINE = "always"

_NOTED: set[str] = set()
_NOTE_LOCK = threading.Lock()


def _note(kind: str, text: str) -> None:
    """Print ``tracer: note: text`` on stderr, once per process for each kind of note."""
    with _NOTE_LOCK:
        if kind in _NOTED:
            return
        _NOTED.add(kind)
    print(f"tracer: note: {text}", file=sys.stderr, flush=True)


if _INLINE_REFUSED:
    _note("inline", f"{INLINE_VARIABLE}={os.environ[INLINE_VARIABLE][:40]!r} is neither 'always' nor 'never': "
                    "using 'always'")


def _describe(exc: BaseException) -> str:
    """An exception as one short line: its type, then its message if it has one."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# While ``_attach_cache`` builds a cache, the folders numba's locators tried and why each was
# refused, as (folder, OSError); None at other times. Per thread: modules may import in parallel.
_REFUSALS = threading.local()


def _refused(cache_path: str, exc: OSError) -> None:
    log = getattr(_REFUSALS, "log", None)
    if log is not None:
        log.append((cache_path, exc))


def _why_unwritable(refusals: list[tuple[str, OSError]]) -> str:
    """The refused folders as ``folder: reason; ...``, naming the folder that could not be
    created or written (the missing ancestor makedirs stopped at, if it says so), each once."""
    parts: dict[str, str] = {}
    for cache_path, exc in refusals:
        where = cache_path
        if exc.filename and Path(cache_path).is_relative_to(os.fspath(exc.filename)):
            where = os.fspath(exc.filename)
        parts.setdefault(where, (exc.strerror or _describe(exc)).lower())
    if not parts:
        return "no cache folder is writable"
    return "; ".join(f"{where}: {reason}" for where, reason in parts.items())


def _is_ours(py_file: str) -> bool:
    """Whether a function's source file lies in this package or any of its subpackages."""
    return PACKAGE in Path(py_file).resolve().parents


@functools.lru_cache(maxsize=1)
def source_digest() -> bytes:
    """SHA-256 of every Python source file under the package, subpackages included, taken in
    order of relative path; each file's relative path goes into the digest with its bytes, so
    moving or renaming a module changes it too. Computed once per process."""
    digest = hashlib.sha256()
    if INLINE != "always":  # its own entries (module comment at INLINE); the default's stamp as before
        digest.update(f"inline={INLINE}\0".encode())
    files = sorted(
        (path.relative_to(PACKAGE).as_posix(), path)
        for path in PACKAGE.rglob("*.py")
        if "__pycache__" not in path.relative_to(PACKAGE).parts
    )
    for name, path in files:
        digest.update(name.encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.digest()


def _install_package_stamp() -> bool:
    """Put, ahead of numba's own cache locators, a copy of each source-file-backed one (in
    numba's order, so ``NUMBA_CACHE_DIR`` still wins) that accepts only functions defined under
    the package and keys their entries to ``source_digest``. Functions of other packages fall
    through to numba's locators untouched. Idempotent.

    Returns False, and tracer then caches nothing (correct but slow), if this numba lacks the
    internals used here, if the package is not a plain folder (a zip: no digest to take), or if
    ``NUMBA_CACHE_LOCATOR_CLASSES`` is set when tracer is imported, since numba then consults
    only the classes named there and tracer's entries would be keyed to one file each."""
    try:
        from numba.core import caching, config
    except ImportError:  # pragma: no cover - numba without its caching module
        return False
    if getattr(config, "CACHE_LOCATOR_CLASSES", "") or not PACKAGE.is_dir():
        return False
    impl = getattr(caching, "CacheImpl", None)
    file_backed = getattr(caching, "_SourceFileBackedLocatorMixin", None)
    if impl is None or file_backed is None or not hasattr(impl, "_locator_classes"):
        return False
    if any(getattr(cls, "tracer_stamped", False) for cls in impl._locator_classes):
        return True

    def stamped(base):
        class PackageStamped(base):
            tracer_stamped = True

            def get_source_stamp(self):
                return source_digest()

            @classmethod
            def from_function(cls, py_func, py_file):
                if not _is_ours(py_file):
                    return None
                return super().from_function(py_func, py_file)

            def ensure_cache_path(self):
                try:
                    super().ensure_cache_path()
                except OSError as exc:
                    _refused(self.get_cache_path(), exc)
                    raise

        PackageStamped.__name__ = PackageStamped.__qualname__ = (
            f"TracerStamped{base.__name__.lstrip('_')}"
        )
        return PackageStamped

    ours = [stamped(cls) for cls in impl._locator_classes if issubclass(cls, file_backed)]
    if not ours:
        return False
    impl._locator_classes = ours + list(impl._locator_classes)
    return True


def _tolerant_cache_class():
    """numba's ``FunctionCache`` with its failures turned into cache misses and notes, or None
    if this numba lacks it."""
    try:
        from numba.core import caching
    except ImportError:  # pragma: no cover - numba without its caching module
        return None
    base = getattr(caching, "FunctionCache", None)
    if base is None or not all(hasattr(base, name) for name in ("load_overload", "save_overload",
                                                                 "flush", "cache_path")):
        return None

    class TracerFunctionCache(base):
        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except Exception as exc:  # any damage to the index or the data file: a miss
                _note("damaged", f"damaged compiled-kernel cache in {self.cache_path} "
                                 f"({_describe(exc)}); recompiling and rewriting it")
                try:
                    self.flush()  # a fresh, empty index, so that the save after compiling works
                except Exception:
                    pass  # the save will fail too, and say so
                return None

        def save_overload(self, sig, data):
            try:
                super().save_overload(sig, data)
            except Exception as exc:
                _note("uncacheable", f"cannot cache compiled kernels (writing to {self.cache_path} "
                                     f"failed: {_describe(exc)}); compiling each run (~50 s)")

    return TracerFunctionCache


CACHE = _install_package_stamp()
_CACHE_CLASS = _tolerant_cache_class() if CACHE else None
if _CACHE_CLASS is None:
    CACHE = False

_compile = njit(nogil=True, error_model="numpy", inline=INLINE)
_compile_inlined = njit(nogil=True, error_model="numpy", inline="always")
_compile_called = njit(nogil=True, error_model="numpy", inline="never")


def _attach_cache(dispatcher) -> None:
    """Give a dispatcher tracer's cache, as numba's ``enable_caching`` gives it numba's. If no
    cache folder is writable, the dispatcher keeps compiling in memory and one note per process
    says which folders were refused and why."""
    _REFUSALS.log = refusals = []
    try:
        cache = _CACHE_CLASS(dispatcher.py_func)
    except Exception as exc:  # RuntimeError from numba: no locator, i.e. no writable folder
        why = _why_unwritable(refusals) if isinstance(exc, RuntimeError) else _describe(exc)
        _note("uncacheable", f"cannot cache compiled kernels ({why}); compiling each run "
                             "(~50 s); set NUMBA_CACHE_DIR to a writable folder to keep them")
        return
    finally:
        _REFUSALS.log = None
    dispatcher._cache = cache


def jit(py_func):
    """Compile ``py_func`` with tracer's options (module docstring), cached on disk when a
    cache folder is writable."""
    return _cached(_compile(py_func))


def jit_called(py_func):
    """As :func:`jit`, but callers call the compiled function instead of inlining it: for the
    large solid-angle light techniques, whose inlining into both kernels multiplied the first
    compilation's time (measured: over 2 minutes). A call costs a few nanoseconds; the cheap
    techniques (area, point, sphere) stay inlined, since calling the whole light dispatcher
    instead made cornell's area-sampled MIS 20% slower. Also for the stratified and Sobol
    samplers' draws, which every kernel calls at six places: inlined, they doubled the first
    compilation (115 s against 49 s). And for the materials that Mitsuba scenes brought
    (plastic, rough plastic, the Beckmann sampler, the conductor's complex Fresnel term):
    inlined into the two kernels' dispatch, they took the first compilation from 74 s to
    369 s at a load of 3 (264 s of CPU); called, 145 s (101 s of CPU) at the same load."""
    return _cached(_compile_called(py_func))


def jit_generated(py_func):
    """As :func:`jit`, without a cache of its own: for the generated dispatch chains
    (``tracer.kernels.dispatch``), which have no source file to key a cache entry to and are
    inlined into the kernels, whose entries hold them (always inlined, whatever ``INLINE``
    says: a kernel's cache entry cannot name a function that has no module to load it from)."""
    return _compile_inlined(py_func)


def _cached(dispatcher):
    if CACHE and hasattr(dispatcher, "_cache"):
        _attach_cache(dispatcher)
    return dispatcher


@jit_called
def opaque(flag: bool) -> bool:
    """``flag`` as a value numba knows only at run time. numba types a constant True or False
    passed to a compiled function as a literal and compiles the function once for each value
    (measured: the warped solid-angle techniques compiled twice, 20 s more); passed through
    this, the callers of both values share one compilation. (A comparison, because numba keeps
    a literal type through a function that returns its argument as it is.)"""
    return flag == True  # noqa: E712
