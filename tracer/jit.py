"""The one way tracer compiles its per-lane code: numba's ``njit`` with fixed options.

The estimator runs loops over lanes in compiled code instead of ~100 whole-array numpy passes
(see the README's Performance section): one pass per batch, no temporaries. Options:

- ``cache=True``: compiled machine code is kept beside the sources (``__pycache__``), so only
  the first run after an install or an edit pays for compilation (about 20 s);
- ``nogil=True``: render threads run the kernels on both cores at once;
- ``error_model="numpy"``: x / 0 gives inf or nan as in numpy instead of raising, so a
  degenerate sample is caught by the render loop's non-finite guard;
- ``inline="always"``: small per-lane functions are inlined into the kernels before numba's
  own optimizations (measured: 370 -> 200 ns a lane for MIS shading).

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
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

from numba import njit

PACKAGE = Path(__file__).resolve().parent


def _is_ours(py_file: str) -> bool:
    """Whether a function's source file lies in this package or any of its subpackages."""
    return PACKAGE in Path(py_file).resolve().parents


@functools.lru_cache(maxsize=1)
def source_digest() -> bytes:
    """SHA-256 of every Python source file under the package, subpackages included, taken in
    order of relative path; each file's relative path goes into the digest with its bytes, so
    moving or renaming a module changes it too. Computed once per process."""
    digest = hashlib.sha256()
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

        PackageStamped.__name__ = PackageStamped.__qualname__ = (
            f"TracerStamped{base.__name__.lstrip('_')}"
        )
        return PackageStamped

    ours = [stamped(cls) for cls in impl._locator_classes if issubclass(cls, file_backed)]
    if not ours:
        return False
    impl._locator_classes = ours + list(impl._locator_classes)
    return True


CACHE = _install_package_stamp()

jit = njit(cache=CACHE, nogil=True, error_model="numpy", inline="always")
