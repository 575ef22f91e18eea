"""Comparison reports: images, error maps, the labelled grid, charts, tables and index.html.

Everything goes into one folder with relative links only, so the folder can be zipped, put on
a web page or opened from disk. Maps and charts are drawn with matplotlib (Agg: no display) and
written as PNG at print resolution (``PRINT_DPI``), which the page shows, and, on request, also
as PDF and SVG (vector: text and lines stay sharp at any size; the maps' pixels are embedded).
"""

from __future__ import annotations

import csv
import html
import io
import json
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import save_figure, staged_folder, write_text
from ..film import Film
from ..imagefiles import to_srgb8, write_exr, write_png
from . import metrics, viewer
from .compare import (
    CONFIDENCE,
    EXTRAPOLATION_LIMIT,
    FIT_MIN_SPP,
    Run,
    convergence_rows,
    run_row,
    sweep_curves,
)
from .reference import Reference

RELERR_RANGE = (-5.0, 1.0)  # log10 of per-pixel relative squared error shown in the maps
RATIO_RANGE = 4.0  # log2 efficiency ratio shown from -4 to 4 (16x either way)
COLORS = {"uniform": "#8c8c8c", "cosine": "#b07aa1", "bsdf": "#4e79a7", "light": "#f28e2b", "mis": "#59a14f"}
# Curves of other methods (a light sampling, a sampler: mis_sobol ...) take these in turn.
MORE_COLORS = ("#e15759", "#76b7b2", "#edc948", "#ff9da7", "#9c755f", "#bab0ac", "#17becf", "#bcbd22")
# Every matplotlib figure is a PNG (the page shows it) and, as asked, a PDF and an SVG too.
FIGURE_FORMATS = ("png", "pdf", "svg")
PRINT_DPI = 300  # PNG figures at print resolution (a 5.5 inch chart is 1650 pixels wide)
# Why heavy-tailed estimators look slower than 1/spp in a sweep: said on the chart and the page.
HEAVY_TAIL_NOTE = (
    "An interval that excludes -1 (†) is the mark of a heavy-tailed estimator: its relMSE is dominated by "
    "rare, very large samples (a small light found by chance). Its expected relMSE still falls exactly as "
    "1/spp, but runs of few samples seldom draw those samples, so their measured error sits below the "
    "expectation and the curve falls slower until spp is large enough that every run draws its share.")
# Why stratified and Sobol points can beat 1/spp: said where a slope's interval lies below -1.
FAST_NOTE = (
    "An interval below -1 (‡) falls faster than 1/spp: stratified or quasi-Monte Carlo points, whose "
    "samples avoid each other (guide: Samplers); independent samples cannot, on average.")


def _slope_side(row: dict[str, Any]) -> str:
    """Where a slope's interval lies against -1: ``shallower``, ``steeper`` or ``""`` (it holds
    -1, or has no interval)."""
    if row["holds_minus_one"] is not False:
        return ""
    return "steeper" if row["slope_spp_high"] < -1.0 else "shallower"


def _slope_notes(slopes: list[dict[str, Any]]) -> list[str]:
    """The notes that the marks on these slopes call for."""
    sides = {_slope_side(r) for r in slopes}
    return [note for side, note in (("shallower", HEAVY_TAIL_NOTE), ("steeper", FAST_NOTE)) if side in sides]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def tight_layout(fig, rect: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)) -> None:
    """``fig.tight_layout(rect=rect)``, leaving the figure without a layout engine.

    ``Figure.tight_layout`` leaves a placeholder engine behind, and a figure that has one is
    drawn twice by ``savefig`` (once to lay it out, once to print), at the file's 300 dpi: the
    maps' image resampled twice. The same engine run once here lays the figure out the same
    way, and ``savefig`` then draws it once: about a third of each map's time."""
    from matplotlib.layout_engine import TightLayoutEngine

    TightLayoutEngine(rect=rect).execute(fig)


def run_name(run: Run) -> str:
    """A file-name-safe label: ``mis``, ``mis_l3_b1``, ``light_x4``, ``light_solid-angle``,
    ``mis_sobol`` ... (``compare.method_name``)."""
    return run.name


# ---------------------------------------------------------------------------------------------
# Per-strategy maps


def save_figures(fig, path: Path, formats: tuple[str, ...] = ("png",)) -> list[str]:
    """Write ``fig`` as ``path`` (a .png, at PRINT_DPI) and beside it in each other format of
    ``formats`` (``FIGURE_FORMATS``); close it. Returns the file names written, PNG first."""
    plt = _pyplot()
    names = []
    for fmt in dict.fromkeys(("png", *formats)):
        target = path.with_suffix(f".{fmt}")
        save_figure(fig, target, dpi=PRINT_DPI)
        names.append(target.name)
    plt.close(fig)
    return names


def save_map(values: np.ndarray, path: Path, title: str, label: str, cmap: str = "magma",
             vmin: float | None = None, vmax: float | None = None,
             formats: tuple[str, ...] = ("png",)) -> list[str]:
    """A false-colour map of ``values (H, W)`` with a title and a labelled colour bar; returns
    the files written (:func:`save_figures`)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(4.6, 3.8))
    im = ax.imshow(values, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.axis("off")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label=label)
    tight_layout(fig)
    return save_figures(fig, path, formats)


def learned_maps(run: Run, out: Path, formats: tuple[str, ...] = ("png",)) -> list[list[str]]:
    """Maps of what a render learned between passes (``tracer.tuning``): the share of light
    samples (adaptive allocation) and the control variate's coefficient, mean of RGB (optimal
    MIS); returns the files of each figure written (none for a render that learned nothing)."""
    name, film = run_name(run), run.film
    shape = (film.height, film.width)
    figures = []
    if "allocation.light" in film.learned:
        share = film.learned["allocation.light"].reshape(shape)
        figures.append(save_map(share, out / f"{name}_allocation.png",
                          f"{name}: share of light samples", "light / (light + BSDF)", cmap="coolwarm",
                          vmin=0.0, vmax=1.0, formats=formats))
    if "alpha.R" in film.learned:
        alpha = np.mean([film.learned[f"alpha.{c}"] for c in "RGB"], axis=0).reshape(shape)
        limit = float(np.quantile(np.abs(alpha), 0.99)) or 1.0
        figures.append(save_map(alpha, out / f"{name}_alpha.png", f"{name}: control-variate coefficient",
                                "a (mean of RGB)", cmap="PuOr", vmin=-limit, vmax=limit, formats=formats))
    return figures


def relerr_map(run: Run, reference: Film, path: Path, formats: tuple[str, ...] = ("png",)) -> list[str]:
    """False-colour map of log10 relative squared error (channel mean), fixed range for all."""
    rel = metrics.relative_squared_error(run.film.image(), reference.image()).mean(axis=2)
    return save_map(np.log10(rel + 1e-12), path, f"{run_name(run)}: relative squared error",
                    "log10 (I-R)² / (R²+0.01)", vmin=RELERR_RANGE[0], vmax=RELERR_RANGE[1], formats=formats)


def flip_map(run: Run, reference: Film, path: Path, formats: tuple[str, ...] = ("png",)) -> np.ndarray:
    """The HDR-FLIP perceptual error map (OpenImageIO's built-in); returns it, ``(H, W)``."""
    import OpenImageIO as oiio

    ref_buf = oiio.ImageBuf(np.ascontiguousarray(reference.image(), dtype=np.float32))
    test_buf = oiio.ImageBuf(np.ascontiguousarray(run.film.image(), dtype=np.float32))
    flip = oiio.ImageBufAlgo.FLIP_diff(ref_buf, test_buf).get_pixels(oiio.FLOAT)[..., 0]
    save_map(flip, path, f"{run_name(run)}: FLIP (mean {flip.mean():.3f})", "FLIP error", vmin=0.0, vmax=1.0,
             formats=formats)
    return flip


def ratio_map(a: Run, b: Run, reference: Film, path: Path,
              formats: tuple[str, ...] = ("png",)) -> dict[str, float]:
    """Per-pixel log2 efficiency ratio of a over b; returns the share of pixels each wins."""
    ref = reference.image()
    err_a = (a.film.image() - ref) ** 2
    err_b = (b.film.image() - ref) ** 2
    ratio = metrics.efficiency_ratio_map(err_a, a.seconds, err_b, b.seconds)
    save_map(ratio, path, f"efficiency: {run_name(a)} (blue) vs {run_name(b)} (red)",
             f"log2 efficiency({run_name(a)}) / efficiency({run_name(b)})", cmap="RdBu",
             vmin=-RATIO_RANGE, vmax=RATIO_RANGE, formats=formats)
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


def _text_size(width: int) -> int:
    """Label text height in pixels for tiles ``width`` pixels wide."""
    return max(10, min(14, width // 18))


def label_band(width: int, lines: list[str], rows: int) -> np.ndarray:
    """A dark band ``(h, width, 3)`` in [0, 1] with ``lines`` of text, tall enough for
    ``rows`` lines: it sits above its tile, so it hides none of the image (the reference's
    inset outlines included)."""
    import OpenImageIO as oiio

    size = _text_size(width)
    band = np.full((rows * (size + 3) + 4, width, 3), 0.12, dtype=np.float32)
    buf = oiio.ImageBuf(band)
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


def grid_image(runs: list[Run], reference: Film | Reference, windows: list[tuple[int, int, int, int]],
               exposure: float, path: Path) -> int:
    """Reference and each run side by side, each under a band of labels and above zoomed insets,
    the insets' windows outlined in red on the reference. Returns the band's height in pixels
    (the image of each column starts that far down)."""
    spp = "spp unknown" if reference.spp is None else f"{reference.spp} spp"
    columns = [("reference", reference, [f"reference {spp}"])] + [
        (run_name(r), r.film, [run_name(r), f"{r.spp} spp  {r.seconds:.2f} {_unit(r.clock)}",
                               f"relMSE {r.measures['relmse']:.3g}"]) for r in runs]
    width = reference.width
    rows = max(len(lines) for _, _, lines in columns)
    tiles = []
    band_height = 0
    for name, film, lines in columns:
        image = to_srgb8(film.image(), exposure).astype(np.float32) / 255.0
        main = image.copy()
        if name == "reference":
            for window in windows:
                _outline(main, window)
        band = label_band(width, lines, rows)
        band_height = band.shape[0]
        parts = [band, main]
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
    return band_height


def _unit(clock: str) -> str:
    """How seconds on ``clock`` are shown: ``s`` (wall) or ``CPU s``."""
    return "CPU s" if clock == "cpu" else "s"


# ---------------------------------------------------------------------------------------------
# Charts


def _interval(value: Any, low: Any, high: Any, spec: str) -> str:
    """``value [low, high]`` with ``spec``, the bounds left out where they are undefined."""
    if value is None or not np.isfinite(value):
        return "n/a"
    text = format(value, spec)
    if low is None or high is None or not (np.isfinite(low) and np.isfinite(high)):
        return text
    return f"{text} [{format(low, spec)}, {format(high, spec)}]"


def slope_text(row: dict[str, Any], ascii_only: bool = False) -> str:
    """A strategy's slope against spp with its interval, marked † (``*`` in ASCII) where that
    lies above -1 (a heavy-tailed estimator) and ‡ (``**``) where it lies below (faster than
    1/spp: stratified or QMC points)."""
    marks = {"shallower": " *" if ascii_only else " †", "steeper": " **" if ascii_only else " ‡", "": ""}
    return (_interval(row["slope_spp"], row["slope_spp_low"], row["slope_spp_high"], ".2f")
            + marks[_slope_side(row)])


def time_text(row: dict[str, Any], unit: str = "s", ascii_only: bool = False) -> str:
    """A time to target with its interval and how it was found (``n/a`` where there is none)."""
    if row["seconds"] is None:
        return "n/a"
    prefix = ("<= " if ascii_only else "≤ ") if row["how"] == "at most" else ""
    low, high = row["low"], row["high"]
    text = f"{prefix}{row['seconds']:.3g} {unit}"
    if low is not None and high is not None:
        infinite = "inf" if ascii_only else "∞"
        text += f" [{low:.3g}, {infinite if not np.isfinite(high) else format(high, '.3g')}]"
    return text + (" (extrapolated)" if row["how"] == "extrapolated" else "")


def convergence_chart(sweep: list[dict[str, Any]], target: float, path: Path,
                      slopes: list[dict[str, Any]], times: list[dict[str, Any]], clock: str = "wall",
                      formats: tuple[str, ...] = ("png",)) -> list[str]:
    """relMSE against seconds and against spp, log-log: per strategy the mean over the sweep's
    seeds (bars: +-1 standard error of the mean; band: the range of the single seeds), its
    fitted slope with its interval in the legend, a dotted slope -1 through the last mean point,
    and the time to the target relMSE (diamond, with its interval) where the data support one.
    Points whose corrected relMSE is not positive (below the reference's noise, or an exactly
    black image) cannot sit on a log axis and are left out. Returns the files written."""
    plt = _pyplot()
    fig, (ax_t, ax_s) = plt.subplots(1, 2, figsize=(11, 5.2))
    slope_of = {r["strategy"]: r for r in slopes}
    time_of = {r["strategy"]: r for r in times}
    seeds = 1
    plotted = False
    extra = iter(MORE_COLORS * 4)
    for name, curve in sweep_curves(sweep).items():
        color = COLORS.get(name) or next(extra, None)
        seeds = max(seeds, len(curve.seeds))
        t = time_of[name]
        ax_s.plot([], [], "o-", ms=3, color=color, label=f"{name}: {slope_text(slope_of[name])}")
        ax_t.plot([], [], "o-", ms=3, color=color, label=f"{name}: {time_text(t, _unit(clock))}")
        rows = [r for r in curve.summary() if r["relmse"] > 0.0]
        if not rows:
            continue
        plotted = True
        mean = np.array([r["relmse"] for r in rows])
        se = np.nan_to_num(np.array([r["relmse_se"] for r in rows]))
        low = np.array([r["relmse_min"] for r in rows])
        high = np.array([r["relmse_max"] for r in rows])
        spp = np.array([r["spp"] for r in rows], dtype=float)
        seconds = np.array([r["seconds"] for r in rows])
        below = np.minimum(se, mean * (1.0 - 1e-6))  # a bar cannot reach 0 on a log axis
        for ax, x in ((ax_t, seconds), (ax_s, spp)):
            if len(curve.seeds) > 1:
                ax.fill_between(x, np.where(low > 0.0, low, np.nan), high, color=color, alpha=0.13, lw=0)
            ax.errorbar(x, mean, yerr=(below, se), fmt="o-", ms=3, lw=1.2, capsize=2, color=color)
        ax_s.plot(spp, mean[-1] * spp[-1] / spp, ":", color=color, lw=1.0)
        if t["seconds"] is not None:
            err = None
            if t["low"] is not None and t["high"] is not None and np.isfinite(t["high"]):
                err = [[t["seconds"] - t["low"]], [t["high"] - t["seconds"]]]
            ax_t.errorbar([t["seconds"]], [target], xerr=err, fmt="D", ms=6, mec="k", mew=0.6,
                          color=color, capsize=3, zorder=5)
    seconds_label = "CPU seconds (all threads)" if clock == "cpu" else "seconds (wall clock)"
    for ax, xlabel in ((ax_t, seconds_label), (ax_s, "samples per pixel")):
        ax.axhline(target, color="k", lw=0.7, ls="--")
        if plotted:
            ax.set_xscale("log")
            ax.set_yscale("log")
        else:
            ax.set_xticks([])
            ax.set_yticks([])
            ax.text(0.5, 0.5, "no positive relMSE to show\n(below what the reference resolves)",
                    ha="center", va="center", transform=ax.transAxes, fontsize=9)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"relMSE (mean of {seeds} seeds)" if seeds > 1 else "relMSE")
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    level = f"{CONFIDENCE:.0%}"
    ax_t.legend(fontsize=7.5, title=f"time to relMSE {target:g} [{level} interval]", title_fontsize=8)
    ax_s.legend(fontsize=7.5, title=f"slope for spp ≥ {FIT_MIN_SPP} [{level} interval]", title_fontsize=8)
    ax_t.set_title(f"error against time (dashed: target relMSE {target:g}; ◆: time to reach it)", fontsize=10)
    ax_s.set_title("error against samples (dotted: slope -1, the expected 1/spp)", fontsize=10)
    caption = (f"Each point: the mean over {seeds} independent seeds; bars ±1 standard error, band: the "
               "range of single seeds. Intervals: jackknife over the seeds." if seeds > 1 else
               "One seed per point: no spread or intervals (use more sweep seeds).")
    caption = " ".join([caption, *_slope_notes(slopes)])
    lines = textwrap.wrap(caption, 175)
    fig.text(0.01, 0.01, "\n".join(lines), fontsize=7.5, va="bottom", ha="left")
    # Room for the caption: its lines of 7.5 points (1.2 line spacing) as a share of the height.
    tight_layout(fig, rect=(0.0, 0.01 + len(lines) * 7.5 * 1.2 / 72.0 / fig.get_figheight(), 1.0, 1.0))
    return save_figures(fig, path, formats)


def allocation_chart(rows: list[dict[str, Any]], path: Path, clock: str = "wall",
                     formats: tuple[str, ...] = ("png",)) -> list[str]:
    """Efficiency of MIS for each light:BSDF sample allocation; returns the files written."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    labels = [f"{r['light_samples']}:{r['bsdf_samples']}" for r in rows]
    ax.bar(labels, [r["efficiency"] for r in rows], color="#59a14f")
    ax.set_xlabel("light : BSDF samples per camera sample")
    ax.set_ylabel("efficiency = 1 / (relMSE × " + ("CPU seconds)" if clock == "cpu" else "seconds)"))
    ax.set_yscale("log")
    ax.set_title("MIS sample allocation", fontsize=10)
    tight_layout(fig)
    return save_figures(fig, path, formats)


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
    columns = ["name", "strategy", "heuristic", "allocation", "light_samples", "bsdf_samples",
               "light_sampling", "environment_sampling", "sampler",
               "spp", "seconds", "budget", "clock",
               "wall_seconds", "cpu_seconds", "mse", "relmse", "variance", "efficiency", "flip",
               "mse_uncorrected", "relmse_uncorrected"]
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(safe["results"])
    write_text(out / "metrics.csv", table.getvalue())


def _convergence_html(document: dict[str, Any]) -> str:
    """The sweep's table (slopes and times to target, with intervals) and what it means."""
    esc = html.escape
    slopes, times = document.get("convergence", []), document.get("time_to_target", [])
    if not slopes:
        return ""
    unit = _unit(document["mode"].get("clock", "wall"))
    target = times[0]["target_relmse"] if times else float("nan")
    level = f"{slopes[0]['confidence']:.0%}"
    rows = []
    for slope, time in zip(slopes, times, strict=True):
        why = f' title="{esc(time["note"])}"' if time["note"] else ""
        note = f"<br><small>{esc(time['note'])}</small>" if time["note"] else ""
        against_time = _interval(slope["slope_seconds"], slope["slope_seconds_low"],
                                 slope["slope_seconds_high"], ".2f")
        rows.append(f"<tr><td>{esc(slope['strategy'])}</td><td>{slope['seeds']}</td>"
                    f"<td>{esc(slope_text(slope))}</td><td>{esc(against_time)}</td>"
                    f"<td{why}>{esc(time_text(time, unit))}{note}</td></tr>")
    notes = _slope_notes(slopes)
    caveat = "".join(f" {esc(note)}" for note in notes)
    if HEAVY_TAIL_NOTE in notes:
        caveat += (" The intervals come from the spread between the seeds, so they cannot account for "
                   "large samples that no seed drew.")
    return f"""<h2>Convergence: slopes and time to relMSE {target:g}</h2>
<p>Each strategy rendered progressively (1, 2, 4, &hellip; spp) once per seed, with
{slopes[0]['seeds']} independent seeds (none of which the reference holds); the chart shows the
mean over the seeds at each spp, &plusmn;1 standard error, and the range of the single seeds.
Slopes are least-squares fits of log mean relMSE for spp &ge; {slopes[0]['first_spp_fitted']};
intervals ({level}) are jackknife over the seeds with Student's t. An unbiased estimator's
expected relMSE falls exactly as 1/spp (slope &minus;1); against time the slope is steeper at
first, as each render also has fixed costs. The time to the target is interpolated between
measured points, or extrapolated along the line fitted against spp (at the last doubling's cost
per spp) only when its interval lies below 0 and the time is at most {EXTRAPOLATION_LIMIT:g}&times;
the sweep's longest; otherwise n/a, with the reason.{caveat}</p>
<table><tr><th>strategy</th><th>seeds</th><th>slope against spp [{level}]</th>
<th>slope against time [{level}]</th><th>time to relMSE {target:g} [{level}]</th></tr>
{''.join(rows)}
</table>
"""


def _sort_value(value: Any) -> str:
    """A table cell's number for sorting (``repr`` of the float: exact), empty when undefined."""
    if value is None or not np.isfinite(value):
        return ""
    return repr(float(value))


def write_index(out: Path, document: dict[str, Any], images: dict[str, list[list[str]]],
                viewer_omitted: str | None = None) -> None:
    """The page: the viewer (or why it was left out: ``viewer_omitted``) beside the metrics
    table, then the grid, maps, charts and tables; relative links only. ``images`` maps a
    section title to its figures, each the list of its files (PNG first, shown; the vector
    copies linked)."""
    esc = html.escape
    mode = document["mode"]
    clock = mode.get("clock", "wall")
    rows = []
    for r in document["results"]:
        budget = f" of {r['budget']:.2f}" if "budget" in r else ""
        cells = [(r["spp"], str(r["spp"])), (r["seconds"], f"{r['seconds']:.2f}{budget}")]
        cells += [(r[k], number(r[k])) for k in ("mse", "relmse", "variance", "efficiency")]
        cells.append((r.get("flip"), number(r.get("flip"), ".3f")))
        # data-value: the number a click on the column's head sorts by (empty: n/a, sorted last)
        rows.append(f"<tr><td>{esc(r['name'])}</td>" + "".join(
            f'<td data-value="{_sort_value(value)}">{text}</td>' for value, text in cells) + "</tr>")
    sections = []
    for title, figures in images.items():
        shown = "".join(f'<a href="{esc(f[0])}"><img src="{esc(f[0])}" alt="{esc(f[0])}"></a>'
                        for f in figures)
        vector = [name for f in figures for name in f[1:]]
        also = ("<p class=also>Also as: " + ", ".join(f'<a href="{esc(v)}">{esc(v)}</a>' for v in vector)
                + "</p>") if vector else ""
        sections.append(f"<h2>{esc(title)}</h2><div class=row>{shown}</div>{also}")
        if title.startswith("Error against time"):
            sections.append(_convergence_html(document))
    seconds_head = "CPU seconds" if clock == "cpu" else "seconds"
    viewer_text = "" if viewer_omitted else (
        " The viewer draws the 32-bit floats of each render's EXR (packed in <code>viewer_data.js</code>): "
        "exposure and maps are applied live.")
    table = (f'<table class="sortable" id="metrics"><tr><th>strategy</th><th>spp</th><th>{seconds_head}</th>'
             "<th>MSE</th><th>relMSE</th><th>variance</th><th>efficiency</th><th>FLIP</th></tr>\n"
             + "\n".join(rows) + "\n</table>")
    clock_text = ("process CPU time of each render, summed over its threads (time.process_time)"
                  if clock == "cpu" else "wall-clock time of each render")
    noise = document["reference_noise"]
    if noise["subtracted"]:
        correction = (f"each less the reference's own variance (its noise, relMSE {number(noise['relmse'])}, "
                      "which adds to every measured error; <code>*_uncorrected</code> in the data are as "
                      "measured; the error maps are uncorrected)")
        noise_note = ""
    else:  # the one line compare prints, as a paragraph of its own above the table
        correction = "each as measured (nothing is subtracted for the reference's own noise: see the note)"
        noise_note = f"<p class=note><b>Note:</b> {esc(noise['correction'])}.</p>\n"
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<title>tracer compare: {esc(document['scene'])}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; background: #fafafa; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }}
td:first-child, th:first-child {{ text-align: left; }}
.row img {{ max-width: 100%; margin: 0.3em; vertical-align: top; }}
.row img[src="grid.png"] {{ image-rendering: pixelated; }}
.row img[src$="_relerr.png"], .row img[src$="_flip.png"], .row img[src^="efficiency_"] {{ width: 460px; }}
.row img[src$="convergence.png"] {{ width: 1100px; }}
.row img[src$="allocation.png"] {{ width: 550px; }}
p {{ max-width: 60em; }}
.also {{ font-size: 0.85em; }}
.note {{ background: #fff4d6; padding: 0.4em 0.6em; }}
</style></head><body>
<h1>{esc(document['scene'])}: sampling strategies compared</h1>
{noise_note}<p>Mode: <b>{esc(mode['kind'])}</b> ({esc(mode['description'])}). Times are the {clock_text}.
Reference: <code>{esc(document['reference'])}</code> ({esc(document['reference_description'])}).
relMSE = mean (I&minus;R)&sup2;/(R&sup2;+0.01) and MSE = mean (I&minus;R)&sup2;, {correction};
efficiency = 1/(relMSE &times; {seconds_head}), n/a where relMSE is not positive.
Data: <a href="metrics.json">metrics.json</a>, <a href="metrics.csv">metrics.csv</a>.{viewer_text}
Click a column's head to sort the table.</p>
{viewer.section_html(table, html.escape(viewer_omitted) if viewer_omitted else None)}
{''.join(sections)}
</body></html>
"""
    write_text(out / "index.html", page)


def terminal_tables(document: dict[str, Any]) -> list[str]:
    """The lines ``tracer compare`` prints after the results: the sweep's slopes and times to
    the target relMSE, each with its interval (none without a sweep)."""
    slopes, times = document.get("convergence", []), document.get("time_to_target", [])
    if not slopes:
        return []
    unit = _unit(document["mode"].get("clock", "wall"))
    level = f"{slopes[0]['confidence']:.0%}"
    target = times[0]["target_relmse"]
    width = max(8, *(len(r["strategy"]) for r in slopes))
    slope_col = [slope_text(r, ascii_only=True) for r in slopes]
    time_col = [time_text(t, unit, ascii_only=True) if t["seconds"] is not None else f"n/a: {t['note']}"
                for t in times]
    sw = max(len(f"slope/spp [{level}]"), *(len(c) for c in slope_col))
    lines = [f"sweep: mean of {slopes[0]['seeds']} seeds per point; Monte Carlo's expected slope is -1",
             f"{'strategy':<{width}}  {f'slope/spp [{level}]':<{sw}}  time to relMSE {target:g} [{level}]"]
    lines += [f"{r['strategy']:<{width}}  {c:<{sw}}  {t}"
              for r, c, t in zip(slopes, slope_col, time_col, strict=True)]
    sides = {_slope_side(r) for r in slopes}
    if "shallower" in sides:
        lines.append("* the interval lies above -1: a heavy-tailed estimator, whose rare large samples runs "
                     "of few spp seldom draw (see index.html)")
    if "steeper" in sides:
        lines.append("** the interval lies below -1: faster than 1/spp, as stratified and QMC points can be")
    return lines


def describe_mode(spp: int | None, budget: float | None, clock: str = "wall") -> dict[str, Any]:
    """The comparison's mode for ``metrics.json`` and the page: equal spp or equal time, and
    the clock its seconds are measured on (``compare.CLOCKS``)."""
    if budget is not None:
        on = "of CPU time (summed over its threads)" if clock == "cpu" else "of wall-clock time"
        return {"kind": "equal-time", "seconds": budget, "clock": clock,
                "description": f"every strategy renders for {budget:g} s {on}"}
    return {"kind": "equal-spp", "spp": spp, "clock": clock,
            "description": f"every strategy renders {spp} spp"}


def result_row(run: Run, flip: float) -> dict[str, Any]:
    row = run_row(run)
    row["name"] = run_name(run)
    row["flip"] = flip
    return row


def efficiency_pairs(runs: list[Run]) -> list[tuple[Run, Run]]:
    """The pairs whose ratio map is most telling: light vs BSDF (where each wins), then MIS
    against each of them (each strategy's first run), then every other light-sampling technique
    and sampler of a strategy against its first (where solid angle beats area sampling, or
    Sobol points independent ones, and where not)."""
    first: dict[str, Run] = {}
    for r in runs:  # a strategy's run with the default settings (mis: power, fixed), else its first
        if run_name(r) == r.strategy.name:
            first[r.strategy.name] = r
    for r in runs:
        first.setdefault(r.strategy.name, r)
    pairs = [(first[a], first[b]) for a, b in (("bsdf", "light"), ("mis", "light"), ("mis", "bsdf"))
             if a in first and b in first]
    return pairs + [(r, first[r.strategy.name]) for r in runs if r is not first[r.strategy.name]]


def uncorrected_line(reference: Reference) -> str | None:
    """The one line that says the reference's noise is not subtracted, and why (None when it
    is): printed by ``tracer compare`` and written into the report's page and metrics.json."""
    if reference.uncorrected_because is None:
        return None
    return (f"mse and relmse are as measured, the reference's own noise not subtracted: "
            f"{reference.uncorrected_because}")


def reference_noise(reference: Reference) -> dict[str, Any]:
    """``metrics.json``'s ``reference_noise``: the reference's own noise on the relMSE and MSE
    scales and whether it was subtracted (null where its variance is not known)."""
    line = uncorrected_line(reference)
    if line is not None:
        return {"relmse": None, "mse": None, "subtracted": False, "correction": line}
    return {"relmse": metrics.reference_relmse(reference.mean, reference.pixel_variance),
            "mse": float(np.mean(reference.pixel_variance)), "subtracted": True,
            "correction": "mse and relmse have the reference's per-pixel variance subtracted "
                          "(unbiased for the image's own error); *_uncorrected are as measured"}


def make_report(out: Path, scene_name: str, reference_path: str, reference: Reference, runs: list[Run],
                mode: dict[str, Any], sweep: list[dict[str, Any]], allocation: list[Run],
                crops: list[tuple[int, int, int, int]] | None, exposure: float,
                target: float, figure_formats: tuple[str, ...] = ("png",),
                say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Write every file of a comparison into ``out`` and return the metrics document. Charts
    and maps are written in each of ``figure_formats`` (PNG always: the page shows it).
    ``say`` receives one progress line as each stage starts (a strategy's images and maps,
    the efficiency maps, each chart, the tables and page): the report takes seconds per
    strategy at 300 dpi, which were silent before.

    The files are written into a stage and moved into ``out`` together (``atomic.staged_folder``),
    the page last: if any write fails (a full disk), ``out`` keeps the report it had, instead of
    new images beside an old page, tables and viewer data."""
    with staged_folder(out) as stage:
        stage.entry = "index.html"
        document, omitted = _write_report(stage.path, scene_name, reference_path, reference, runs, mode,
                                          sweep, allocation, crops, exposure, target, figure_formats,
                                          say or (lambda text: None))
        if omitted:
            stage.remove(viewer.DATA_FILE)  # an older report's viewer data would contradict the page
    return document


def _write_report(out: Path, scene_name: str, reference_path: str, reference: Reference, runs: list[Run],
                  mode: dict[str, Any], sweep: list[dict[str, Any]], allocation: list[Run],
                  crops: list[tuple[int, int, int, int]] | None, exposure: float, target: float,
                  figure_formats: tuple[str, ...],
                  say: Callable[[str], None]) -> tuple[dict[str, Any], str | None]:
    """:func:`make_report`'s files, written into ``out``; the document and the reason the
    viewer was left out (None: it was written)."""
    clock = mode.get("clock", "wall")
    formats = tuple(figure_formats)
    images: dict[str, list[list[str]]] = {}
    windows = crops or pick_insets(runs, reference)
    grid_image(runs, reference, windows, exposure, out / "grid.png")
    images["Side by side (insets: where the strategies differ most)"] = [["grid.png"]]

    results, relerr_files, flip_files, viewed = [], [], [], []
    for i, run in enumerate(runs, start=1):
        name = run_name(run)
        say(f"  report {i}/{len(runs)}: {name}: EXR, PNG, error and FLIP maps")
        write_exr(out / f"{name}.exr", run.film)  # the header carries the record render() set
        write_png(out / f"{name}.png", run.film.image(), exposure)
        relerr_files.append(relerr_map(run, reference, out / f"{name}_relerr.png", formats))
        flip = flip_map(run, reference, out / f"{name}_flip.png", formats)
        flip_files.append([f"{name}_flip.{fmt}" for fmt in dict.fromkeys(("png", *formats))])
        results.append(result_row(run, float(flip.mean())))
        viewed.append({"name": name, "film": run.film, "seconds": run.seconds, "unit": _unit(run.clock),
                       "flip": flip})
    images["Relative squared error"] = relerr_files
    images["FLIP perceptual error"] = flip_files
    learned_files = [figure for run in runs for figure in learned_maps(run, out, formats)]
    if learned_files:
        images["What the learning renders learned (allocation: share of light samples; optimal MIS: "
               "the control variate's coefficient)"] = learned_files

    wins = []
    ratio_files = []
    pairs = efficiency_pairs(runs)
    if pairs:
        say(f"  report: {len(pairs)} efficiency-ratio map{'s' if len(pairs) != 1 else ''}")
    for a, b in pairs:
        stem = f"efficiency_{run_name(a)}_vs_{run_name(b)}"
        share = ratio_map(a, b, reference, out / f"{stem}.png", formats)
        ratio_files.append([f"{stem}.{fmt}" for fmt in dict.fromkeys(("png", *formats))])
        wins.append({"a": run_name(a), "b": run_name(b), "share_a_wins": share["a_wins"],
                     "share_b_wins": share["b_wins"]})
    if ratio_files:
        images["Per-pixel efficiency ratio (where each strategy wins)"] = ratio_files
    # The viewer's efficiency view compares with the first pair's second run by default.
    baseline = next(i for i, r in enumerate(runs) if r is pairs[0][1]) if pairs else None
    say("  report: the viewer's data")
    omitted = viewer.omission(reference.width, reference.height, len(runs))
    viewer.write_viewer(out, None if omitted else viewer.viewer_data(
        scene_name, reference, viewed, exposure, RELERR_RANGE, RATIO_RANGE, baseline))

    document: dict[str, Any] = {
        "scene": scene_name, "reference": reference_path, "reference_spp": reference.spp,
        "reference_strategy": reference.record.strategy,
        "reference_made_by": "tracer" if reference.external is None else "another renderer",
        "reference_description": reference.description,
        "reference_noise": reference_noise(reference),
        "mode": mode, "results": results, "sweep": sweep, "efficiency_ratio": wins}
    if sweep:
        say("  report: convergence chart")
        slopes, times = convergence_rows(sweep, target)
        document["sweep_summary"] = [row for curve in sweep_curves(sweep).values() for row in curve.summary()]
        document["convergence"] = slopes
        document["time_to_target"] = times
        images["Error against time and samples"] = [
            convergence_chart(sweep, target, out / "convergence.png", slopes, times, clock, formats)]
    if allocation:
        say("  report: allocation chart")
        rows = [run_row(r) for r in allocation]
        document["allocation"] = rows
        images["MIS sample allocation (light : BSDF)"] = [
            allocation_chart(rows, out / "allocation.png", clock, formats)]
    document["viewer"] = {"data_bytes": viewer.data_bytes(reference.width, reference.height, len(runs)),
                          "written": omitted is None}
    say("  report: tables and index.html")
    write_tables(out, document)
    write_index(out, document, images, omitted)
    return document, omitted
