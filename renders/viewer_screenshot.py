"""The README's picture of the compare viewer: a report of veach_mis at 16 spp against the shipped
reference, opened in headless Chromium: the light-sampling render's relative error zoomed on the
plates, a pixel held in the readout, the efficiency against BSDF sampling, the table by relMSE.

    python renders/viewer_screenshot.py [--out renders/viewer.png] [--keep DIR]

Needs Debian's chromium and chromium-driver and the selenium package (the test extras).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "renders" / "viewer.png"))
    parser.add_argument("--keep", help="write the report into this folder and keep it")
    args = parser.parse_args()

    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin

    from tracer.cli import main as tracer

    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="viewer_"))
    status = tracer(["compare", str(ROOT / "scenes" / "veach_mis.toml"), "--reference",
                     str(ROOT / "renders" / "references" / "veach_mis.exr"), "--spp", "16", "--out",
                     str(folder), "--quiet"])
    if status != 0:
        return status
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium")
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-sync",
                 "--disable-background-networking", "--disable-component-update", "--window-size=1480,930",
                 "--force-device-scale-factor=1", "--hide-scrollbars"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(shutil.which("chromedriver")), options=options)
    try:
        driver.get((folder / "index.html").resolve().as_uri())
        driver.execute_script("document.querySelector('.viewer-layout').scrollIntoView()")
        ActionChains(driver).send_keys("5").perform()  # the light-sampling render
        canvas = driver.find_element("id", "viewer-canvas")
        # Zoom 2x about a point on the plates (offsets from the canvas's centre), then hold a
        # pixel on the smoothest plate, where light sampling is noisy.
        origin = ScrollOrigin.from_element(canvas, -60, 150)
        ActionChains(driver).scroll_from_origin(origin, 0, -240).perform()
        ActionChains(driver).move_to_element_with_offset(canvas, -90, 175).click().perform()
        from selenium.webdriver.support.ui import Select

        Select(driver.find_element("id", "viewer-baseline")).select_by_visible_text("bsdf")
        ActionChains(driver).send_keys("r").perform()  # the relative-error view, with its scale
        driver.find_element("css selector", "table#metrics th:nth-child(5)").click()  # sort by relMSE
        driver.save_screenshot(args.out)
    finally:
        driver.quit()
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
