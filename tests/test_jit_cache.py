"""numba's on-disk cache, as tracer/jit.py keys it: every tracer entry carries the digest of all
tracer sources, so editing a module that a kernel inlined recompiles the kernel.

tracer/jit.py reaches into numba's private cache-locator classes to do this (numba documents no
way to add files to a cache key), and pyproject.toml caps numba at the versions whose source was
read. These tests are what to run before raising that cap."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import pickle
import shlex
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

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


def _env(root: Path, **extra: str) -> dict:
    """The environment for a fresh interpreter on the copy at root: no numba settings of ours,
    plus extra."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES", "NUMBA_DISABLE_JIT")}
    env["PYTHONPATH"] = str(root)
    # No .pyc files: the edit below keeps a.py's size, and CPython's .pyc check (whole-second
    # mtime and size) could otherwise serve the old bytecode within the same second.
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env["TRACER_INLINE"] = "always"  # the probes test inlined code (the suite's default is never)
    env.update(extra)
    return env


def _launch(root: Path, args: list[str], env: dict | None = None,
            prefix: list[str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*(prefix or []), sys.executable, *args], cwd=root,
                          env=env or _env(root), capture_output=True, text=True, timeout=120)


def _run_with_stderr(root: Path, env: dict | None = None,
                     prefix: list[str] | None = None) -> tuple[dict, str]:
    done = _launch(root, ["-c", RUN], env, prefix)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


def _run(root: Path) -> dict:
    return _run_with_stderr(root)[0]


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
    or an edit of lights.py would leave the shade kernel stale (it did, before tracer/jit.py);
    it fails if a build's kernel (``tracer.kernels``) got one of numba's own locators instead of
    tracer's."""
    from tracer import jit
    from tracer.estimator import kernels
    from tracer.kernels import FeatureSet, build

    assert jit.CACHE
    made = build(FeatureSet(("diffuse",), ("triangle_area",), "power", "independent", "bsdf", "mis",
                            True, True, False))
    shade = made.function(kernels.shade)
    locator = shade._cache._impl._locator  # the dispatcher's own cache (numba internals)
    assert type(locator).__name__.startswith("TracerStamped")
    assert locator.get_source_stamp() == jit.source_digest()
    assert made.key in shade._cache._impl.filename_base  # the feature set's key names the entry


@contextlib.contextmanager
def _read_only(folders: list[Path]):
    """Make folders read-only for the commands run with the prefix this yields. Not as root:
    chmod, undone on exit. As root, whom permission bits do not stop: a private mount namespace
    (``unshare``) in which each folder is bind-mounted read-only, as on a read-only install;
    skipped where that is not allowed."""
    if os.geteuid() != 0:
        for folder in folders:
            for path in [folder, *folder.rglob("*")]:
                path.chmod(path.stat().st_mode & ~0o222)
        try:
            yield []
        finally:
            for folder in folders:
                for path in [folder, *folder.rglob("*")]:
                    path.chmod(path.stat().st_mode | 0o200)
        return
    mounts = "".join(f"mount --bind {q} {q} && mount -o remount,ro,bind {q} {q} && "
                     for q in map(shlex.quote, map(str, folders)))
    prefix = ["unshare", "--mount", "--propagation", "private", "sh", "-c", mounts + 'exec "$@"', "sh"]
    if shutil.which("unshare") is None or subprocess.run([*prefix, "true"],
                                                          capture_output=True).returncode != 0:
        pytest.skip("root without mount namespaces: no way to make a folder read-only")
    yield prefix


def test_no_writable_cache_folder_compiles_in_memory_with_one_note(tmp_path):
    """Runs b.call() and ``tracer --help`` in fresh processes on a read-only copy of tracer,
    with HOME read-only too and no NUMBA_CACHE_DIR, and compares the results with 1.0 compiled
    in memory and stderr with exactly one note line naming the refused folders. It fails if
    numba's "no locator available" RuntimeError escapes when a module defines its kernels (it
    did: every command that imports one died), if the note is missing or printed once per
    kernel (a.value and b.call both try), or if ``--help`` prints anything on stderr."""
    site, home = tmp_path / "site", tmp_path / "home"
    home.mkdir()
    probe = _copy_with_probe(site)
    env = _env(site, HOME=str(home))
    env.pop("XDG_CACHE_HOME", None)  # numba's user-wide folder is then HOME/.cache/numba

    with _read_only([site, home]) as prefix:
        result, err = _run_with_stderr(site, env, prefix)
        helped = _launch(site, ["-m", "tracer", "--help"], env, prefix)

    assert (result["value"], result["hits"], result["misses"]) == (1.0, 0, 1)
    assert result["cache_path"] is None, "a cache was attached although no folder is writable"
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("tracer: note: cannot cache compiled kernels ("), err
    # The folder named is that of the first function given a cache in the process (tracer's own
    # ``jit.opaque``, defined before the probe's), and the user-wide one.
    assert f"{site}/tracer/" in lines[0] and "__pycache__" in lines[0] and str(home) in lines[0], err
    assert not (probe / "__pycache__").exists()
    assert helped.returncode == 0, helped.stderr
    assert helped.stdout.startswith("usage: tracer") and helped.stderr == ""


def _assert_recovers(root: Path) -> None:
    """A run over a damaged entry recompiles with one note; the run after it loads cleanly."""
    damaged, err = _run_with_stderr(root)
    assert (damaged["value"], damaged["hits"], damaged["misses"]) == (1.0, 0, 1)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracer: note: damaged compiled-kernel cache"), err

    again, err = _run_with_stderr(root)
    assert (again["value"], again["hits"], again["misses"]) == (1.0, 1, 0), "entry not rewritten"
    assert err == ""


@pytest.mark.parametrize("damage", ["truncated", "nonsense"])
def test_damaged_index_is_a_cache_miss(tmp_path, damage):
    """Compares b.call() and the cache counters across fresh processes after its .nbi index is
    cut in half, or replaced by numba's version header followed by a list instead of a (stamp,
    overloads) pair: the next run must compile with one note line, and the run after it must
    load from the cache with nothing on stderr. It fails if the unpickling error escapes (it
    did, on every run until __pycache__ was removed) or if the index is not rewritten."""
    probe = _copy_with_probe(tmp_path)
    _run(tmp_path)
    (index,) = (probe / "__pycache__").glob("b.call-*.nbi")
    if damage == "truncated":
        index.write_bytes(index.read_bytes()[: index.stat().st_size // 2])
    else:
        with index.open("rb") as f:
            version = pickle.load(f)
        index.write_bytes(pickle.dumps(version) + pickle.dumps(["not", "an", "index"]))
    _assert_recovers(tmp_path)


@pytest.mark.parametrize("damage", ["truncated", "garbage"])
def test_damaged_data_is_a_cache_miss(tmp_path, damage):
    """Compares b.call() and the cache counters across fresh processes after its .nbc data file
    (the compiled code) is cut in half or overwritten with bytes that are no pickle: the next
    run must compile with one note line, and the run after it must load from the cache with
    nothing on stderr. It fails if the unpickling error escapes (it did, on every run until
    __pycache__ was removed) or if the data file is not rewritten."""
    probe = _copy_with_probe(tmp_path)
    _run(tmp_path)
    (data,) = (probe / "__pycache__").glob("b.call-*.nbc")
    if damage == "truncated":
        data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    else:
        data.write_bytes(hashlib.sha256(b"garbage").digest() * 64)
    _assert_recovers(tmp_path)


def test_inlining_changes_no_bit_of_a_render(tmp_path):
    """The suite compiles with numba's inlining off (tests/conftest.py, ``tracer.jit.INLINE``),
    users' renders with it on: a render of the shipped Cornell box with each, in fresh
    processes, gives the same bits in every pixel (IEEE semantics either way: inlining moves
    code, it does not reorder arithmetic). The inlined render compiles the scene's own build in
    a cache folder of its own, as a user's render does; the other takes the suite's shared
    build from the suite's cache (other tests compile it too), which must render the bits of a
    scene's own build (tests/test_kernels.py): one fresh compile instead of two, and a
    difference from either cause is a defect."""
    import numpy as np

    scene = Path(tracer.__file__).parent / "scenes" / "cornell.toml"
    images = []
    for mode in ("always", "never"):
        out = tmp_path / f"{mode}.exr"
        env = {**os.environ, "TRACER_INLINE": mode}
        if mode == "always":
            env.update(TRACER_KERNELS="scene", NUMBA_CACHE_DIR=str(tmp_path / f"cache-{mode}"))
        done = subprocess.run([sys.executable, "-m", "tracer", "render", str(scene), "--strategy", "light",
                               "--spp", "4", "--width", "24", "--height", "24", "--quiet", "-o", str(out)],
                              env=env, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, done.stderr
        images.append(tracer.read_image(out))
    assert np.array_equal(images[0].mean, images[1].mean)
    assert np.array_equal(images[0].variance, images[1].variance, equal_nan=True)
