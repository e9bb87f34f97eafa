"""A real browser on the material-tuning notebook (slow): JupyterLab + Playwright + Chromium.

JupyterLab serves a scratch copy of ``notebooks/material_tuning.ipynb`` (so nothing writes
into the repository), Chromium (Debian's ``/usr/bin/chromium``; installed with apt-get when
missing and running as root) runs all cells under ``DRAAW_MI_NOTEBOOK_SMALL=1``, waits until
the preview is at rest (budget reached), then drags the first material slider and checks that
the displayed image changed (pixels of the ``<img>`` element, not just its URL); with
``jupyter_rfb`` installed (its canvas shows the preview) it then drags on the image and checks
that the camera orbited (the image changed again). Screenshots
are kept in ``out/test-artifacts/``. Skipped, with the reason, when a piece is missing.
"""
from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
import uuid

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ARTEFACTS = os.path.join(ROOT, "out", "test-artifacts")
CHROMIUM = "/usr/bin/chromium"

pytestmark = pytest.mark.slow


def _chromium() -> str:
    if os.path.exists(CHROMIUM):
        return CHROMIUM
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        pytest.skip(f"{CHROMIUM} is missing and apt-get is not usable here (not root): "
                    "apt-get install chromium to run this test")
    for cmd in (["apt-get", "install", "-y", "-q", "chromium"], ["apt-get", "update", "-q"],
                ["apt-get", "install", "-y", "-q", "chromium"]):
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=600)
        if os.path.exists(CHROMIUM):
            return CHROMIUM
    pytest.skip("apt-get install chromium failed")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def lab(tmp_path):
    pytest.importorskip("jupyterlab", reason="JupyterLab is not installed (pip install 'draaw-mi[notebooks]')")
    pytest.importorskip("ipywidgets")
    work = tmp_path / "project"
    (work / "notebooks").mkdir(parents=True)
    shutil.copy(os.path.join(ROOT, "notebooks", "material_tuning.ipynb"), work / "notebooks")
    os.symlink(os.path.join(ROOT, "scenes"), work / "scenes")
    port, token = _free_port(), uuid.uuid4().hex
    env = dict(os.environ, DRAAW_MI_NOTEBOOK_SMALL="1")
    log = open(tmp_path / "lab.log", "w")
    proc = subprocess.Popen([sys.executable, "-m", "jupyterlab", "--no-browser", f"--port={port}",
                             "--ServerApp.ip=127.0.0.1", f"--IdentityProvider.token={token}",
                             f"--ServerApp.root_dir={work / 'notebooks'}", "--allow-root",
                             "--ServerApp.open_browser=False"], env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    try:
        for _ in range(120):
            try:
                urllib.request.urlopen(f"{base}/api/status?token={token}", timeout=2)
                break
            except OSError:
                if proc.poll() is not None:
                    pytest.skip(f"JupyterLab did not start: {(tmp_path / 'lab.log').read_text()[-500:]}")
                time.sleep(0.5)
        else:
            pytest.skip("JupyterLab did not answer within 60 s")
        yield base, token
    finally:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()


def _pixels(el) -> np.ndarray:
    from PIL import Image
    import io
    # a fixed size: the element's box can differ by a few pixels between layouts
    im = Image.open(io.BytesIO(el.screenshot())).convert("RGB").resize((64, 64), Image.BILINEAR)
    return np.asarray(im, dtype=np.int16)


def _at_rest(page, img, timeout=120.0) -> np.ndarray:
    """Pixels of the preview once two captures 1.5 s apart agree (the budget is reached)."""
    deadline = time.time() + timeout
    prev = _pixels(img)
    while time.time() < deadline:
        time.sleep(1.5)
        cur = _pixels(img)
        if cur.shape == prev.shape and np.abs(cur - prev).max() == 0:
            return cur
        prev = cur
    pytest.fail("the preview never came to rest")


def test_moving_a_slider_changes_the_displayed_image(lab):
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install playwright)")
    chromium = _chromium()
    base, token = lab
    os.makedirs(ARTEFACTS, exist_ok=True)
    with sync_api.sync_playwright() as p:
        try:
            browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox", "--disable-gpu"])
        except Exception as e:  # noqa: BLE001
            pytest.skip(f"Chromium does not start under Playwright: {e}")
        page = browser.new_page(viewport={"width": 1500, "height": 1000})
        try:
            page.goto(f"{base}/lab/tree/material_tuning.ipynb?token={token}", timeout=120_000)
            page.wait_for_selector(".jp-Notebook", timeout=120_000)
            page.wait_for_selector("text=/ipykernel\\) \\| Idle/", timeout=120_000)   # kernel ready
            for attempt in range(3):      # a click before the kernel is wired up can be lost
                page.click(".lm-MenuBar-itemLabel:text-is('Run')")
                page.click(".lm-Menu-itemLabel:text-is('Run All Cells')")
                try:
                    page.wait_for_selector(".jp-InputPrompt:has-text('[1]')", timeout=60_000)
                    break
                except sync_api.TimeoutError:
                    if attempt == 2:
                        raise
            # the last code cell's output: everything ran
            page.wait_for_selector(".jp-OutputArea-output:has-text('metal roughness in the file')",
                                   timeout=300_000)
            # jupyter_rfb's canvas (an <img> it draws into) when installed, else ipywidgets.Image
            img = page.wait_for_selector(".jp-OutputArea-output img.renderview-view, "
                                         ".jp-OutputArea-output img.widget-image", timeout=60_000)
            canvas = "renderview-view" in (img.get_attribute("class") or "")
            img.scroll_into_view_if_needed()
            before = _at_rest(page, img)
            page.screenshot(path=os.path.join(ARTEFACTS, "material_tuning_before.png"))
            handle = page.locator(".widget-hslider .noUi-handle").first
            handle.scroll_into_view_if_needed()
            box = handle.bounding_box()
            assert box is not None, "no slider handle on the page"
            page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
            page.mouse.down()
            page.mouse.move(box["x"] - 120, box["y"] + box["height"] / 2, steps=8)
            page.mouse.up()
            img.scroll_into_view_if_needed()
            after = _at_rest(page, img)
            page.screenshot(path=os.path.join(ARTEFACTS, "material_tuning_after.png"))
            orbited = None
            if canvas:                   # drag on the image: the camera orbits
                box = img.bounding_box()
                assert box is not None, "the canvas has no box on the page"
                cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
                page.mouse.move(cx, cy)
                page.mouse.down()
                page.mouse.move(cx + box["width"] / 4, cy, steps=8)
                page.mouse.up()
                orbited = _at_rest(page, img)
                page.screenshot(path=os.path.join(ARTEFACTS, "material_tuning_orbited.png"))
        except Exception:
            page.screenshot(path=os.path.join(ARTEFACTS, "material_tuning_failure.png"), full_page=True)
            with open(os.path.join(ARTEFACTS, "material_tuning_failure.html"), "w") as fh:
                fh.write(page.content())
            raise
        finally:
            browser.close()
    assert before.shape == after.shape
    diff = np.abs(after - before).max(axis=2)
    assert diff.max() > 10 and (diff > 10).mean() > 0.01, "the displayed image did not change"
    if orbited is not None:
        diff = np.abs(orbited - after).max(axis=2)
        assert diff.max() > 10 and (diff > 10).mean() > 0.05, "dragging on the canvas did not orbit"
