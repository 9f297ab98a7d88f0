"""The dashboard in a real browser: Playwright driving Debian's chromium headless against a real
server. Loads the page, sees the scene drawn, runs an analysis of an example, starts a plan (or,
while the planner is not part of the build, an enumeration job), sees it finish; writes a
screenshot to test-artifacts/."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from service_helpers import ROOT, free_port, start_server, stop_server

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = ROOT / "test-artifacts"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


@pytest.mark.slow
def test_dashboard_in_chromium(tmp_path: Path) -> None:
    if not CHROMIUM.exists():
        pytest.skip("no /usr/bin/chromium: install Debian's chromium (apt-get install chromium) to run the "
                    "browser test")
    from playwright.sync_api import expect, sync_playwright

    port = free_port()
    server = start_server(tmp_path, port)
    profile = tmp_path / "chromium-profile"
    try:
        with sync_playwright() as pw:
            ctx = pw.chromium.launch_persistent_context(
                str(profile), executable_path=str(CHROMIUM), headless=True, args=FLAGS,
                viewport={"width": 1280, "height": 1100})
            page = ctx.pages[0] if ctx.pages else ctx.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"http://127.0.0.1:{port}/")
            expect(page.locator("body[data-ready='1']")).to_have_count(1, timeout=30_000)
            # the planar example is drawn: two fingers of two links, five contacts with cones
            assert page.locator("#scene-view line.link").count() == 4
            assert page.locator("#scene-view circle.contact").count() == 5
            assert page.locator("#scene-view .cone").count() == 5
            # analysis of the example: the table of combinations
            page.click("#analyze-btn")
            expect(page.locator("#analysis-status")).to_contain_text("combinations feasible", timeout=60_000)
            rows = page.locator("#combo-table tbody tr")
            assert rows.count() > 0
            rows.first.click()
            expect(page.locator("#report-title")).to_contain_text("feasible", timeout=30_000)
            assert page.locator("#dafc-view circle.dafc-in").count() > 0
            # a 3-D example is drawn too, and rotates when dragged
            page.select_option("#example-select", "sphere_four_finger_palm.json")
            expect(page.locator("#scene-info")).to_contain_text("3-D", timeout=30_000)
            expect(page.locator("#scene-view line.link")).not_to_have_count(0)
            before = page.locator("#scene-view line.link").first.get_attribute("x2")
            box = page.locator("#scene-view").bounding_box()
            assert box is not None
            page.mouse.move(box["x"] + 300, box["y"] + 200)
            page.mouse.down()
            page.mouse.move(box["x"] + 380, box["y"] + 230, steps=5)
            page.mouse.up()
            assert page.locator("#scene-view line.link").first.get_attribute("x2") != before
            page.select_option("#example-select", "planar_disk_envelope.json")
            expect(page.locator("#scene-info")).to_contain_text("2-D", timeout=30_000)
            page.click("#analyze-btn")
            expect(page.locator("#analysis-status")).to_contain_text("combinations feasible", timeout=60_000)
            page.locator("#combo-table tbody tr").nth(1).click()
            expect(page.locator("#report-title")).to_contain_text("feasible", timeout=30_000)
            # a job, watched live until it finishes
            page.select_option("#goal-select", "active")
            page.click("#plan-btn")
            expect(page.locator("#job-status[data-status='succeeded']")).to_have_count(1, timeout=180_000)
            expect(page.locator("#player")).to_be_visible()
            assert page.locator("#steps li").count() > 0  # the planar grasp has a plan to active closure
            page.click("#play-btn")
            page.wait_for_timeout(500)
            assert page.locator("#torque-bars rect.torque-bar").count() > 0
            # an enumeration job, watched the same way
            page.click("#enum-btn")
            expect(page.locator("#job-status")).to_contain_text("enumeration", timeout=30_000)
            expect(page.locator("#job-status[data-status='succeeded']")).to_have_count(1, timeout=120_000)
            expect(page.locator("#analysis-status")).to_contain_text("combinations feasible")
            ARTIFACTS.mkdir(exist_ok=True)
            shot = ARTIFACTS / "dashboard.png"
            page.screenshot(path=str(shot), full_page=True)
            assert shot.stat().st_size > 10_000
            assert not errors, errors
            ctx.close()
    finally:
        stop_server(server)
        shutil.rmtree(profile, ignore_errors=True)
