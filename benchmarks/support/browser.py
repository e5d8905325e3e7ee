"""Driving viewdb's web page in Debian's headless Chromium with Selenium: starting the
browser, waiting, picking a photo, drawing on it with a mouse or a finger (the tests and
``benchmarks/web_screenshots.py``)."""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
#: The machine has no internet: without these Chromium keeps calling home.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")
WAIT = 180.0


def start_chromium(profile: Path, size: tuple[int, int]) -> Any:
    """A headless Chromium (Debian's, through its chromedriver) with a fresh profile."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(options=options, service=Service(executable_path=str(CHROMEDRIVER)))
    driver.set_page_load_timeout(60)
    return driver


@contextlib.contextmanager
def screenshot_on_failure(driver, name: str) -> Iterator[None]:
    """Save what the browser shows when the block fails (``$VIEWDB_SCREENSHOTS``, default
    a folder in the temp dir), and say where."""
    try:
        yield
    except BaseException:
        default = Path(tempfile.gettempdir()) / "viewdb-screenshots"
        folder = Path(os.environ.get("VIEWDB_SCREENSHOTS", default))
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}.png"
        driver.save_screenshot(str(path))
        print(f"screenshot of the failed page: {path}")
        raise


def wait(driver, condition, timeout: float = WAIT):
    """Poll ``condition(driver)`` until it is true. An element the page redraws between
    being found and being read (stale) or not drawn yet counts as not yet, not as a failure."""
    from selenium.common.exceptions import NoSuchElementException, StaleElementReferenceException
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(driver, timeout, poll_frequency=0.2,
                         ignored_exceptions=(NoSuchElementException, StaleElementReferenceException)
                         ).until(lambda d: condition(d))


def js(driver, script: str, *args):
    return driver.execute_script(script, *args)


def open_with_token(driver, url: str, token: str | None = None) -> None:
    """Load the page, giving it the token if it asks."""
    from selenium.webdriver.common.by import By

    driver.get(url + "/")
    wait(driver, lambda d: js(d, "return document.readyState") == "complete")
    wait(driver, lambda d: (d.find_element(By.ID, "server").text
                            or d.find_element(By.ID, "token-panel").is_displayed()))
    if token and driver.find_element(By.ID, "token-panel").is_displayed():
        driver.find_element(By.ID, "token").send_keys(token)
        driver.find_element(By.CSS_SELECTOR, "#token-form button").click()
        wait(driver, lambda d: d.find_element(By.ID, "server").text)


def upload(driver, path: Path) -> None:
    from selenium.webdriver.common.by import By

    field = driver.find_element(By.ID, "photo")
    field.clear()
    field.send_keys(str(path))
    driver.find_element(By.ID, "go").click()


def message(driver) -> str:
    """The page's error message, once it shows one."""
    from selenium.webdriver.common.by import By

    wait(driver, lambda d: d.find_element(By.ID, "message").is_displayed()
         and "error" in d.find_element(By.ID, "message").get_attribute("class"))
    return driver.find_element(By.ID, "message").text


def no_horizontal_scroll(driver) -> None:
    width, scroll, widest = js(driver, """
        const root = document.documentElement;
        let widest = 0;
        for (const node of document.querySelectorAll('body *')) {
          const box = node.getBoundingClientRect();
          if (box.width > 0) widest = Math.max(widest, box.right);
        }
        return [root.clientWidth, root.scrollWidth, widest];""")
    assert scroll <= width and widest <= width + 0.5, (width, scroll, widest)


def choose(driver, path: Path) -> dict[str, float]:
    """Pick ``path`` without sending it; once its preview shows, where the drawing surface
    is on the screen (CSS pixels) and the photo's size in its own pixels."""
    from selenium.webdriver.common.by import By

    field = driver.find_element(By.ID, "photo")
    field.clear()
    field.send_keys(str(path))
    wait(driver, lambda d: js(d, "return document.getElementById('photo-img').naturalWidth") > 0)
    js(driver, "document.getElementById('stage').scrollIntoView({block: 'center'})")
    return js(driver, """
        const box = document.getElementById('marks').getBoundingClientRect();
        const img = document.getElementById('photo-img');
        return {left: box.left, top: box.top, width: box.width, height: box.height,
                photo_width: img.naturalWidth, photo_height: img.naturalHeight};""")


def on_screen(surface: dict[str, float], x: float, y: float) -> tuple[int, int]:
    """Photo pixel (x, y) → the CSS pixel of the viewport that shows it."""
    return (round(surface["left"] + x * surface["width"] / surface["photo_width"]),
            round(surface["top"] + y * surface["height"] / surface["photo_height"]))


def gesture(driver, path: list[tuple[int, int]], kind: str = "mouse") -> None:
    """Press at ``path[0]``, move through the rest, release: a mouse drag, or a finger's."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions import interaction
    from selenium.webdriver.common.actions.action_builder import ActionBuilder
    from selenium.webdriver.common.actions.pointer_input import PointerInput

    chain = ActionChains(driver)
    pointer = PointerInput(interaction.POINTER_TOUCH if kind == "touch" else interaction.POINTER_MOUSE, kind)
    chain.w3c_actions = ActionBuilder(driver, mouse=pointer)
    chain.w3c_actions.pointer_action.move_to_location(*path[0]).pointer_down()
    for x, y in path[1:]:
        chain.w3c_actions.pointer_action.move_to_location(x, y)
    chain.w3c_actions.pointer_action.pointer_up()
    chain.perform()


def drag_box(driver, surface: dict[str, float], box: tuple[float, float, float, float]) -> None:
    (x1, y1), (x2, y2) = on_screen(surface, *box[:2]), on_screen(surface, *box[2:])
    gesture(driver, [(x1, y1), ((x1 + x2) // 2, (y1 + y2) // 2), (x2, y2)])


