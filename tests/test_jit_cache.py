"""numba's on-disk cache, as tracer/jit.py keys it: every tracer entry carries the digest of all
tracer sources, so editing a module that a kernel inlined recompiles the kernel.

tracer/jit.py reaches into numba's private cache-locator classes to do this (numba documents no
way to add files to a cache key), and pyproject.toml caps numba at the versions whose source was
read. These tests are what to run before raising that cap."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import tracer

# Jitted probe functions, placed in a subpackage of a copy of tracer: b.call inlines a.value
# (tracer's jit uses inline="always"), so b's compiled code holds a's return value.
PROBE_A = """\
from tracer.jit import jit


@jit
def value():
    return {value}
"""

PROBE_B = """\
from tracer._probe import a
from tracer.jit import jit


@jit
def call():
    return a.value()
"""

# Run in a fresh interpreter: call b.call() once and report its value, whether numba loaded it
# from the cache or compiled it, where the cache lives, and which modules the imports pulled in.
RUN = textwrap.dedent("""\
    import json
    import sys

    import tracer
    from tracer import jit
    from tracer._probe import b

    result = b.call()
    stats = b.call.stats
    print(json.dumps({
        "value": result,
        "hits": sum(stats.cache_hits.values()),
        "misses": sum(stats.cache_misses.values()),
        "cache_path": stats.cache_path,
        "cache": jit.CACHE,
        "package": tracer.__file__,
        "modules": sorted(m for m in sys.modules if m == "tracer" or m.startswith("tracer.")),
        "embree": any(m.startswith("embree") for m in sys.modules),
    }))
""")


def _copy_with_probe(root: Path) -> Path:
    """Copy the installed tracer sources to root/tracer and add the probe subpackage; returns
    the probe folder."""
    shutil.copytree(Path(tracer.__file__).parent, root / "tracer",
                    ignore=shutil.ignore_patterns("__pycache__"))
    probe = root / "tracer" / "_probe"
    probe.mkdir()
    (probe / "__init__.py").write_text("")
    (probe / "a.py").write_text(PROBE_A.format(value="1.0"))
    (probe / "b.py").write_text(PROBE_B)
    return probe


def _run(root: Path) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES", "NUMBA_DISABLE_JIT")}
    env["PYTHONPATH"] = str(root)
    # No .pyc files: the edit below keeps a.py's size, and CPython's .pyc check (whole-second
    # mtime and size) could otherwise serve the old bytecode within the same second.
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    done = subprocess.run([sys.executable, "-c", RUN], cwd=root, env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_edit_of_inlined_module_recompiles_its_caller(tmp_path):
    """Compares b.call() across three fresh processes on a copy of tracer: after a first run
    compiles and caches it, a second run with no edit must load it from the cache (cache_hits,
    the dispatcher's public counter of overloads loaded from disk), and a third run after a.py
    changes 1.0 to 2.0 must compile again and return 2.0. It fails if tracer's entries are keyed
    to their own file only (numba's default, which returns the stale 1.0), if the digest skips
    subpackages or the locator refuses files in them (same stale 1.0), or if nothing is cached
    at all (no hit on the second run)."""
    probe = _copy_with_probe(tmp_path)

    first = _run(tmp_path)
    assert Path(first["package"]).resolve() == (tmp_path / "tracer" / "__init__.py").resolve()
    assert first["cache"] is True
    assert first["modules"] == ["tracer", "tracer._probe", "tracer._probe.a", "tracer._probe.b",
                                "tracer.jit"], "importing tracer.jit pulled in heavy modules"
    assert not first["embree"]
    assert Path(first["cache_path"]).resolve() == (probe / "__pycache__").resolve()
    assert (first["value"], first["hits"], first["misses"]) == (1.0, 0, 1)

    again = _run(tmp_path)
    assert (again["value"], again["hits"], again["misses"]) == (1.0, 1, 0), "not loaded from cache"

    (probe / "a.py").write_text(PROBE_A.format(value="2.0"))
    edited = _run(tmp_path)
    assert edited["value"] == 2.0, "b.call kept the inlined a.value from before the edit"
    assert (edited["hits"], edited["misses"]) == (0, 1)


def test_installed_numba_supports_the_keying():
    """Compares jit.CACHE with True: it is False when the installed numba lacks the internals
    tracer/jit.py hooks into (or NUMBA_CACHE_LOCATOR_CLASSES is set), and tracer then silently
    compiles every kernel on every run."""
    from tracer import jit

    assert jit.CACHE is True


def test_compiled_code_is_keyed_to_all_sources():
    """Compares the stamp of a real kernel's cache entry with the digest of all package sources.
    tracer's kernels inline functions of other modules, so every entry must carry that digest,
    or an edit of lights.py would leave estimators._shade stale (it did, before tracer/jit.py);
    it fails if the kernel got one of numba's own locators instead of tracer's."""
    from tracer import estimators, jit

    assert jit.CACHE
    locator = estimators._shade._cache._impl._locator  # the dispatcher's own cache (numba internals)
    assert type(locator).__name__.startswith("TracerStamped")
    assert locator.get_source_stamp() == jit.source_digest()
