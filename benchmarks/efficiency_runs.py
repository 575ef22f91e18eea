"""What the technique benchmarks share (benchmarks/light_sampling.py, environment_sampling.py):
a strategy's relMSE and efficiency at equal spp and at equal time over several seeds, and a
child process in Mitsuba's interpreter.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

# Mitsuba's llvm variants need LLVM >= 19 (Debian 12: the libllvm19 package); Dr.Jit finds an
# older system LLVM first and then fails ("Cannot select: fmaximum"), so a child is pointed at
# this one when it exists and DRJIT_LIBLLVM_PATH is not set.
LIBLLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"


def measure(scene, reference, strategy, seeds: list[int], spp: int, seconds: float, threads: int,
            row: dict, masks: dict | None = None) -> dict:
    """``row`` with, for ``strategy`` on ``scene`` against ``reference`` (a Film), each seed's
    ``equal_spp`` (``spp`` samples) and ``equal_time`` (``seconds`` of wall time) run, and their
    means: ``{kind}_relmse``, ``{kind}_seconds`` and ``{kind}_efficiency`` = 1 / (relMSE x s);
    for each of ``masks`` (name -> (pixels,) bool, the pixels of some objects) the same relMSE
    and efficiency over those pixels alone, ``{kind}_{name}_relmse`` and
    ``{kind}_{name}_efficiency``."""
    from tracer.study import metrics
    from tracer.study.compare import Comparison

    masks = masks or {}
    variance = reference.variance_of_mean()

    row.update(equal_spp=[], equal_time=[])
    for seed in seeds:
        comparison = Comparison(scene, reference, seed, threads)
        for kind, run in (("equal_spp", comparison.equal_spp(strategy, spp)),
                          ("equal_time", comparison.equal_time(strategy, seconds))):
            record = {"seed": seed, "spp": run.spp, "seconds": run.seconds, "relmse": run.measures["relmse"]}
            for name, mask in masks.items():
                record[f"relmse_{name}"] = metrics.relmse(run.film.mean[mask], reference.mean[mask],
                                                          variance[mask])
            row[kind].append(record)
    for kind in ("equal_spp", "equal_time"):
        rel = sum(r["relmse"] for r in row[kind]) / len(row[kind])
        sec = sum(r["seconds"] for r in row[kind]) / len(row[kind])
        row[f"{kind}_relmse"], row[f"{kind}_seconds"] = rel, sec
        row[f"{kind}_efficiency"] = 1.0 / (rel * sec)
        for name in masks:
            rel = sum(r[f"relmse_{name}"] for r in row[kind]) / len(row[kind])
            row[f"{kind}_{name}_relmse"], row[f"{kind}_{name}_efficiency"] = rel, 1.0 / (rel * sec)
    return row


def write_results(folder: Path, name: str, doc: dict, markdown) -> None:
    """``folder/name.json`` (``doc``) and ``folder/name.md`` (``markdown``, also printed): the
    text, or a function of ``doc`` that makes it, called once the JSON is written, so that a
    failing table never loses a long run's numbers."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.json").write_text(json.dumps(doc, indent=1) + "\n")
    if callable(markdown):
        markdown = markdown(doc)
    (folder / f"{name}.md").write_text(markdown)
    print(markdown)


def mitsuba_child(python: str, script: str | Path, spec: dict) -> dict:
    """Run ``script --mitsuba-child SPEC`` with Mitsuba's interpreter ``python`` and return the
    JSON its last line prints; RuntimeError with its stderr's tail if it fails."""
    env = dict(os.environ)
    if "DRJIT_LIBLLVM_PATH" not in env and os.path.exists(LIBLLVM19):
        env["DRJIT_LIBLLVM_PATH"] = LIBLLVM19
    proc = subprocess.run([python, str(script), "--mitsuba-child", json.dumps(spec)],
                          capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"Mitsuba child failed: {proc.stderr.strip()[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    sys.exit("a module of the benchmarks: run benchmarks/light_sampling.py or environment_sampling.py")
