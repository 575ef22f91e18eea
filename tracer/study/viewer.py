"""The interactive viewer of a comparison report: the float data it draws (``viewer_data.js``)
and the page's part that holds it (``viewer.js``, written beside ``index.html``).

The report opens from disk (``file://``) with no server and no network. Browsers refuse
``fetch`` and ``XMLHttpRequest`` of local files, but they run local scripts, so the data are a
script: one assignment ``window.TRACER_VIEWER_DATA = {...}`` (JSON) whose arrays are base64
strings of little-endian IEEE 32-bit floats, row-major (row y from the top, then x, then the
channel). 32-bit, not half floats: they are the very numbers of the EXRs (whose means are 32-bit),
so the pixel readout shows what ``oiiotool`` would, and variances of small bright emitters, which
exceed half floats' 65504, stay finite. The cost is size: 24 bytes per pixel per image (mean and
variance of the mean, 3 channels each) plus 4 for a FLIP map, times 4/3 for base64; a 256 x 256
comparison of five strategies (and the reference) is 14 MB.

Everything the viewer shows is computed in the browser from those numbers, the way
``tracer.study.metrics`` computes it for the static maps: the exposure and sRGB curve
(``imagefiles.to_srgb8``), the relative squared error (``metrics.relative_squared_error``, channel
mean), the efficiency ratio against any other image (``metrics.efficiency_ratio_map``: the squared
error averaged over channels and a 7 x 7 window, times seconds), the variance of the mean.
Only FLIP, which OpenImageIO computes, travels as a map. The colour scales are matplotlib's, as
256-entry tables, so the live maps match the static PNGs.
"""

from __future__ import annotations

import base64
import json
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_write, write_text
from . import metrics
from .reference import Reference

DATA_FILE = "viewer_data.js"
SCRIPT_FILE = "viewer.js"
FORMAT_VERSION = 2  # 2: the reference's spp and variance may be null (another renderer's image)
# The colour tables the map views use (each view's range is the static map's: report.RELERR_RANGE
# and RATIO_RANGE; the variance's comes from the data).
COLORMAPS = ("magma", "RdBu")
ARRAYS = ("mean", "variance", "flip")  # each image's packed arrays: (H, W, 3), (H, W, 3), (H, W)
# Past this much float data (before base64: 4/3 of it as text) a browser takes many seconds and
# gigabytes to load the page, so the report leaves the viewer out and says why. A 1024 x 1024
# comparison of five strategies (164 MiB) stays under it.
MAX_DATA_BYTES = 192 * 2**20


def pack(values: np.ndarray) -> str:
    """``values`` as base64 of little-endian 32-bit floats in C (row-major) order."""
    return base64.b64encode(np.ascontiguousarray(values, dtype="<f4").tobytes()).decode("ascii")


def unpack(text: str, shape: tuple[int, ...]) -> np.ndarray:
    """The inverse of :func:`pack`: a float32 array of ``shape``."""
    return np.frombuffer(base64.b64decode(text), dtype="<f4").reshape(shape)


def colormap_table(name: str) -> list[list[int]]:
    """matplotlib's colour map ``name`` as 256 [r, g, b] entries in 0..255."""
    import matplotlib

    table = matplotlib.colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3]
    return np.rint(table * 255.0).astype(int).tolist()


def _log_variance_range(variances: list[np.ndarray]) -> list[float]:
    """The variance view's default range: log10 of the variance of the pixel mean (channel
    mean of each ``(..., 3)`` array) from its 1st to its 99.5th percentile over every image's
    nonzero pixels."""
    logs = [np.log10(v[v > 0.0]) for v in (v.mean(axis=-1, dtype=np.float64) for v in variances)]
    logs = np.concatenate(logs) if logs else np.zeros(0)
    if logs.size == 0:
        return [-6.0, 0.0]
    low, high = np.percentile(logs, [1.0, 99.5])
    low, high = float(np.floor(low)), float(np.ceil(high))
    return [low, high if high > low else low + 1.0]


def viewer_data(scene: str, reference: Reference, images: list[dict[str, Any]], exposure: float,
                relerr_range: tuple[float, float], ratio_range: float,
                baseline: int | None) -> dict[str, Any]:
    """The document ``viewer_data.js`` assigns, its arrays still float32 arrays (:func:`write_viewer`
    packs them as it writes). ``images``: one dict per compared render, in the report's order,
    with ``name``, ``film``, ``seconds``, ``unit`` (``s`` or ``CPU s``) and ``flip`` (an ``(H, W)``
    map); ``baseline``: the index among them of the efficiency view's default comparison (None:
    the first). The reference's ``spp`` and ``variance`` are null where they are not known
    (another renderer's image: ``reference.Reference``)."""
    h, w = reference.height, reference.width
    variance = None if reference.pixel_variance is None else _float32(reference.pixel_variance)
    entries = [{"name": "reference", "spp": reference.spp, "seconds": None, "unit": "",
                "mean": _float32(reference.image()), "variance": variance, "flip": None}]
    for image in images:
        film = image["film"]
        if (film.height, film.width) != (h, w):
            raise ValueError(f"{image['name']} is {film.width}x{film.height}, the reference {w}x{h}")
        entries.append({"name": image["name"], "spp": film.spp, "seconds": float(image["seconds"]),
                        "unit": image["unit"], "mean": _float32(film.image()),
                        "variance": _float32(film.variance_of_mean()), "flip": _float32(image["flip"])})
    return {
        "format": "tracer-viewer", "version": FORMAT_VERSION, "scene": scene,
        "encoding": "base64 of little-endian float32, row-major (y from the top, x, channel)",
        "width": w, "height": h, "exposure": float(exposure),
        "relmse_epsilon": metrics.RELMSE_EPSILON, "efficiency_radius": metrics.EFFICIENCY_RADIUS,
        "baseline": 1 + (baseline or 0) if images else None,
        "images": entries,
        "views": {
            "relerr": {"range": [float(relerr_range[0]), float(relerr_range[1])], "colormap": "magma",
                       "label": "log10 relative squared error (I-R)²/(R²+0.01), mean of RGB"},
            "flip": {"range": [0.0, 1.0], "colormap": "magma", "label": "FLIP error (OpenImageIO)"},
            "efficiency": {"range": [-float(ratio_range), float(ratio_range)], "colormap": "RdBu",
                           "label": "log2 efficiency ratio (blue: this image wins)"},
            "variance": {"range": _log_variance_range([e["variance"] for e in entries
                                                        if e["variance"] is not None]), "colormap": "magma",
                         "label": "log10 variance of the pixel mean (σ²/spp), mean of RGB"},
        },
        "colormaps": {name: colormap_table(name) for name in COLORMAPS},
    }


def _float32(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float32)


def _json_open(value: dict[str, Any]) -> str:
    """``value`` as compact JSON without its closing brace, for more fields to follow."""
    return json.dumps(value, separators=(",", ":"), allow_nan=False)[:-1]


def write_viewer(out: Path, document: dict[str, Any] | None) -> list[str]:
    """Write ``viewer_data.js`` (``document``, from :func:`viewer_data`; None: none, the
    viewer left out, and an older one removed) and ``viewer.js`` (which also sorts the table)
    into ``out``, atomically; returns their names. The data are written an array at a time, so
    that at most one array's base64 text is in memory beside the arrays (a single json.dumps
    of the whole would hold several copies of the file)."""
    written = []
    if document is None:
        (out / DATA_FILE).unlink(missing_ok=True)
    else:
        def write(tmp: str) -> None:
            with open(tmp, "w", encoding="ascii", newline="") as fh:
                fh.write("window.TRACER_VIEWER_DATA = ")
                fh.write(_json_open({k: v for k, v in document.items() if k != "images"}) + ',"images":[')
                for n, image in enumerate(document["images"]):
                    fields = {k: v for k, v in image.items() if k not in ARRAYS}
                    fh.write(("," if n else "") + _json_open(fields))
                    for key in ARRAYS:
                        if image[key] is None:
                            fh.write(f',"{key}":null')
                        else:  # three writes: no second copy of the base64 text
                            fh.write(f',"{key}":"')
                            fh.write(pack(image[key]))
                            fh.write('"')
                    fh.write("}")
                fh.write("]};\n")

        atomic_write(out / DATA_FILE, write)
        written.append(DATA_FILE)
    write_text(out / SCRIPT_FILE, resources.files(__package__).joinpath(SCRIPT_FILE).read_text("utf-8"))
    return [*written, SCRIPT_FILE]


def read_viewer_data(path: Path) -> dict[str, Any]:
    """The document a ``viewer_data.js`` assigns (tests, and tools that want the numbers)."""
    text = Path(path).read_text("utf-8")
    start, end = text.index("{"), text.rindex("}")
    return json.loads(text[start:end + 1])


def data_bytes(width: int, height: int, renders: int) -> int:
    """The viewer's float data for a comparison of ``renders`` at ``width`` x ``height``, in
    bytes before base64: per pixel 24 of mean and variance for each render and the reference,
    and 4 of FLIP for each render."""
    return width * height * (24 * (renders + 1) + 4 * renders)


def omission(width: int, height: int, renders: int) -> str | None:
    """Why a comparison's viewer is left out (its data past ``MAX_DATA_BYTES``), or None."""
    size = data_bytes(width, height, renders)
    if size <= MAX_DATA_BYTES:
        return None
    return (f"The interactive viewer was left out: its data would be {size / 2**20:.0f} MiB of floats, "
            f"more than the {MAX_DATA_BYTES / 2**20:.0f} MiB a browser loads in reasonable time (compare "
            "fewer strategies or a smaller reference for one). The static images below show the same "
            "comparison.")


def section_html(table: str, omitted: str | None = None) -> str:
    """The page's viewer: an empty frame that ``viewer.js`` fills, beside ``table`` (the metrics
    table, HTML, which the script makes sortable), and what a reader without scripts sees; or,
    where the data were left out, ``omitted``: why (HTML)."""
    if omitted is None:
        frame = ('<div id="tracer-viewer" class="viewer"><noscript><p>The interactive viewer needs '
                 "JavaScript; the static images below show the same comparison.</p></noscript></div>")
        scripts = [DATA_FILE, SCRIPT_FILE]
    else:
        frame = f'<div id="tracer-viewer" class="viewer" data-omitted="true"><p>{omitted}</p></div>'
        scripts = [SCRIPT_FILE]  # it still sorts the table
    tags = "".join(f'<script src="{name}"></script>\n' for name in scripts)
    return f'<div class="viewer-layout">\n{frame}\n<div class="viewer-side">{table}</div>\n</div>\n{tags}'
