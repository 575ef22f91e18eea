"""Comparison reports: images, error maps, the labelled grid, charts, tables and index.html.

Everything goes into one folder with relative links only, so the folder can be zipped, put on
a web page or opened from disk. Maps and charts are drawn with matplotlib (Agg: no display).
"""

from __future__ import annotations

import csv
import html
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import save_figure, write_text
from ..film import Film
from ..imagefiles import to_srgb8, write_exr, write_png
from . import metrics
from .compare import Run, fit_convergence, run_row, time_to_reach

RELERR_RANGE = (-5.0, 1.0)  # log10 of per-pixel relative squared error shown in the maps
RATIO_RANGE = 4.0  # log2 efficiency ratio shown from -4 to 4 (16x either way)
COLORS = {"uniform": "#8c8c8c", "cosine": "#b07aa1", "bsdf": "#4e79a7", "light": "#f28e2b", "mis": "#59a14f"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def run_name(run: Run) -> str:
    """A file-name-safe label: ``mis``, ``mis_l3_b1``, ``light_x4`` ..."""
    s = run.strategy
    if s.name == "mis" and (s.light_samples, s.bsdf_samples) != (1, 1):
        return f"mis_l{s.light_samples}_b{s.bsdf_samples}"
    count = s.light_count or s.direction_count
    return s.name if count == 1 else f"{s.name}_x{count}"


# ---------------------------------------------------------------------------------------------
# Per-strategy maps


def save_map(values: np.ndarray, path: Path, title: str, label: str, cmap: str = "magma",
             vmin: float | None = None, vmax: float | None = None) -> None:
    """A false-colour map of ``values (H, W)`` with a title and a labelled colour bar."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(4.6, 3.8))
    im = ax.imshow(values, cmap=cmap, vmin=vmin, vmax=vmax)
    ax.set_title(title, fontsize=9)
    ax.axis("off")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label=label)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def relerr_map(run: Run, reference: Film, path: Path) -> None:
    """False-colour map of log10 relative squared error (channel mean), fixed range for all."""
    rel = metrics.relative_squared_error(run.film.image(), reference.image()).mean(axis=2)
    save_map(np.log10(rel + 1e-12), path, f"{run_name(run)}: relative squared error",
             "log10 (I-R)² / (R²+0.01)", vmin=RELERR_RANGE[0], vmax=RELERR_RANGE[1])


def flip_map(run: Run, reference: Film, path: Path) -> float:
    """The HDR-FLIP perceptual error map (OpenImageIO's built-in); returns the mean FLIP."""
    import OpenImageIO as oiio

    ref_buf = oiio.ImageBuf(np.ascontiguousarray(reference.image(), dtype=np.float32))
    test_buf = oiio.ImageBuf(np.ascontiguousarray(run.film.image(), dtype=np.float32))
    flip = oiio.ImageBufAlgo.FLIP_diff(ref_buf, test_buf).get_pixels(oiio.FLOAT)[..., 0]
    save_map(flip, path, f"{run_name(run)}: FLIP (mean {flip.mean():.3f})", "FLIP error", vmin=0.0, vmax=1.0)
    return float(flip.mean())


def ratio_map(a: Run, b: Run, reference: Film, path: Path) -> dict[str, float]:
    """Per-pixel log2 efficiency ratio of a over b; returns the share of pixels each wins."""
    ref = reference.image()
    err_a = (a.film.image() - ref) ** 2
    err_b = (b.film.image() - ref) ** 2
    ratio = metrics.efficiency_ratio_map(err_a, a.seconds, err_b, b.seconds)
    save_map(ratio, path, f"efficiency: {run_name(a)} (blue) vs {run_name(b)} (red)",
             f"log2 efficiency({run_name(a)}) / efficiency({run_name(b)})", cmap="RdBu",
             vmin=-RATIO_RANGE, vmax=RATIO_RANGE)
    lit = ratio != 0.0
    return {"a_wins": float(np.mean(ratio[lit] > 0.0)) if lit.any() else 0.0,
            "b_wins": float(np.mean(ratio[lit] < 0.0)) if lit.any() else 0.0}


# ---------------------------------------------------------------------------------------------
# The grid


def pick_insets(runs: list[Run], reference: Film, count: int = 2) -> list[tuple[int, int, int, int]]:
    """Windows (x, y, w, h) where the strategies' errors differ most: the spread over strategies
    of log10 of the locally averaged relative squared error, maximized over square windows of
    a sixth of the image, non-overlapping."""
    ref = reference.image()
    h, w = ref.shape[:2]
    size = min(max(8, min(w, h) // 6), w, h)  # at least 8 pixels, but never past the image
    logs = [np.log10(metrics.box_blur(metrics.relative_squared_error(r.film.image(), ref).mean(axis=2), 2)
                     + 1e-8) for r in runs]
    spread = np.std(np.stack(logs), axis=0) if len(logs) > 1 else logs[0]
    score = metrics.box_blur(spread, size // 2)
    windows = []
    for _ in range(count):
        y, x = np.unravel_index(int(np.argmax(score)), score.shape)
        x0 = int(np.clip(x - size // 2, 0, w - size))
        y0 = int(np.clip(y - size // 2, 0, h - size))
        windows.append((x0, y0, size, size))
        score[max(0, y0 - size):y0 + 2 * size, max(0, x0 - size):x0 + 2 * size] = -np.inf
    return windows


def _label(tile: np.ndarray, lines: list[str]) -> np.ndarray:
    """Write lines of text on a dark band at the top of an RGB float tile in [0, 1]."""
    import OpenImageIO as oiio

    size = max(10, min(14, tile.shape[1] // 18))
    band = (len(lines) * (size + 3) + 4)
    tile = tile.copy()
    tile[:band] *= 0.35
    buf = oiio.ImageBuf(np.ascontiguousarray(tile, dtype=np.float32))
    for i, text in enumerate(lines):
        oiio.ImageBufAlgo.render_text(buf, 4, (i + 1) * (size + 3), text, size, "", (1.0, 0.95, 0.5))
    return buf.get_pixels(oiio.FLOAT)


def _outline(tile: np.ndarray, window: tuple[int, int, int, int], color=(1.0, 0.2, 0.2)) -> None:
    x, y, w, h = window
    c = np.asarray(color)
    tile[y, x:x + w] = c
    tile[y + h - 1, x:x + w] = c
    tile[y:y + h, x] = c
    tile[y:y + h, x + w - 1] = c


def grid_image(runs: list[Run], reference: Film, windows: list[tuple[int, int, int, int]],
               exposure: float, path: Path) -> None:
    """Reference and each run side by side, labelled, with zoomed insets below each tile."""
    tiles = []
    columns = [("reference", reference, [f"reference {reference.spp} spp"])] + [
        (run_name(r), r.film, [run_name(r), f"{r.spp} spp  {r.seconds:.2f} s",
                               f"relMSE {r.measures['relmse']:.3g}"]) for r in runs]
    width = reference.width
    for name, film, lines in columns:
        image = to_srgb8(film.image(), exposure).astype(np.float32) / 255.0
        main = image.copy()
        if name == "reference":
            for window in windows:
                _outline(main, window)
        parts = [_label(main, lines)]
        for x, y, w, h in windows:
            crop = image[y:y + h, x:x + w]
            zoom = max(1, width // w)
            inset = np.repeat(np.repeat(crop, zoom, axis=0), zoom, axis=1)
            pad = np.zeros((inset.shape[0], width, 3), dtype=np.float32)
            pad[:, :min(width, inset.shape[1])] = inset[:, :width]
            parts.append(np.full((3, width, 3), 1.0, dtype=np.float32))
            parts.append(pad)
        tiles.append(np.concatenate(parts, axis=0))
        tiles.append(np.ones((tiles[-1].shape[0], 3, 3), dtype=np.float32))
    write_png(path, np.concatenate(tiles[:-1], axis=1), srgb=True)


# ---------------------------------------------------------------------------------------------
# Charts


def convergence_chart(sweep: list[dict[str, Any]], target: float, path: Path) -> None:
    """relMSE against seconds and against spp, log-log, with fitted slopes in the legend.
    Points whose corrected relMSE is not positive (below the reference's noise, or an exactly
    black image) cannot sit on a log axis and are left out."""
    plt = _pyplot()
    fig, (ax_t, ax_s) = plt.subplots(1, 2, figsize=(11, 4.3))
    for name in dict.fromkeys(p["strategy"] for p in sweep):
        pts = [p for p in sweep if p["strategy"] == name and p["relmse"] > 0.0]
        color = COLORS.get(name)
        slope_t, _ = fit_convergence(pts, "seconds")
        slope_s, _ = fit_convergence(pts, "spp")
        ax_t.loglog([p["seconds"] for p in pts], [p["relmse"] for p in pts], "o-", color=color,
                    label=f"{name} (slope {slope_t:.2f})", ms=3)
        ax_s.loglog([p["spp"] for p in pts], [p["relmse"] for p in pts], "o-", color=color,
                    label=f"{name} (slope {slope_s:.2f})", ms=3)
    for ax, xlabel in ((ax_t, "seconds"), (ax_s, "samples per pixel")):
        ax.axhline(target, color="k", lw=0.7, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("relMSE")
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
        ax.legend(fontsize=8)
    ax_t.set_title(f"error against time (dashed: target relMSE {target:g})", fontsize=10)
    ax_s.set_title("error against samples (Monte Carlo: slope -1)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def allocation_chart(rows: list[dict[str, Any]], path: Path) -> None:
    """Efficiency of MIS for each light:BSDF sample allocation."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    labels = [f"{r['light_samples']}:{r['bsdf_samples']}" for r in rows]
    ax.bar(labels, [r["efficiency"] for r in rows], color="#59a14f")
    ax.set_xlabel("light : BSDF samples per camera sample")
    ax.set_ylabel("efficiency = 1 / (relMSE × seconds)")
    ax.set_yscale("log")
    ax.set_title("MIS sample allocation", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Tables and the page


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float (an undefined efficiency, a time to target never
    reached) replaced by None, so that it is valid JSON (null), not NaN or Infinity."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def number(value: Any, spec: str = ".4g") -> str:
    """A measure for a table: formatted, or ``n/a`` when it is missing or not finite."""
    if value is None or isinstance(value, float) and not np.isfinite(value):
        return "n/a"
    return format(value, spec)


def write_tables(out: Path, document: dict[str, Any]) -> None:
    """metrics.json (the whole document, strict JSON: undefined numbers are null) and
    metrics.csv (the results table; undefined numbers are empty cells)."""
    safe = json_safe(document)
    write_text(out / "metrics.json", json.dumps(safe, indent=2, allow_nan=False) + "\n")
    columns = ["strategy", "heuristic", "light_samples", "bsdf_samples", "spp", "seconds", "budget",
               "mse", "relmse", "variance", "efficiency", "flip", "mse_uncorrected", "relmse_uncorrected"]
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(safe["results"])
    write_text(out / "metrics.csv", table.getvalue())


def write_index(out: Path, document: dict[str, Any], images: dict[str, list[str]]) -> None:
    """A static page with the grid, maps, charts and table; relative links only."""
    esc = html.escape
    rows = []
    for r in document["results"]:
        budget = f" of {r['budget']:.2f}" if "budget" in r else ""
        rows.append(
            f"<tr><td>{esc(r['name'])}</td><td>{r['spp']}</td><td>{r['seconds']:.2f}{budget}</td>"
            f"<td>{number(r['mse'])}</td><td>{number(r['relmse'])}</td><td>{number(r['variance'])}</td>"
            f"<td>{number(r['efficiency'])}</td><td>{number(r.get('flip'), '.3f')}</td></tr>")
    sections = []
    for title, files in images.items():
        figures = "".join(f'<a href="{esc(f)}"><img src="{esc(f)}" alt="{esc(f)}"></a>' for f in files)
        sections.append(f"<h2>{esc(title)}</h2><div class=row>{figures}</div>")
    mode = document["mode"]
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<title>tracer compare: {esc(document['scene'])}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; background: #fafafa; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }}
td:first-child, th:first-child {{ text-align: left; }}
.row img {{ max-width: 100%; margin: 0.3em; vertical-align: top; image-rendering: pixelated; }}
</style></head><body>
<h1>{esc(document['scene'])}: sampling strategies compared</h1>
<p>Mode: <b>{esc(mode['kind'])}</b> ({esc(mode['description'])}). Reference:
<code>{esc(document['reference'])}</code> ({document['reference_spp']} spp,
{esc(str(document['reference_strategy']))}).
relMSE = mean (I&minus;R)&sup2;/(R&sup2;+0.01) and MSE = mean (I&minus;R)&sup2;, each less the
reference's own variance (its noise, relMSE {number(document['reference_noise']['relmse'])}, which
adds to every measured error; <code>*_uncorrected</code> in the data are as measured; the error maps
are uncorrected); efficiency = 1/(relMSE &times; seconds), n/a where relMSE is not positive.
Data: <a href="metrics.json">metrics.json</a>, <a href="metrics.csv">metrics.csv</a>.</p>
<table><tr><th>strategy</th><th>spp</th><th>seconds</th><th>MSE</th><th>relMSE</th>
<th>variance</th><th>efficiency</th><th>FLIP</th></tr>
{''.join(rows)}
</table>
{''.join(sections)}
</body></html>
"""
    write_text(out / "index.html", page)


def describe_mode(spp: int | None, budget: float | None) -> dict[str, Any]:
    if budget is not None:
        return {"kind": "equal-time", "seconds": budget,
                "description": f"every strategy renders for {budget:g} s"}
    return {"kind": "equal-spp", "spp": spp, "description": f"every strategy renders {spp} spp"}


def result_row(run: Run, flip: float) -> dict[str, Any]:
    row = run_row(run)
    row["name"] = run_name(run)
    row["flip"] = flip
    return row


def efficiency_pairs(runs: list[Run]) -> list[tuple[Run, Run]]:
    """The strategy pairs whose ratio map is most telling: light vs BSDF (where each wins),
    then MIS against each of them."""
    by_name = {r.strategy.name: r for r in runs}
    pairs = [("bsdf", "light"), ("mis", "light"), ("mis", "bsdf")]
    return [(by_name[a], by_name[b]) for a, b in pairs if a in by_name and b in by_name]


def time_to_target_rows(sweep: list[dict[str, Any]], target: float) -> list[dict[str, Any]]:
    rows = []
    for name in dict.fromkeys(p["strategy"] for p in sweep):
        pts = [p for p in sweep if p["strategy"] == name]
        seconds, extrapolated = time_to_reach(pts, target)
        slope, _ = fit_convergence(pts, "spp")
        rows.append({"strategy": name, "target_relmse": target, "seconds_to_target": seconds,
                     "extrapolated": extrapolated, "slope_per_spp": slope})
    return rows


def make_report(out: Path, scene_name: str, reference_path: str, reference: Film, runs: list[Run],
                mode: dict[str, Any], sweep: list[dict[str, Any]], allocation: list[Run],
                crops: list[tuple[int, int, int, int]] | None, exposure: float,
                target: float) -> dict[str, Any]:
    """Write every file of a comparison into ``out`` and return the metrics document."""
    out.mkdir(parents=True, exist_ok=True)
    images: dict[str, list[str]] = {}
    windows = crops or pick_insets(runs, reference)
    grid_image(runs, reference, windows, exposure, out / "grid.png")
    images["Side by side (insets: where the strategies differ most)"] = ["grid.png"]

    results, relerr_files, flip_files = [], [], []
    for run in runs:
        name = run_name(run)
        write_exr(out / f"{name}.exr", run.film)  # the header carries the record render() set
        write_png(out / f"{name}.png", run.film.image(), exposure)
        relerr_map(run, reference, out / f"{name}_relerr.png")
        flip = flip_map(run, reference, out / f"{name}_flip.png")
        relerr_files.append(f"{name}_relerr.png")
        flip_files.append(f"{name}_flip.png")
        results.append(result_row(run, flip))
    images["Relative squared error"] = relerr_files
    images["FLIP perceptual error"] = flip_files

    wins = []
    ratio_files = []
    for a, b in efficiency_pairs(runs):
        file = f"efficiency_{run_name(a)}_vs_{run_name(b)}.png"
        share = ratio_map(a, b, reference, out / file)
        ratio_files.append(file)
        wins.append({"a": run_name(a), "b": run_name(b), "share_a_wins": share["a_wins"],
                     "share_b_wins": share["b_wins"]})
    if ratio_files:
        images["Per-pixel efficiency ratio (where each strategy wins)"] = ratio_files

    reference_variance = reference.variance_of_mean()
    document: dict[str, Any] = {
        "scene": scene_name, "reference": reference_path, "reference_spp": reference.spp,
        "reference_strategy": reference.record.strategy,
        "reference_noise": {
            "relmse": metrics.reference_relmse(reference.mean, reference_variance),
            "mse": float(np.mean(reference_variance)),
            "correction": "mse and relmse have the reference's per-pixel variance subtracted "
                          "(unbiased for the image's own error); *_uncorrected are as measured"},
        "mode": mode, "results": results, "sweep": sweep, "efficiency_ratio": wins}
    if sweep:
        convergence_chart(sweep, target, out / "convergence.png")
        document["time_to_target"] = time_to_target_rows(sweep, target)
        images["Error against time and samples"] = ["convergence.png"]
    if allocation:
        rows = [run_row(r) for r in allocation]
        allocation_chart(rows, out / "allocation.png")
        document["allocation"] = rows
        images["MIS sample allocation (light : BSDF)"] = ["allocation.png"]
    write_tables(out, document)
    write_index(out, document, images)
    return document
