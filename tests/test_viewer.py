"""The compare report's interactive viewer: its packed data against the EXRs, and the page
itself in headless Chromium (keys, zoom, pan, exposure, maps, readout, sorting) against the
same EXRs, read with OpenImageIO rather than with tracer's own reader.

The browser tests need Debian's ``chromium`` and ``chromium-driver`` and the ``selenium``
package. Where one is missing they are skipped, unless TRACER_BROWSER_TESTS=required (as
``.ci/run`` sets after installing the browser), when they fail instead: CI cannot pass them
by not running them.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import matplotlib
import numpy as np
import OpenImageIO as oiio
import pytest

from tracer.cli import main
from tracer.study import metrics, viewer

SCENES = Path(__file__).resolve().parent.parent / "tracer" / "scenes"
WIDTH, HEIGHT = 32, 32
REFERENCE_SPP, SPP = 64, 4
STRATEGIES = ("uniform", "cosine", "bsdf", "light", "mis")  # compare's default, in its order


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    """A compare report of the Cornell box at 32x32: a 64-spp reference, five strategies at 4 spp."""
    folder = tmp_path_factory.mktemp("viewer")
    scene = str(SCENES / "cornell.toml")
    ref = folder / "ref.exr"
    assert main(["reference", scene, "-o", str(ref), "--width", str(WIDTH), "--height", str(HEIGHT),
                 "--spp", str(REFERENCE_SPP), "--quiet", "--float"]) == 0
    out = folder / "cmp"
    assert main(["compare", scene, "--reference", str(ref), "--spp", str(SPP), "--out", str(out),
                 "--quiet"]) == 0
    return out


def exr_planes(path: Path, spp: int) -> tuple[np.ndarray, np.ndarray]:
    """An EXR's RGB means and the variance of each mean (its variance channels / spp), (H, W, 3)
    float32, read with OpenImageIO."""
    buf = oiio.ImageBuf(str(path))
    names = list(buf.spec().channelnames)
    pixels = buf.get_pixels(oiio.FLOAT)
    mean = pixels[..., [names.index(c) for c in "RGB"]]
    variance = pixels[..., [names.index(f"variance.{c}") for c in "RGB"]]
    return mean, (variance.astype(np.float64) / spp).astype(np.float32)


def test_packed_data_are_the_exrs_floats(report):
    """viewer_data.js holds, bit for bit, the 32-bit means of every EXR the report wrote and of
    the reference, the variance of each mean to float32 rounding of variance / spp, and each
    strategy's FLIP map; every link of the page is a file of the folder (opens from disk)."""
    data = viewer.read_viewer_data(report / viewer.DATA_FILE)
    assert (data["width"], data["height"], data["version"]) == (WIDTH, HEIGHT, viewer.FORMAT_VERSION)
    assert [image["name"] for image in data["images"]] == ["reference", *STRATEGIES]
    results = json.loads((report / "metrics.json").read_text())["results"]
    flips = {row["name"]: row["flip"] for row in results}
    for image in data["images"]:
        path = report.parent / "ref.exr" if image["name"] == "reference" else report / f"{image['name']}.exr"
        mean, variance = exr_planes(path, image["spp"])
        assert np.array_equal(viewer.unpack(image["mean"], (HEIGHT, WIDTH, 3)), mean), image["name"]
        packed = viewer.unpack(image["variance"], (HEIGHT, WIDTH, 3))
        assert np.allclose(packed, variance, rtol=2e-7, atol=0.0), image["name"]
        if image["name"] != "reference":  # the FLIP map whose mean metrics.json reports
            flip = viewer.unpack(image["flip"], (HEIGHT, WIDTH))
            assert flip.mean(dtype=np.float64) == pytest.approx(flips[image["name"]], rel=1e-5)
            assert 0.0 <= flip.min() and flip.max() <= 1.0 and flip.max() > 0.0
    page = (report / "index.html").read_text()
    assert f'<script src="{viewer.DATA_FILE}">' in page and f'<script src="{viewer.SCRIPT_FILE}">' in page
    shipped = Path(viewer.__file__).parent / viewer.SCRIPT_FILE
    assert (report / viewer.SCRIPT_FILE).read_text() == shipped.read_text()


def test_a_viewer_too_big_for_a_browser_is_left_out_with_the_reason(report, tmp_path, monkeypatch):
    """Past MAX_DATA_BYTES of floats the report writes no viewer data; the page says why where the
    viewer would be, keeps the script (it sorts the table) and links nothing missing; metrics.json
    records the size it would have had."""
    monkeypatch.setattr(viewer, "MAX_DATA_BYTES", 1000)
    out = tmp_path / "cmp"
    assert main(["compare", str(SCENES / "cornell.toml"), "--reference", str(report.parent / "ref.exr"),
                 "--spp", "1", "--strategies", "light,mis", "--out", str(out), "--quiet"]) == 0
    page = (out / "index.html").read_text()
    assert "The interactive viewer was left out" in page and 'data-omitted="true"' in page
    assert not (out / viewer.DATA_FILE).exists() and viewer.DATA_FILE not in page
    assert (out / viewer.SCRIPT_FILE).is_file()
    document = json.loads((out / "metrics.json").read_text())
    assert document["viewer"] == {"data_bytes": WIDTH * HEIGHT * (24 * 3 + 4 * 2), "written": False}


def test_pack_round_trips_float32():
    values = np.array([[0.0, -1.5, 3.4028235e38], [1e-45, np.pi, 65504.0 * 4]], dtype=np.float64)
    assert np.array_equal(viewer.unpack(viewer.pack(values), (2, 3)), values.astype(np.float32))


# ---------------------------------------------------------------------------------------------
# In the browser


def _start_chromium(scale: float):
    """Headless Chromium through chromedriver at device scale factor ``scale``, with the flags
    this machine's closed network needs (no background connections), logging the page's
    console; skips (or fails, under TRACER_BROWSER_TESTS=required) when something is missing."""
    missing = [name for name, found in (("chromium", shutil.which("chromium")),
                                        ("chromedriver", shutil.which("chromedriver"))) if not found]
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        missing.append("selenium")
    if missing:
        message = f"browser test needs {', '.join(missing)} (Debian: chromium chromium-driver; pip: selenium)"
        if os.environ.get("TRACER_BROWSER_TESTS") == "required":
            pytest.fail(message)
        pytest.skip(message)
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium")
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                 "--no-first-run", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--window-size=1400,1100", f"--force-device-scale-factor={scale:g}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(shutil.which("chromedriver")), options=options)


@pytest.fixture(scope="module")
def browser():
    driver = _start_chromium(1.0)
    yield driver
    driver.quit()


def _open(driver, report: Path) -> None:
    """Load the report from disk and scroll the viewer's canvas to the middle of the window, so
    that every pixel of it can be pointed at whatever the page's text above it takes."""
    driver.get((report / "index.html").resolve().as_uri())
    driver.execute_script("document.getElementById('viewer-canvas').scrollIntoView({block: 'center'})")


def _readout(driver) -> dict[str, str]:
    from selenium.webdriver.common.by import By

    return {cell.get_attribute("data-field"): cell.text
            for cell in driver.find_elements(By.CSS_SELECTOR, "#readout td[data-field]")}


def _triple(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split()])


def _state(driver) -> dict:
    return driver.execute_script("return JSON.parse(JSON.stringify(window.tracerViewer.state))")


def _keys(driver, keys: str) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    ActionChains(driver).send_keys(keys).perform()


def _canvas_point(driver, state: dict, pixel: tuple[int, int]) -> tuple[float, float]:
    """The canvas point (CSS pixels from its top-left corner) at the centre of image ``pixel``."""
    return state["ox"] + (pixel[0] + 0.5) * state["scale"], state["oy"] + (pixel[1] + 0.5) * state["scale"]


def _click(driver, point: tuple[float, float]) -> None:
    """A click at ``point`` of the canvas (selenium's offsets are from the element's centre)."""
    from selenium.webdriver.common.action_chains import ActionChains

    canvas = driver.find_element("id", "viewer-canvas")
    dx, dy = int(round(point[0] - canvas.size["width"] / 2)), int(round(point[1] - canvas.size["height"] / 2))
    ActionChains(driver).move_to_element_with_offset(canvas, dx, dy).click().perform()


def _canvas_rgb(driver, point: tuple[float, float], scale: float = 1.0) -> np.ndarray:
    """The 8-bit colour drawn at ``point`` (CSS pixels) of the canvas, whose backing store has
    ``scale`` (the device scale factor) store pixels per CSS pixel."""
    return np.array(driver.execute_script(
        "const c = document.getElementById('viewer-canvas');"
        "const rgba = c.getContext('2d').getImageData(arguments[0], arguments[1], 1, 1).data;"
        "return Array.from(rgba).slice(0, 3);",
        int(point[0] * scale), int(point[1] * scale)))


def _lut(name: str) -> np.ndarray:
    return np.rint(matplotlib.colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3] * 255.0)


def _is_lut_colour(rgb: np.ndarray, table: np.ndarray, value: float, low: float, high: float) -> bool:
    """Whether ``rgb`` is the colour-table entry of ``value`` on [low, high]: bin floor(256 t), t
    the value's place in the range; within 1e-4 of a bin's edge either bin (the browser's float64
    sums and numpy's may round to either side of it)."""
    t = (value - low) / (high - low) * 256.0
    bins = {int(np.clip(np.floor(t), 0, 255))}
    if abs(t - round(t)) < 1e-4:
        bins |= {int(np.clip(round(t) - 1, 0, 255)), int(np.clip(round(t), 0, 255))}
    return any(np.array_equal(rgb, table[i]) for i in bins)


def _srgb8(value: np.ndarray, exposure: float, curve: bool = True) -> np.ndarray:
    """imagefiles.to_srgb8 written out again: exposure, clipping, the sRGB curve, 8 bits."""
    clipped = np.clip(value.astype(np.float64) * 2.0**exposure, 0.0, 1.0)
    if curve:
        clipped = np.where(clipped <= 0.0031308, 12.92 * clipped, 1.055 * clipped ** (1 / 2.4) - 0.055)
    return np.rint(clipped * 255)


def test_viewer_in_chromium_matches_the_exrs(report, browser):
    """Opened from disk: no console errors; keys choose and flip images; a click holds the readout
    on a pixel whose value, reference, error, variance and efficiency ratio equal those computed
    here from the EXRs (to the 7 digits shown); the wheel zooms about the cursor for every image;
    a drag pans; exposure and the sRGB switch change the drawn colours as imagefiles.to_srgb8 does;
    the relative-error view draws matplotlib's magma entry of that pixel's value; the range keys
    move the colour scale; a click on a column's head sorts the metrics table."""
    driver = browser
    _open(driver, report)
    errors = [entry for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
    assert not errors, errors
    data = viewer.read_viewer_data(report / viewer.DATA_FILE)
    names = [image["name"] for image in data["images"]]
    flips = {image["name"]: viewer.unpack(image["flip"], (HEIGHT, WIDTH)) for image in data["images"][1:]}
    reference, reference_variance = exr_planes(report.parent / "ref.exr", REFERENCE_SPP)
    planes = {name: exr_planes(report / f"{name}.exr", SPP) for name in STRATEGIES}

    # Keys 1-9 and the arrows choose the image; the caption names it.
    _keys(driver, "1")
    assert _state(driver)["image"] == 0 and "reference" in driver.find_element("id", "viewer-caption").text
    _keys(driver, "5")
    assert names[_state(driver)["image"]] == "light"
    from selenium.webdriver.common.keys import Keys
    _keys(driver, Keys.ARROW_RIGHT)
    assert names[_state(driver)["image"]] == "mis"
    _keys(driver, Keys.ARROW_RIGHT)  # past the last: back to the first
    assert _state(driver)["image"] == 0
    _keys(driver, Keys.ARROW_LEFT)
    assert names[_state(driver)["image"]] == "mis"

    # A lit pixel that uniform sampling found, and where the light-sampling render at +1 stop lies
    # inside the sRGB curve's range in every channel (not clipped, not 0), so that the curve shows.
    # And where uniform and light sampling differ in efficiency, by far more than their times
    # vary from run to run, so that its map shows which is which.
    doubled = 2.0 * planes["light"][0]
    seconds = {image["name"]: image["seconds"] for image in data["images"]}

    def ratio_map(name: str, against: str) -> np.ndarray:
        """log2 efficiency(name) / efficiency(against) per pixel, from the EXRs."""
        squared = [(planes[n][0].astype(np.float64) - reference) ** 2 for n in (name, against)]
        return metrics.efficiency_ratio_map(squared[0], seconds[name], squared[1], seconds[against])

    lit = np.argwhere((reference.mean(axis=2) > 0.05) & (planes["uniform"][0].mean(axis=2) > 0.0)
                      & np.all((doubled > 0.02) & (doubled < 0.9), axis=2)
                      & (np.abs(ratio_map("uniform", "light")) > 1.0))
    assert len(lit), "no pixel to test on"
    y, x = (int(v) for v in lit[len(lit) // 2])
    state = _state(driver)
    _click(driver, _canvas_point(driver, state, (x, y)))
    assert _state(driver)["pinned"] == [x, y]

    def ratio_at(name: str, against: str) -> float:
        return float(ratio_map(name, against)[y, x])

    def check_readout(name: str) -> None:
        shown = _readout(driver)
        assert shown["pixel"].startswith(f"{x}, {y}") and shown["image"] == name
        mean, variance = planes[name]
        np.testing.assert_allclose(_triple(shown["value"]), mean[y, x], rtol=1e-6)
        np.testing.assert_allclose(_triple(shown["reference"]), reference[y, x], rtol=1e-6)
        error = mean[y, x].astype(np.float64) - reference[y, x]
        np.testing.assert_allclose(_triple(shown["error"]), error, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(_triple(shown["variance"]), variance[y, x], rtol=1e-6)
        assert float(shown["flip"]) == pytest.approx(float(flips[name][y, x]), rel=1e-6, abs=1e-12)
        relerr = metrics.relative_squared_error(mean[y, x].astype(np.float64),
                                                reference[y, x].astype(np.float64)).mean()
        assert float(shown["relerr"]) == pytest.approx(relerr, rel=1e-6)
        against = names[_state(driver)["baseline"]]
        if name != against:
            ratio = ratio_at(name, against)
            assert float(shown["efficiency"].split()[0]) == pytest.approx(ratio, rel=1e-6, abs=1e-9)
        else:
            assert shown["efficiency"] == "n/a"

    check_readout("mis")
    _keys(driver, "2")  # flipping keeps the held pixel: now the uniform render's numbers there
    check_readout("uniform")

    # The wheel zooms about the cursor: the image point under it stays put, for every image.
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    canvas = driver.find_element("id", "viewer-canvas")
    before = _state(driver)
    cursor = _canvas_point(driver, before, (x, y))
    origin = ScrollOrigin.from_element(canvas, int(round(cursor[0] - canvas.size["width"] / 2)),
                                       int(round(cursor[1] - canvas.size["height"] / 2)))
    ActionChains(driver).scroll_from_origin(origin, 0, -480).perform()
    after = _state(driver)
    assert after["scale"] > 2.0 * before["scale"]
    # The point that stays put (the same image coordinate before and after) is where the cursor
    # was, to the pixel that selenium's whole-pixel offsets from the element's centre allow.
    for axis, offset in ((0, "ox"), (1, "oy")):
        fixed = ((before[offset] * after["scale"] - after[offset] * before["scale"])
                 / (after["scale"] - before["scale"]))
        assert abs(fixed - cursor[axis]) <= 1.0, (axis, fixed, cursor)
    _keys(driver, "3")
    assert _state(driver)["scale"] == after["scale"]  # the zoom is shared, not per image

    # A drag pans by what the mouse moved, and holds no pixel.
    ActionChains(driver).move_to_element(canvas).click_and_hold().move_by_offset(40, 25).release().perform()
    panned = _state(driver)
    assert (panned["ox"] - after["ox"], panned["oy"] - after["oy"]) == pytest.approx((40, 25), abs=1e-9)
    assert panned["pinned"] == [x, y]

    # Exposure and the sRGB curve act on the floats: the drawn colour of the held pixel.
    _keys(driver, "5")  # light
    _keys(driver, "0")  # the report's exposure (0)
    _keys(driver, "++")
    state = _state(driver)
    assert state["exposure"] == 1.0
    point = _canvas_point(driver, state, (x, y))
    value = planes["light"][0][y, x]
    assert np.abs(_canvas_rgb(driver, point) - _srgb8(value, 1.0)).max() <= 1  # 1: rounding of .5
    _keys(driver, "s")
    assert np.abs(_canvas_rgb(driver, point) - _srgb8(value, 1.0, curve=False)).max() <= 1
    _keys(driver, "s")

    # The relative-error view: the magma colour of log10 of the pixel's relative squared error.
    _keys(driver, "r")
    state = _state(driver)
    low, high = state["ranges"]["relerr"]
    assert (low, high) == tuple(data["views"]["relerr"]["range"])
    relerr = metrics.relative_squared_error(planes["light"][0][y, x].astype(np.float64),
                                            reference[y, x].astype(np.float64)).mean()
    assert _is_lut_colour(_canvas_rgb(driver, point), _lut("magma"), np.log10(relerr + 1e-12), low, high)
    # FLIP and the variance of the mean (channel mean, log10) in theirs.
    _keys(driver, "f")
    assert _is_lut_colour(_canvas_rgb(driver, point), _lut("magma"), float(flips["light"][y, x]),
                          *_state(driver)["ranges"]["flip"])
    _keys(driver, "v")
    log_variance = np.log10(planes["light"][1][y, x].astype(np.float64).mean())
    assert _is_lut_colour(_canvas_rgb(driver, point), _lut("magma"), log_variance,
                          *_state(driver)["ranges"]["variance"])
    _keys(driver, "r]")
    raised = _state(driver)["ranges"]["relerr"]
    assert raised[0] == low and raised[1] > high
    assert float(driver.find_element("id", "viewer-range-high").get_attribute("value")) == raised[1]
    assert driver.find_element("id", "viewer-scale-high").text == format(raised[1], "g")

    # The efficiency view against an image chosen in the list (whose focus goes back to the page,
    # so the next key acts): the RdBu colour of the ratio at the held pixel, computed here.
    # (as a user's pick leaves it: the list focused, then a change event)
    driver.execute_script("const list = document.getElementById('viewer-baseline'); list.focus();"
                          "list.value = arguments[0]; list.dispatchEvent(new Event('change'));",
                          str(names.index("light")))
    _keys(driver, "2e")
    state = _state(driver)
    shown = (names[state["image"]], state["view"], names[state["baseline"]])
    assert shown == ("uniform", "efficiency", "light")
    low, high = state["ranges"]["efficiency"]
    assert _is_lut_colour(_canvas_rgb(driver, point), _lut("RdBu"), ratio_at("uniform", "light"), low, high)
    check_readout("uniform")

    # Sorting: relMSE ascending, then descending (undefined values last either way).
    results = json.loads((report / "metrics.json").read_text())["results"]
    heads = driver.find_elements("css selector", "table#metrics th")
    head = next(h for h in heads if h.text.startswith("relMSE"))

    def order() -> list[str]:
        rows = driver.find_elements("css selector", "table#metrics tr")[1:]
        return [row.find_element("css selector", "td").text for row in rows]

    by_relmse = [r["name"] for r in sorted(results, key=lambda r: r["relmse"])]
    head.click()
    assert order() == by_relmse
    head.click()
    assert order() == by_relmse[::-1]
    errors = [entry for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
    assert not errors, errors


def test_viewer_at_device_scale_factor_2(report):
    """On a screen of 2 device pixels per CSS pixel (a laptop's), a click still reads the pixel
    under it, and the canvas draws that pixel's colour (exposure 0, sRGB) in the store pixels
    under it: the backing store is scaled, not the mapping."""
    driver = _start_chromium(2.0)
    try:
        _open(driver, report)
        assert driver.execute_script("return window.devicePixelRatio") == 2
        _keys(driver, "5")  # light sampling
        light = exr_planes(report / "light.exr", SPP)[0]
        y, x = (int(v) for v in np.argwhere(np.all((light > 0.02) & (light < 0.9), axis=2))[0])
        state = _state(driver)
        point = _canvas_point(driver, state, (x, y))
        _click(driver, point)
        assert _readout(driver)["pixel"].startswith(f"{x}, {y}")
        np.testing.assert_allclose(_triple(_readout(driver)["value"]), light[y, x], rtol=1e-6)
        assert np.abs(_canvas_rgb(driver, point, scale=2.0) - _srgb8(light[y, x], 0.0)).max() <= 1
        errors = [entry for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
        assert not errors, errors
    finally:
        driver.quit()
