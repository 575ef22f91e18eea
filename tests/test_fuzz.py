"""A seeded slice of the fuzzer in benchmarks/fuzz.py, which holds the code (one copy): hostile
scene files, meshes, render EXRs and noise baselines, each run through tracer's API and CLI."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
fuzz = importlib.import_module("fuzz")  # by name on sys.path: its worker process imports it too


def run_slice(tmp_path: Path, seed: int, scenes: int, exrs: int, baselines: int, xmls: int = 0,
              schedulers: int = 0) -> None:
    keep = tmp_path / "keep"
    report = fuzz.run(seed=seed, scenes=scenes, exrs=exrs, baselines=baselines, jobs=2, timeout=120.0,
                      keep=keep, progress=False, workdir=tmp_path, xmls=xmls, schedulers=schedulers)
    assert report.outcomes, "the fuzzer ran no checks"
    if report.failures:
        pytest.fail(fuzz.format_report(report, keep), pytrace=False)


def test_fuzz_slice(tmp_path):
    """Every outcome of 15 seeded hostile inputs (5 scenes, 3 EXRs, 2 baselines, 3 Mitsuba XML
    scenes, 2 scheduler addresses; about 30 s: test_fuzz_bigger and benchmarks/fuzz.py run more)
    is compared with the bad-input promise: exit 0 with finite EXR/JSON/CSV outputs, or exit 2
    with exactly one stderr line, and in-process only tracer.InputError. It fails when tracer
    prints a traceback, dies from a signal, runs past 120 s (a scheduler address: past its
    connect timeout and 55 s), writes NaN or inf, or refuses in more or fewer than one line; the
    inputs are a function of the seed, so a failure repeats
    (`python benchmarks/fuzz.py --seed 0 --only FAMILY:INDEX`) and the report names each one."""
    run_slice(tmp_path, seed=0, scenes=5, exrs=3, baselines=2, xmls=3, schedulers=2)


@pytest.mark.slow
def test_fuzz_bigger(tmp_path):
    """The same comparison over 280 other inputs (120 scenes, 50 EXRs, 30 baselines, 60 XML
    scenes, 20 scheduler addresses; a few minutes): rarer mutations and their combinations."""
    run_slice(tmp_path, seed=1, scenes=120, exrs=50, baselines=30, xmls=60, schedulers=20)
