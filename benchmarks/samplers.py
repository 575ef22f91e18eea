"""Samplers side by side (independent, stratified, sobol): convergence, cost, equal-time efficiency.

    python benchmarks/samplers.py [--scenes cornell,veach_mis] [--samplers independent,stratified,sobol]
                                  [--spp-max 1024] [--seeds 4] [--fit-min 16] [--threads 2]
                                  [--out benchmarks/results] [--figure renders/samplers_convergence.png]
    python benchmarks/samplers.py --analyse benchmarks/results/samplers.json [--note TEXT ...]
        # tables and figure again from the JSON (no rendering), optionally with (new) notes for the .md

The ``mis`` strategy with its default options, 256x256 (the references' size), against the shipped
references ``renders/references/SCENE.exr`` (1024-spp ``independent``, seed 0; relMSE less the
reference's own noise, ``tracer.compare``). For each scene, sampler, spp = 4, 8, ..., ``--spp-max``
and each of ``--seeds`` seed indices k, one fresh render: no render continues another, and each has
its own seed (1 + 1000 k + 100 x sampler index + spp index; never a seed the reference holds), so
that every render is independent of every other, also across samplers (``independent``'s sample r
and replicate r of the others start from the same hash of (seed, pixel, r)).

Measured, all in this one run:

- relMSE against spp: per point the mean over seeds, min and max, and the standard error of the mean
  of log relMSE;
- the slope of log relMSE against log spp, fitted per seed over spp ``--fit-min`` .. ``--spp-max``
  and summarised as the mean of the per-seed slopes with its t-interval (95%). Why from 16: the
  stratified and Sobol samplers split a pixel's samples into 8 replicates (``tracer.samplers``), so
  at 4 and 8 spp every replicate holds at most one point and they are plain random sampling; from
  16 spp on (2+ points per replicate) the stratification can act. The same slope of the relMSE the
  film's own variance predicts (no reference involved) is a check on the reference's correction;
- relMSE at 64 spp of each sampler as a ratio to ``independent``'s: ratio of the means over seeds,
  with a delta-method interval on its log (t quantile, n - 1 degrees of freedom) and a percentile
  bootstrap over seeds (each sampler's seeds resampled on their own: their renders are
  independent);
- cost per sample: seconds / spp, pooled over the renders of 64 spp and more (where a render's fixed
  costs are negligible) per seed, as a ratio to ``independent``'s of the same seed (the renders of
  one seed and spp run back to back, the samplers' order rotated from point to point, so that
  machine load hits all alike); geometric mean of the per-seed ratios with its t-interval. On the
  wall clock (``Image.seconds``: the render loop's, after the kernels are compiled) and, as a check
  less disturbed by other processes, on the process's CPU time around ``tracer.render``;
- equal-time efficiency 1 / (relMSE x seconds) at 64 and 256 spp as a ratio to ``independent``'s:
  the ratio of the mean relMSE over the wall-clock cost ratio, intervals combined on the log scale;
  and, as a check, the ratio of relMSE at equal time: each sampler's mean relMSE interpolated
  (log-log) at the spp it renders in the time ``independent`` takes for 64 (256) spp.

Before any timing, each sampler renders each scene once at 1 spp (untimed, excluded): numba
compiles its kernels (about 100 s after any change under ``tracer/``) or loads them from its cache.

Writes OUT/samplers.json (every render: seed, seconds, CPU seconds, relMSE, the uncorrected relMSE
and the relMSE the film's own variance predicts; the machine; the summary), OUT/samplers.md and the
figure, and prints the tables. Timing lives in benchmarks, never in the tests; the machine and its
load average are recorded with the numbers.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SAMPLERS = ("independent", "stratified", "sobol")
BASE = "independent"
SIZE = 256
RATIO_SPP = 64
EFFICIENCY_SPP = (64, 256)
TIMING_MIN_SPP = 64
CLOCKS = {"wall": "seconds", "cpu": "cpu_seconds"}  # clock -> key of a render's row
BOOTSTRAP = 10_000
# (scene, sampler, target): relMSE ratio at RATIO_SPP at most the target; efficiency ratio above it
TARGETS = {"ratio_64": ("cornell", "sobol", 0.5), "equal_time": ("cornell", "sobol", 1.0)}
NAN = float("nan")


def machine() -> dict:
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        git = ["git", "-C", str(ROOT)]
        commit = subprocess.run(git + ["rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True).stdout.strip()
        dirty = subprocess.run(git + ["status", "--porcelain", "--", "tracer"], capture_output=True,
                               text=True).stdout.strip()
    except OSError:
        commit, dirty = "", ""
    digest = hashlib.sha256()
    for path in sorted((ROOT / "tracer").rglob("*.py")):
        digest.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes())
    return {"nproc": os.cpu_count(), "cpu": model, "python": platform.python_version(), "commit": commit,
            "tracer_dirty": bool(dirty), "tracer_sources_sha256": digest.hexdigest()}


def load_average() -> list[float]:
    return [round(v, 2) for v in os.getloadavg()]


def now() -> str:
    return datetime.datetime.now().astimezone().isoformat(timespec="seconds")


def render_seed(k: int, sampler_index: int, spp_index: int) -> int:
    return 1 + 1000 * k + 100 * sampler_index + spp_index


def correction_sd(name: str) -> float:
    """How far the reference's realized squared error may stray from the variance ``relmse``
    subtracts, on the relMSE scale (one standard deviation, Gaussian pixel errors, the three
    channels of a pixel fully correlated): sqrt(2 sum_p (sum_c Var(R) / (R^2 + 0.01))^2) / N.
    One reference serves all renders, so this error is shared by every value of the scene."""
    import tracer
    from tracer.study import metrics

    ref = tracer.read_image(ROOT / "renders" / "references" / f"{name}.exr")
    t = ref.variance_of_mean / (ref.mean**2 + metrics.RELMSE_EPSILON)
    return float(math.sqrt(2.0 * float(np.sum(t.sum(axis=-1) ** 2))) / t.size)


# --------------------------------------------------------------------------------------- measuring


def measure(args) -> dict:
    import tracer
    from tracer.study import metrics

    spps = [2**e for e in range(2, int(math.log2(args.spp_max)) + 1)]
    samplers = args.samplers.split(",")
    names = args.scenes.split(",")
    results = {"machine": machine(), "date": now(), "load_at_start": load_average(),
               "command": " ".join([Path(sys.executable).name] + sys.argv), "strategy": "mis", "size": SIZE,
               "threads": args.threads, "spps": spps, "seeds": args.seeds, "fit_min": args.fit_min,
               "samplers": samplers, "scenes": {}, "warmup": [], "complete": False}
    scenes, references = {}, {}
    all_seeds = {render_seed(k, i, j) for k in range(args.seeds) for i in range(len(samplers))
                 for j in range(len(spps))}
    for name in names:
        scenes[name] = tracer.load_scene(ROOT / "scenes" / f"{name}.toml", width=SIZE, height=SIZE)
        ref = references[name] = tracer.read_image(ROOT / "renders" / "references" / f"{name}.exr")
        held = {s for s, _, _ in ref.film.record.samples or ((0, 0, 0),)}
        if all_seeds & held:
            raise SystemExit(f"the reference of {name} holds seeds {sorted(all_seeds & held)}: renders "
                             "would share its random numbers")
        results["scenes"][name] = {
            "reference": {"spp": ref.spp, "sampler": ref.film.record.sampler, "seeds": sorted(held),
                          "relmse_of_its_noise": metrics.reference_relmse(ref.mean, ref.variance_of_mean),
                          "correction_sd": correction_sd(name)},
            "renders": []}
    # Warm-up: compile (or load) every sampler's kernels on every scene; untimed, excluded.
    for name in names:
        for sampler in samplers:
            start = time.perf_counter()
            tracer.render(scenes[name], "mis", spp=1, seed=999_999, sampler=sampler, threads=args.threads)
            seconds = time.perf_counter() - start
            results["warmup"].append({"scene": name, "sampler": sampler, "seconds_with_compile": seconds})
            print(f"warm-up {name} {sampler}: {seconds:.1f} s", file=sys.stderr, flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for k in range(args.seeds):
        for name in names:
            ref = references[name]
            weight = ref.mean**2 + metrics.RELMSE_EPSILON
            for j, spp in enumerate(spps):
                shift = (k + j) % len(samplers)
                for sampler in samplers[shift:] + samplers[:shift]:
                    seed = render_seed(k, samplers.index(sampler), j)
                    cpu = time.process_time()
                    image = tracer.render(scenes[name], "mis", spp=spp, seed=seed, sampler=sampler,
                                          threads=args.threads)
                    cpu = time.process_time() - cpu
                    measures = tracer.compare(image, ref)
                    row = {"k": k, "sampler": sampler, "spp": spp, "seed": seed, "seconds": image.seconds,
                           "cpu_seconds": cpu, "relmse": measures["relmse"],
                           "relmse_uncorrected": measures["relmse_uncorrected"],
                           "relmse_predicted": float(np.mean(image.variance_of_mean / weight)),
                           "nonfinite": image.nonfinite, "finished": time.time()}
                    results["scenes"][name]["renders"].append(row)
                    print(f"k={k} {name} {sampler:11s} spp {spp:5d}: relMSE {row['relmse']:.4g} "
                          f"(predicted {row['relmse_predicted']:.4g}) in {image.seconds:.2f} s",
                          file=sys.stderr, flush=True)
        results["load_after_seed"] = results.get("load_after_seed", []) + [load_average()]
        (out / "samplers.json").write_text(json.dumps(results, indent=1) + "\n")  # partial, in case of a stop
    results["load_at_end"] = load_average()
    results["date_end"] = now()
    results["complete"] = True
    return results


# --------------------------------------------------------------------------------------- analysing


def t_quantile(df: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, df)) if df >= 1 else NAN


def mean_interval(values) -> dict:
    """Mean with its 95% t-interval."""
    v = np.asarray(values, dtype=float)
    n = len(v)
    m = float(v.mean()) if n else NAN
    half = t_quantile(n - 1) * float(v.std(ddof=1)) / math.sqrt(n) if n > 1 else NAN
    return {"mean": m, "lo": m - half, "hi": m + half, "n": n}


def ratio_of_means(a, b, t_a=None, t_b=None, rng=None) -> dict:
    """mean(a) / mean(b), times mean(t_a) / mean(t_b) if those are given, with a delta-method
    interval on the log (t, n - 1 d.o.f.) and, given ``rng``, a percentile bootstrap in which
    each array is resampled on its own (independent renders)."""
    parts = [(np.asarray(a, float), 1), (np.asarray(b, float), -1)]
    if t_a is not None:
        parts += [(np.asarray(t_a, float), 1), (np.asarray(t_b, float), -1)]
    value = math.exp(sum(sign * math.log(x.mean()) for x, sign in parts))
    var = sum(x.var(ddof=1) / (len(x) * x.mean() ** 2) for x, _ in parts)
    half = t_quantile(min(len(x) for x, _ in parts) - 1) * math.sqrt(var)
    out = {"value": value, "lo": value * math.exp(-half), "hi": value * math.exp(half),
           "log_se": math.sqrt(var)}
    if rng is not None:
        logs = np.zeros(BOOTSTRAP)
        for x, sign in parts:
            logs += sign * np.log(x[rng.integers(0, len(x), size=(BOOTSTRAP, len(x)))].mean(axis=1))
        lo, hi = np.exp(np.percentile(logs, [2.5, 97.5]))
        out["bootstrap_lo"], out["bootstrap_hi"] = float(lo), float(hi)
    return out


def per_seed_slopes(rows, sampler, seeds, fit_spps, key) -> tuple[list[float], int]:
    """Slope of log rows[key] on log spp per seed over ``fit_spps``; values <= 0 are left out
    (and counted)."""
    slopes, dropped = [], 0
    for k in seeds:
        pts = [(r["spp"], r[key]) for r in rows
               if r["sampler"] == sampler and r["k"] == k and r["spp"] in fit_spps]
        good = [(x, y) for x, y in pts if y > 0]
        dropped += len(pts) - len(good)
        if len(good) >= 2:
            slopes.append(float(np.polyfit(np.log([x for x, _ in good]), np.log([y for _, y in good]), 1)[0]))
    return slopes, dropped


def analyse_scene(results: dict, rows: list[dict], rng) -> dict:
    spps, samplers = results["spps"], results["samplers"]
    fit_spps = [s for s in spps if s >= results["fit_min"]]
    seeds = sorted({r["k"] for r in rows})

    def get(sampler, spp, key="relmse"):
        return np.array([r[key] for r in rows if r["sampler"] == sampler and r["spp"] == spp])

    s = {"curves": {}, "slopes": {}, "ratio_64": {}, "cost_per_sample": {}, "cost_ratio": {},
         "efficiency_ratio": {}, "efficiency_ratio_render_seconds": {}, "equal_time_relmse_ratio": {},
         "dropped_nonpositive": 0}
    for sampler in samplers:
        curve = []
        for spp in spps:
            rel = get(sampler, spp)
            logs = np.log(rel[rel > 0])
            sem_log = float(logs.std(ddof=1) / math.sqrt(len(logs))) if len(logs) > 1 else None
            curve.append({"spp": spp, "mean": float(rel.mean()), "min": float(rel.min()),
                          "max": float(rel.max()), "sem_log": sem_log,
                          "predicted_over_measured": float(get(sampler, spp, "relmse_predicted").mean()
                                                           / rel.mean()),
                          "seconds": float(get(sampler, spp, "seconds").mean()), "n": int(len(rel))})
        s["curves"][sampler] = curve
        per_seed, dropped = per_seed_slopes(rows, sampler, seeds, fit_spps, "relmse")
        s["dropped_nonpositive"] += dropped
        slope = mean_interval(per_seed)
        slope["per_seed"] = per_seed
        predicted, _ = per_seed_slopes(rows, sampler, seeds, fit_spps, "relmse_predicted")
        slope["predicted"] = mean_interval(predicted) if len(predicted) > 1 else None
        means = [c["mean"] for c in curve if c["spp"] in fit_spps]
        slope["of_mean_curve"] = float(np.polyfit(np.log(fit_spps), np.log(means), 1)[0]) \
            if len(means) > 1 and all(m > 0 for m in means) else NAN
        s["slopes"][sampler] = slope
        # seconds per spp, pooled per seed over the renders of TIMING_MIN_SPP spp and more, per clock
        s["cost_per_sample"][sampler] = {}
        for clock, key in CLOCKS.items():
            cost = []
            for k in seeds:
                sel = [r for r in rows
                       if r["sampler"] == sampler and r["k"] == k and r["spp"] >= TIMING_MIN_SPP]
                if sel and all(key in r for r in sel):
                    cost.append(sum(r[key] for r in sel) / sum(r["spp"] for r in sel))
            if cost and len(cost) == len(seeds):
                s["cost_per_sample"][sampler][clock] = {"per_seed": cost, "mean": float(np.mean(cost))}
    for clock in CLOCKS:
        s["cost_ratio"][clock] = {}
        if clock not in s["cost_per_sample"][BASE]:
            continue
        base_cost = np.array(s["cost_per_sample"][BASE][clock]["per_seed"])
        for sampler in samplers:
            if sampler == BASE:
                s["cost_ratio"][clock][sampler] = {"value": 1.0, "lo": 1.0, "hi": 1.0, "log_se": 0.0}
                continue
            logs = np.log(np.array(s["cost_per_sample"][sampler][clock]["per_seed"]) / base_cost)
            mi = mean_interval(logs)
            s["cost_ratio"][clock][sampler] = {
                "value": math.exp(mi["mean"]), "lo": math.exp(mi["lo"]), "hi": math.exp(mi["hi"]),
                "log_se": float(logs.std(ddof=1) / math.sqrt(len(logs))) if len(logs) > 1 else NAN,
                "per_seed": [float(math.exp(v)) for v in logs]}
    for sampler in samplers:
        if sampler == BASE:
            continue
        if RATIO_SPP in spps:
            s["ratio_64"][sampler] = ratio_of_means(get(sampler, RATIO_SPP), get(BASE, RATIO_SPP), rng=rng)
        eff, eff_render, equal = {}, {}, {}
        cost = s["cost_ratio"]["wall"][sampler]
        for spp in (e for e in EFFICIENCY_SPP if e in spps):
            # efficiency ratio = (rel_base / rel_sampler) / (cost_sampler / cost_base): relMSE means over
            # seeds, cost per sample pooled and paired by seed; the intervals combined on the log scale
            rel = ratio_of_means(get(BASE, spp), get(sampler, spp))
            value = rel["value"] / cost["value"]
            half = t_quantile(len(seeds) - 1) * math.sqrt(rel["log_se"] ** 2 + cost["log_se"] ** 2)
            eff[str(spp)] = {"value": value, "lo": value * math.exp(-half), "hi": value * math.exp(half)}
            # the same from the seconds of the renders at this spp alone (unpaired; noisier)
            eff_render[str(spp)] = ratio_of_means(get(BASE, spp), get(sampler, spp),
                                                  get(BASE, spp, "seconds"), get(sampler, spp, "seconds"))
            # relMSE of `sampler` in the time BASE takes for spp, interpolated (log-log) on its mean curve
            matched = spp / cost["value"]
            xs = np.log([c["spp"] for c in s["curves"][sampler]])
            ys = np.log([max(c["mean"], 1e-300) for c in s["curves"][sampler]])
            at = math.exp(float(np.interp(math.log(matched), xs, ys)))
            equal[str(spp)] = {"spp_in_same_time": matched, "relmse": at, "ratio": at / get(BASE, spp).mean()}
        s["efficiency_ratio"][sampler] = eff
        s["efficiency_ratio_render_seconds"][sampler] = eff_render
        s["equal_time_relmse_ratio"][sampler] = equal
    return s


def analyse(results: dict) -> dict:
    rng = np.random.default_rng(2024)
    summary = {}
    for name, data in results["scenes"].items():
        if "correction_sd" not in data["reference"]:
            data["reference"]["correction_sd"] = correction_sd(name)
        summary[name] = analyse_scene(results, data["renders"], rng)
    return summary


# --------------------------------------------------------------------------------------- reporting


def verdict(ratio: dict, target: float, below: bool) -> str:
    lo, hi, v = ratio["lo"], ratio["hi"], ratio["value"]
    if below:
        if hi <= target:
            return "met (whole interval below the target)"
        if v <= target:
            return "met at the point estimate, but the interval reaches above the target"
        if lo > target:
            return "missed (whole interval above the target)"
        return "missed at the point estimate (the interval reaches below the target)"
    if lo > target:
        return "met (whole interval above the target)"
    if v > target:
        return "met at the point estimate, but the interval reaches below the target"
    if hi < target:
        return "missed (whole interval below the target)"
    return "missed at the point estimate (the interval reaches above the target)"


def fmt_iv(d: dict, digits: int = 2) -> str:
    return f"{d['value']:.{digits}f} [{d['lo']:.{digits}f}, {d['hi']:.{digits}f}]"


def scene_tables(results: dict, name: str, s: dict) -> list[str]:
    samplers, spps = results["samplers"], results["spps"]
    ref = results["scenes"][name]["reference"]
    lines = [f"## {name}", "",
             f"The reference's own noise on the relMSE scale (subtracted from every value): "
             f"{ref['relmse_of_its_noise']:.3g}; how far its realized error may stray from that (1 sd, "
             f"Gaussian approximation, shared by every value below): {ref['correction_sd']:.2g}.", "",
             "relMSE, mean over seeds (min .. max):", "",
             "| spp | " + " | ".join(samplers) + " |", "|---|" + "---|" * len(samplers)]
    for i, spp in enumerate(spps):
        cells = [f"{c['mean']:.3g} ({c['min']:.3g} .. {c['max']:.3g})"
                 for c in (s["curves"][sampler][i] for sampler in samplers)]
        lines.append(f"| {spp} | " + " | ".join(cells) + " |")
    last = spps[-1]
    lines += ["", f"Convergence (slopes of log relMSE on log spp over spp {results['fit_min']} .. {last}):",
              "",
              "| sampler | slope: mean of per-seed fits [95% t] | slope of the mean curve "
              "| slope of the film's predicted relMSE (reference-free check) "
              f"| film's predicted / measured relMSE at 64, {last} spp |", "|---|---|---|---|---|"]
    for sampler in samplers:
        sl, pr = s["slopes"][sampler], s["slopes"][sampler].get("predicted")
        pm = {c["spp"]: c["predicted_over_measured"] for c in s["curves"][sampler]}
        lines.append(f"| {sampler} | {sl['mean']:.3f} [{sl['lo']:.3f}, {sl['hi']:.3f}] "
                     f"| {sl['of_mean_curve']:.3f} | "
                     + (f"{pr['mean']:.3f} [{pr['lo']:.3f}, {pr['hi']:.3f}]" if pr else "n/a")
                     + f" | {pm.get(64, NAN):.2f}, {pm.get(last, NAN):.2f} |")
    has_cpu = bool(s["cost_ratio"].get("cpu"))
    lines += ["", "Ratios to independent (95% intervals: delta method on the log, t with n - 1 d.o.f.; for "
              "the relMSE ratio also a percentile bootstrap, second):", "",
              "| sampler | relMSE at 64 spp | ms per spp, wall (256x256) | cost per sample, wall "
              + ("| cost per sample, CPU " if has_cpu else "")
              + "".join(f"| efficiency at {e} spp " for e in EFFICIENCY_SPP)
              + "".join(f"| relMSE at equal time ({e} spp of independent's time) " for e in EFFICIENCY_SPP)
              + "|",
              "|---|---|---|---|" + ("---|" if has_cpu else "") + "---|" * (2 * len(EFFICIENCY_SPP))]
    for sampler in samplers:
        wall = s["cost_per_sample"][sampler]["wall"]["mean"]
        row = [sampler]
        if sampler == BASE:
            row += ["1", f"{1000 * wall:.1f}", "1"] + (["1"] if has_cpu else [])
            row += ["1"] * (2 * len(EFFICIENCY_SPP))
        else:
            r = s["ratio_64"].get(sampler)
            row += [f"{fmt_iv(r, 3)}, [{r['bootstrap_lo']:.3f}, {r['bootstrap_hi']:.3f}]" if r else "n/a",
                    f"{1000 * wall:.1f}", fmt_iv(s["cost_ratio"]["wall"][sampler])]
            if has_cpu:
                row.append(fmt_iv(s["cost_ratio"]["cpu"][sampler]))
            eff, eq = s["efficiency_ratio"][sampler], s["equal_time_relmse_ratio"][sampler]
            row += [fmt_iv(eff[str(e)]) if str(e) in eff else "n/a" for e in EFFICIENCY_SPP]
            row += [f"{eq[str(e)]['ratio']:.3f} (at {eq[str(e)]['spp_in_same_time']:.0f} spp)"
                    if str(e) in eq else "n/a" for e in EFFICIENCY_SPP]
        lines.append("| " + " | ".join(row) + " |")
    if s["dropped_nonpositive"]:
        lines += ["", f"{s['dropped_nonpositive']} relMSE values at or below 0 (below what the reference "
                  "resolves) were left out of the slope fits."]
    return lines + [""]


def markdown(results: dict, summary: dict) -> str:
    m, n = results["machine"], results["seeds"]
    dirty = " with uncommitted changes under tracer/" if m["tracer_dirty"] else ""
    lines = [
        "# Samplers: independent, stratified, sobol (`mis`, default options)", "",
        f"Machine: {m['nproc']} cores, {m['cpu']}; Python {m['python']}; tracer at {m['commit']}{dirty}. "
        f"Date: {results['date']} to {results.get('date_end', '?')}. Load average (1, 5, 15 min) at "
        f"start {results['load_at_start']}, at end {results.get('load_at_end')}; after each seed "
        f"{results.get('load_after_seed')}.", "",
        f"Command: `{results['command']}`. Run time {results.get('run_seconds', NAN) / 60:.1f} min.", ""]
    if results.get("notes"):
        lines += [f"- {note}" for note in results["notes"]] + [""]
    lines += [
        f"{results['size']}x{results['size']}, {results['threads']} threads, spp {results['spps'][0]} .. "
        f"{results['spps'][-1]} (powers of two), {n} seeds: every point is {n} independent fresh renders per "
        "sampler (no render continues another; each has its own seed). relMSE is against "
        "`renders/references/SCENE.exr` (1024-spp `independent`, seed 0) less the reference's own noise "
        "(`tracer.compare`). Intervals are 95%. Figure: `renders/samplers_convergence.png`.", ""]
    for name, s in summary.items():
        lines += scene_tables(results, name, s)
    lines += ["## Targets", ""]
    scene, sampler, target = TARGETS["ratio_64"]
    if scene in summary and sampler in summary[scene]["ratio_64"]:
        r = summary[scene]["ratio_64"][sampler]
        lines.append(f"- {sampler} relMSE <= {target}x independent's at 64 spp on {scene}: {fmt_iv(r, 3)} "
                     f"-> {verdict(r, target, below=True)}.")
    scene, sampler, target = TARGETS["equal_time"]
    for e, r in summary.get(scene, {}).get("efficiency_ratio", {}).get(sampler, {}).items():
        lines.append(f"- {sampler} better than independent at equal time on {scene}, at {e} spp: "
                     f"efficiency ratio {fmt_iv(r)} -> {verdict(r, target, below=False)}.")
    lines += [
        "", "## How the numbers are made", "",
        f"- Slopes: least squares of log relMSE on log spp over spp {results['fit_min']} .. "
        f"{results['spps'][-1]} per seed, then the mean of the {n} per-seed slopes and its t-interval "
        f"({n - 1} degrees of freedom). From 16 because with 8 replicates per pixel the stratified and "
        "Sobol samplers hold at most one point per replicate at 4 and 8 spp, i.e. they are plain random "
        "sampling there. All spp are powers of two (a power of two per replicate at 16+), the best case "
        "for Sobol nets; stratified's grid per replicate is square at 32, 128 and 512 spp only.",
        "- Ratio at 64 spp: ratio of the means over seeds; interval by the delta method on its log (t, "
        f"{n - 1} d.o.f.) and by a percentile bootstrap over seeds (each sampler's seeds resampled apart).",
        f"- Cost per sample: seconds / spp over the renders of {TIMING_MIN_SPP}+ spp, per seed, as a ratio "
        "to independent's of the same seed (the three samplers of one seed and spp render back to back, "
        "their order rotated from point to point); geometric mean and t-interval of the per-seed ratios. "
        "Wall: the render loop's clock (`Image.seconds`, after the kernels are compiled; each sampler "
        "first rendered each scene once at 1 spp, untimed). CPU: the process's CPU time around "
        "`tracer.render` (both threads; it also holds the estimator's set-up), which other processes on "
        "the machine disturb less than the wall clock.",
        "- Efficiency 1 / (relMSE x seconds) at 64 and 256 spp, as a ratio to independent's: (ratio of the "
        "mean relMSE) / (wall-clock cost-per-sample ratio), the two intervals combined on the log scale. "
        "Seconds from the pooled, seed-paired cost rather than from the few renders at that spp alone, "
        "whose times the machine's other load scatters (that version is in the JSON, "
        "`efficiency_ratio_render_seconds`). The equal-time relMSE ratio reads the sampler's mean curve "
        "(log-log interpolation between the measured powers of two) at the spp it renders in "
        "independent's time (spp / cost ratio).",
        "- Predicted / measured: the relMSE the film's own variance predicts (mean of variance of the "
        "pixel value / (R^2 + 0.01)) over the measured one; near 1 when the variance is honest (and the "
        "reference's correction accurate).", ""]
    return "\n".join(lines)


def figure(results: dict, summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"independent": "tab:blue", "stratified": "tab:orange", "sobol": "tab:green"}
    names = list(summary)
    spps = results["spps"]
    fig, axes = plt.subplots(1, len(names), figsize=(6.2 * len(names), 5.2), squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        s = summary[name]
        for sampler in results["samplers"]:
            c, sl, colour = s["curves"][sampler], s["slopes"][sampler], colours.get(sampler)
            x = [p["spp"] for p in c]
            ax.plot(x, [p["mean"] for p in c], "o-", color=colour, ms=4,
                    label=f"{sampler}: slope {sl['mean']:.2f} [{sl['lo']:.2f}, {sl['hi']:.2f}]")
            ax.fill_between(x, [max(p["min"], 1e-12) for p in c], [p["max"] for p in c], color=colour,
                            alpha=0.2, lw=0)
        x0, y0 = s["curves"][BASE][0]["spp"], s["curves"][BASE][0]["mean"]
        xs = np.array([x0, spps[-1]], float)
        ax.plot(xs, y0 * (xs / x0) ** -1.0, ":", color="grey", lw=1, label="slope -1 (guide)")
        noise = results["scenes"][name]["reference"]["relmse_of_its_noise"]
        ax.axhline(noise, color="black", ls="--", lw=0.8,
                   label=f"reference's own noise ({noise:.2g}), subtracted")
        ax.axvspan(spps[0] / 1.2, results["fit_min"] / 1.2, color="grey", alpha=0.08, lw=0,
                   label="not in the slope fits")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xticks(spps)
        ax.set_xticklabels([str(v) for v in spps])
        ax.set_xlabel("samples per pixel")
        ax.set_ylabel("relMSE (mean over seeds; band: min .. max)")
        ax.set_title(f"{name}: mis, {results['size']}x{results['size']}, {results['seeds']} seeds "
                     f"(slopes fitted over {results['fit_min']}+ spp, 95% t-intervals)", fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="cornell,veach_mis")
    parser.add_argument("--samplers", default=",".join(SAMPLERS))
    parser.add_argument("--spp-max", type=int, default=1024)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--fit-min", type=int, default=16)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", default=str(HERE / "results"))
    parser.add_argument("--figure", default=str(ROOT / "renders" / "samplers_convergence.png"))
    parser.add_argument("--analyse", metavar="JSON", help="tables and figure from an earlier run's JSON")
    parser.add_argument("--note", action="append", default=[],
                        help="a line of notes for the .md (kept in the JSON; given, they replace the "
                        "JSON's); may be repeated")
    args = parser.parse_args()
    if args.analyse:
        results = json.loads(Path(args.analyse).read_text())
    else:
        if BASE not in args.samplers.split(","):
            parser.error(f"--samplers must include {BASE}: the ratios are to it")
        start = time.perf_counter()
        results = measure(args)
        results["run_seconds"] = time.perf_counter() - start
    if args.note:
        results["notes"] = args.note
    summary = analyse(results)
    results["summary"] = summary
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "samplers.json").write_text(json.dumps(results, indent=1) + "\n")
    text = markdown(results, summary)
    (out / "samplers.md").write_text(text)
    figure(results, summary, Path(args.figure))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
