"""tracer check: passes on the shipped tree, fails on a noisier or biased estimator.

The noise tests are one-sided exact Mann-Whitney U tests and the bias tests per-pixel and
image-mean z-tests, all at a 1% false-alarm rate for the whole baseline file (see
tracer/study/check.py); these tests show that the bounds are neither so wide that real
regressions pass nor so tight that an unchanged tree with other random numbers fails.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
from pathlib import Path

import pytest

from tracer import estimators
from tracer.cli import main
from tracer.errors import InputError
from tracer.study.check import format_table, load_baseline, run_check, save_baseline

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / "renders" / "noise_baseline.json"


@pytest.fixture
def baseline_copy(tmp_path):
    """The shipped baseline beside a copy of the references, so tests can edit it freely."""
    shutil.copytree(ROOT / "renders" / "references", tmp_path / "references")
    path = tmp_path / "baseline.json"
    shutil.copy(BASELINE, path)
    return path


def _only(path: Path, *names: str) -> list:
    return [e for e in load_baseline(path) if e.name in names]


def test_shipped_tree_passes():
    """The committed baseline was measured from this tree with these seeds: every entry holds."""
    result = run_check(BASELINE, stream=None)
    assert result.ok, format_table(result.verdicts)


def test_halved_baseline_noise_fails_with_table_and_maps(baseline_copy, tmp_path):
    """A baseline that claims half the noise makes the check fail on relMSE and variance, and
    the failing entry's image, reference, error and p-value maps are written."""
    entries = load_baseline(baseline_copy)
    for e in entries:
        if e.name == "cornell/light":
            e.relmse, e.relmse_seeds = e.relmse / 2, [x / 2 for x in e.relmse_seeds]
            e.variance, e.variance_seeds = e.variance / 2, [x / 2 for x in e.variance_seeds]
    save_baseline(baseline_copy, entries)
    out = tmp_path / "failures"
    result = run_check(baseline_copy, out=out, stream=None, entries=_only(baseline_copy, "cornell/light"))
    failed = {(v.entry, v.measure) for v in result.verdicts if not v.ok}
    assert failed == {("cornell/light", "relmse"), ("cornell/light", "variance")}
    table = format_table(result.verdicts)
    assert "FAIL" in table and "ratio" in table
    for file in ("image.exr", "reference.exr", "error.png", "pvalue.png"):
        assert (out / "cornell_light" / file).is_file(), file


def _patch_estimator(monkeypatch, change):
    """Every DirectLighting built from now on gets ``change(estimator)`` applied after its
    constructor: the faults below are injected into the tables the compiled kernels read."""
    original = estimators.DirectLighting.__init__

    def patched(self, *args, **kwargs):
        original(self, *args, **kwargs)
        change(self)

    monkeypatch.setattr(estimators.DirectLighting, "__init__", patched)


def test_noisier_estimator_fails(baseline_copy, monkeypatch):
    """MIS switched by mistake to its one-sample form (one technique per sample, chosen with
    probability 1/2) stays unbiased but takes half the samples: the noise test catches it and
    the image mean stays unbiased. The fault: every estimator is built with one_sample set."""
    original = estimators.DirectLighting.__init__

    def one_sample(self, scene, strategy, *args, **kwargs):
        original(self, scene, dataclasses.replace(strategy, one_sample=True), *args, **kwargs)

    monkeypatch.setattr(estimators.DirectLighting, "__init__", one_sample)
    result = run_check(baseline_copy, stream=None, entries=_only(baseline_copy, "veach_mis/mis-power"))
    failed = {v.measure for v in result.verdicts if not v.ok}
    assert "relmse" in failed, format_table(result.verdicts)
    assert "image mean z" not in failed


def test_biased_estimator_fails(baseline_copy, monkeypatch):
    """A light pdf 10% too large (an image 10% too dark) fails the per-pixel and image-mean
    bias tests. The fault: the 1 / area column of the triangle rows of the light table."""
    from tracer.lights import TRIANGLE_AREA, triangle_area

    def biased(est):
        rows = est.lights.tables.rows.copy()
        rows[est.lights.tables.technique == TRIANGLE_AREA, triangle_area.INV_AREA] *= 1.1
        est.lights.tables = est.lights.tables._replace(rows=rows)

    _patch_estimator(monkeypatch, biased)
    result = run_check(baseline_copy, stream=None, entries=_only(baseline_copy, "cornell/light"))
    failed = {v.measure for v in result.verdicts if not v.ok}
    assert {"pixels passing", "image mean z"} <= failed, format_table(result.verdicts)


@pytest.mark.parametrize("offset", [1000, 2000, 3000])
def test_unchanged_tree_passes_with_other_seeds(offset):
    """With other random numbers the unchanged tree passes: the tolerances come from the spread
    over seeds and the reference's error, not from reproducing the baseline bit for bit."""
    result = run_check(BASELINE, seed_offset=offset, stream=None)
    assert result.ok, format_table(result.verdicts)


@pytest.mark.slow
@pytest.mark.parametrize("offset", range(10_000, 30_000, 1000))
def test_unchanged_tree_passes_with_many_seeds(offset):
    """Twenty more seed sets (slow): at a 1% family rate a failure here is most likely real."""
    result = run_check(BASELINE, seed_offset=offset, stream=None)
    assert result.ok, format_table(result.verdicts)


def test_update_and_command_line(baseline_copy, tmp_path, capsys):
    """--update writes fresh means and spreads; the command then passes (exit 0), prints the
    table, and a broken baseline exits 2 with one line."""
    doc = json.loads(baseline_copy.read_text())
    doc["entries"] = [{k: v for k, v in e.items() if k in ("scene", "strategy", "heuristic", "spp", "seeds")}
                      for e in doc["entries"] if e["scene"] == "point_light"]
    baseline_copy.write_text(json.dumps(doc))
    assert main(["check", "--baseline", str(baseline_copy), "--update", "--threads", "2"]) == 0
    entries = load_baseline(baseline_copy)
    assert all(e.relmse > 0 and len(e.relmse_seeds) == len(e.seeds) and e.variance > 0 for e in entries)
    capsys.readouterr()
    assert main(["check", "--baseline", str(baseline_copy), "--out", str(tmp_path / "f")]) == 0
    out = capsys.readouterr().out
    assert "point_light/light" in out and "relmse" in out and "FAIL" not in out

    bad = copy.deepcopy(doc)
    bad["entries"][0]["strategy"] = "fast"
    baseline_copy.write_text(json.dumps(bad))
    assert main(["check", "--baseline", str(baseline_copy)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "entries[0].strategy" in err[0]


GOOD_ENTRY = {"scene": "cornell", "strategy": "mis", "spp": 16, "seeds": [1, 2, 3]}
DAMAGED_ENTRIES = {
    "spp as a string": ({"spp": "16"}, "entries[0].spp"),
    "fractional spp": ({"spp": 16.5}, "entries[0].spp"),
    "seeds not a list": ({"seeds": 5}, "entries[0].seeds"),
    "string seeds": ({"seeds": ["a", "b"]}, "entries[0].seeds"),
    "repeated seeds": ({"seeds": [1, 1]}, "entries[0].seeds"),
    "bad heuristic": ({"heuristic": "mean"}, "entries[0].heuristic"),
    "negative light samples": ({"light_samples": -3}, "entries[0].light_samples"),
    "boolean spp": ({"spp": True}, "entries[0].spp"),
    "NaN relmse": ({"relmse": float("nan")}, "entries[0].relmse"),
    "per-seed values of another length": ({"relmse_seeds": [0.1]}, "entries[0].relmse_seeds"),
    "no samples at all": ({"strategy": "light", "light_samples": 0}, "entries[0]"),
    "scene missing": ({"scene": None}, "entries[0].scene"),
}


@pytest.mark.parametrize("case", sorted(DAMAGED_ENTRIES))
def test_damaged_baseline_is_refused_with_the_key(case, tmp_path):
    """Every damaged field of a baseline entry is refused on load with InputError naming the
    file and the entry's key (before: tracebacks deep in the check for nine such files)."""
    import json

    change, key = DAMAGED_ENTRIES[case]
    entry = {k: v for k, v in {**GOOD_ENTRY, **change}.items() if v is not None}
    path = tmp_path / "baseline.json"
    path.write_text(json.dumps({"entries": [entry]}))
    with pytest.raises(InputError) as info:
        load_baseline(path)
    assert key in str(info.value) and "baseline.json" in str(info.value), str(info.value)
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"entries": [GOOD_ENTRY]}))
    assert load_baseline(good)[0].spp == 16


def test_a_reference_of_another_scene_is_refused(baseline_copy, capsys):
    """An entry for cornell whose reference is veach_mis's (same size, both square): the check
    refuses it before rendering, exit 2, one line naming the reference file and
    tracer:scene_digest. Before the digest the check measured cornell against veach_mis and
    reported the noise as a regression (or a pass), whichever it happened to be."""
    doc = json.loads(baseline_copy.read_text())
    entry = next(e for e in doc["entries"] if e["scene"] == "cornell")
    entry["reference"] = "references/veach_mis.exr"
    doc["entries"] = [entry]
    baseline_copy.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["check", "--baseline", str(baseline_copy)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "veach_mis.exr: tracer:scene_digest" in err[0], err


def test_an_interrupted_check_neither_judges_nor_writes(baseline_copy, monkeypatch, capsys):
    """Ctrl-C during `check --update` (injected: the second render reports it was interrupted,
    as render() does after a signal): exit 130 and the baseline file unchanged. Before, the cut
    render was measured as if it had its full spp and written into the baseline, exit 0."""
    from tracer import render_loop

    doc = json.loads(baseline_copy.read_text())
    doc["entries"] = [e for e in doc["entries"] if e["scene"] == "point_light"][:1]
    baseline_copy.write_text(json.dumps(doc))
    before = baseline_copy.read_bytes()
    real_render = render_loop.render
    calls = []

    def interrupted_on_second_call(*args, **kwargs):
        result = real_render(*args, **kwargs)
        calls.append(1)
        result.interrupted = result.interrupted or len(calls) == 2
        return result

    monkeypatch.setattr(render_loop, "render", interrupted_on_second_call)
    assert main(["check", "--baseline", str(baseline_copy), "--update"]) == 130
    assert baseline_copy.read_bytes() == before and len(calls) == 2
    assert "interrupted" in capsys.readouterr().err


@pytest.mark.parametrize("content, words", [
    (b"[" * 100_000, "nested too deeply"),
    (b'{"entries": [{"spp": ' + b"7" * 5000 + b"}]}", "not a readable JSON baseline"),
    (b'{"entries": [\xff]}', "not a readable JSON baseline"),
    (b'{"entries": [{"scene": "cornell", "strategy": "mis", "spp": 1, "seeds": [1], "a\\nb": 1}]}',
     "unknown key 'a\\nb'"),
])
def test_hostile_baseline_text_is_one_line(content, words, tmp_path, capsys):
    """JSON nested 100,000 deep (RecursionError), a 5,000-digit number (Python's digit limit,
    ValueError), bytes that are not UTF-8 (UnicodeDecodeError) and a key holding a newline
    (printed raw, two lines): each is refused with exit 2 and one line naming the file."""
    path = tmp_path / "hostile.json"
    path.write_bytes(content)
    assert main(["check", "--baseline", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "hostile.json" in err and words in err, err
