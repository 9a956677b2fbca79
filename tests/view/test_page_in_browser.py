"""The page in a real headless browser (the system's Chromium through Selenium): it loads the
cards, shows a taxtel's texture profile, takes a stroke drawn with the pointer, re-times it at
the speed typed in, and plots the renderer's own numbers.

Skipped only where Chromium or its driver is not installed (``.ci/run`` installs the Debian
packages chromium and chromium-driver, so it runs in CI)."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from hcard.render import Renderer, RenderOptions
from hcard.view.model import path_track
from hcard.view.server import ViewState
from tests.view.cards import card_a, card_b
from tests.view.served import view_server

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="Chromium and chromedriver are not installed (Debian: apt-get install chromium "
           "chromium-driver; .ci/run installs them)")


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-dev-shm-usage", "--window-size=1400,1800",
                     "--force-device-scale-factor=1"):
        options.add_argument(argument)
    driver = webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)),
                              options=options)
    driver.set_script_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture(scope="module")
def page(browser: Any) -> Iterator[Any]:
    from selenium.webdriver.support.ui import WebDriverWait

    with view_server(ViewState([card_a(), card_b()], ["a.hcard", "b.hcard"])) as url:
        browser.get(url)
        WebDriverWait(browser, 20).until(
            lambda d: d.execute_script("return document.body.dataset.ready === 'true'"))
        yield browser


def _surface_point(page: Any, x_mm: float, y_mm: float) -> tuple[int, int]:
    """The offset from the first surface canvas's centre (Selenium's origin) of a point in
    mm, in CSS pixels."""
    s = page.execute_script(
        "const s = hcardView.surfaces[0]; return [s.left, s.top, s.scale, s.canvas.width, "
        "s.canvas.height, s.canvas.getBoundingClientRect().width];")
    left, top, scale, width, height, css_width = s
    ratio = css_width / width
    return (round((left + x_mm * scale - width / 2) * ratio),
            round((top + y_mm * scale - height / 2) * ratio))


def test_the_page_draws_both_maps_to_scale_and_the_difference(page: Any) -> None:
    from selenium.webdriver.common.by import By

    surface = page.find_element(By.ID, "surface-0")
    assert (surface.get_attribute("data-cols"), surface.get_attribute("data-rows")) == ("8", "6")
    assert page.find_element(By.ID, "surface-1").is_displayed()
    assert page.find_element(By.ID, "diff-map").is_displayed()
    scale = page.execute_script("return hcardView.surfaces.map((s) => s.scale)")
    assert scale[0] == scale[1]  # same surface size, same scale
    play = page.find_element(By.ID, "play")
    assert not play.is_enabled() and "--device" in play.get_attribute("title")


def test_clicking_a_taxtel_shows_its_profile_and_spectrum(page: Any) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    surface = page.find_element(By.ID, "surface-0")
    ActionChains(page).move_to_element_with_offset(surface, *_surface_point(page, 32.0, 12.0)
                                                   ).click().perform()
    WebDriverWait(page, 10).until(lambda d: d.execute_script("return hcardView.lastProfile"))
    profile = page.execute_script("return hcardView.lastProfile")
    assert page.execute_script("return hcardView.selected.texture") == 1  # the right half
    assert profile["length_mm"] == 20.0
    s = np.array(profile["s_mm"])
    np.testing.assert_allclose(profile["friction"], 1.3 + 0.2 * np.cos(np.pi * s) + 0.1 * np.cos(
        4 * np.pi * s + 1.0), rtol=1e-9)
    assert page.execute_script("return hcardView.plots['plot-spectrum'].points.length") == 2


def test_a_drawn_stroke_is_rendered_with_the_renderers_numbers(page: Any) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    surface = page.find_element(By.ID, "surface-0")
    corners = [(3.0, 4.0), (36.0, 9.0), (30.0, 26.0)]
    chain = ActionChains(page).move_to_element_with_offset(surface,
                                                           *_surface_point(page, *corners[0]))
    chain.click_and_hold()
    for x_mm, y_mm in corners[1:]:
        chain.move_to_element_with_offset(surface, *_surface_point(page, x_mm, y_mm))
    chain.release().perform()
    path = np.array(page.execute_script("return hcardView.stroke"))
    assert len(path) >= 3
    np.testing.assert_allclose(path[0], corners[0], atol=0.5)  # a CSS pixel is 0.1 mm or so
    np.testing.assert_allclose(path[-1], corners[-1], atol=0.5)

    speed = page.find_element(By.ID, "speed")
    speed.clear()
    speed.send_keys("150")
    page.find_element(By.ID, "render").click()
    WebDriverWait(page, 20).until(lambda d: d.execute_script("return hcardView.lastRender"))
    shown = page.execute_script("return hcardView.lastRender")

    # the renderer, called here on the stroke the page drew, timed at 150 mm/s
    track = path_track(path, 150.0)
    frames = Renderer(card_a(), RenderOptions(frame_rate_hz=10_000.0)).render(track)
    got = shown["frames"]
    assert len(got["friction"]) == len(frames) > 1000
    for name, values in (("t_s", frames.t), ("uv", frames.uv), ("ev", frames.ev),
                         ("friction", frames.friction)):
        np.testing.assert_allclose(got[name], values, rtol=1e-9, atol=0)
    assert shown["summary"]["duration_s"] == pytest.approx(track.duration_s, rel=1e-12)

    # the plotted polylines are those numbers, within a pixel
    distance = np.array(got["distance_mm"])
    for canvas, values in (("plot-friction", frames.friction), ("plot-uv", frames.uv),
                           ("plot-ev", frames.ev)):
        plotted = page.execute_script(f"return hcardView.plots['{canvas}']")
        box, (x0, x1), (y0, y1) = plotted["box"], plotted["x"], plotted["y"]
        assert x0 == distance.min() and x1 == distance.max()
        expected_x = box["left"] + (distance - x0) / (x1 - x0) * (box["right"] - box["left"])
        expected_y = box["bottom"] - (values - y0) / (y1 - y0) * (box["bottom"] - box["top"])
        points = np.array(plotted["points"])
        assert points.shape == (len(frames), 2)
        np.testing.assert_allclose(points[:, 0], expected_x, atol=1.0)
        np.testing.assert_allclose(points[:, 1], expected_y, atol=1.0)
        assert box["top"] - 1 <= points[:, 1].min() and points[:, 1].max() <= box["bottom"] + 1
    assert "rendered" in page.find_element(By.ID, "status").text
