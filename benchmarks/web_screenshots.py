"""The web page's screenshots in ``docs/images/``, taken in Debian's headless Chromium from a
real ``viewdb serve`` on the demo's database.

    python benchmarks/web_screenshots.py [--db demo/demo.db] [--out docs/images]

Without ``--db`` the demo's database is built (``viewdb demo``: every sample model, 30°
grid) in a temporary folder. Three pictures, each of the whole page:

* ``web.png`` (1100 px wide): the demo's photo of the mug, recognised as one object (the
  second time: the first query of a fresh server compiles and loads what the others reuse);
* ``web-prompts.png`` (1100 px wide): a table with a mug, a bottle and a dice, two boxes
  dragged with the mouse and a tap on the dice, each object's answer;
* ``web-phone.png`` (390 px wide): the same answer on a phone's width.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

import viewdb
from support.browser import (
    choose,
    drag_box,
    gesture,
    js,
    on_screen,
    open_with_token,
    start_chromium,
    upload,
    wait,
)
from support.serving import ServerProcess
from viewdb.bench.photos import table_photo
from viewdb_cli.main import _demo_photo

ROOT = Path(__file__).resolve().parents[1]

#: The table: (object, azimuth, elevation) of each view, and where it goes (top-left).
TABLE = (("mug", 130.0, 25.0), ("bottle", 50.0, 15.0), ("cube_dice", 200.0, 35.0))
PLACES = [(30, 40), (330, 20), (600, 70)]
SIZE = (880, 340)


def whole_page(driver, width: int, out: Path) -> None:
    """A screenshot of the whole page at ``width`` CSS pixels (the viewport made as tall
    as the page)."""
    metrics = {"width": width, "height": 900, "deviceScaleFactor": 1, "mobile": False}
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", metrics)
    wait(driver, lambda d: js(d, "return window.innerWidth") == width)
    metrics["height"] = js(driver, "return document.documentElement.scrollHeight")
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", metrics)
    js(driver, "window.scrollTo(0, 0)")
    driver.save_screenshot(str(out))
    driver.execute_cdp_cmd("Emulation.clearDeviceMetricsOverride", {})
    print(f"wrote {out}")


def answered(driver) -> None:
    """Wait for the answer: its overlays and thumbnails loaded."""
    shown = "[...document.querySelectorAll('#layers img:not([hidden]), .ranking img')]"
    wait(driver, lambda d: js(d, "return state.answer !== null && !document.getElementById('answers').hidden"
                                 f" && {shown}.every(i => i.naturalWidth > 0)"))


def table(db_path: Path, out: Path) -> list[tuple[int, int, int, int]]:
    """The table photo, and each object's bounding box in it."""
    with viewdb.open(db_path, read_only=True) as db:
        views = [db.render(name, h, v) for name, h, v in TABLE]
    photo, masks = table_photo(views, SIZE, PLACES)
    Image.fromarray(photo).save(out)
    boxes = []
    for mask in masks:
        ys, xs = np.nonzero(mask)
        boxes.append((int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1))
    return boxes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", type=Path, help="the demo's database (default: built here)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="viewdb-screens-") as tmp:
        folder = Path(tmp)
        db_path = args.db
        if db_path is None:
            subprocess.run([sys.executable, "-m", "viewdb_cli.main", "demo", "--out", str(folder)],
                           check=True, stdout=subprocess.DEVNULL)
            db_path = folder / "demo.db"
        photo = folder / "query.png"
        _demo_photo(db_path, "mug", photo)
        scene = folder / "table.png"
        boxes = table(db_path, scene)
        with ServerProcess(db_path, workers=1) as srv:
            driver = start_chromium(folder / "chromium", (1100, 900))
            try:
                open_with_token(driver, srv.url)
                upload(driver, photo)  # a first query warms the server (kernels, caches) ...
                answered(driver)
                open_with_token(driver, srv.url)
                upload(driver, photo)  # ... so the picture shows a query as a running server answers it
                answered(driver)
                whole_page(driver, 1100, args.out / "web.png")

                open_with_token(driver, srv.url)
                surface = choose(driver, scene)
                for x1, y1, x2, y2 in boxes[:2]:
                    drag_box(driver, surface, (x1 - 10, y1 - 10, x2 + 10, y2 + 10))
                x1, y1, x2, y2 = boxes[2]
                gesture(driver, [on_screen(surface, (x1 + x2) / 2, (y1 + y2) / 2)], kind="touch")
                driver.find_element("id", "go").click()
                answered(driver)
                whole_page(driver, 1100, args.out / "web-prompts.png")
                whole_page(driver, 390, args.out / "web-phone.png")
            finally:
                driver.quit()


if __name__ == "__main__":
    main()
