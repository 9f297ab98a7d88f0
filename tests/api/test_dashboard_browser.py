"""The dashboard in a real browser: Playwright driving Debian's chromium headless against a real
server. Loads the page, sees the scene drawn, runs an analysis of an example, starts a plan (or,
while the planner is not part of the build, an enumeration job), sees it finish; writes a
screenshot to test-artifacts/."""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Any

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
            # the job id is shown in full, and the API knows it by what is shown
            job_id = page.locator("#job-status").get_attribute("data-job-id")
            assert job_id and job_id in page.locator("#job-status").inner_text()
            assert page.request.get(f"http://127.0.0.1:{port}/plans/{job_id}").status == 200
            # frame 0 of the plan: the contact markers carry the plan's states, as the chips do
            chips = [t.rsplit(": ", 1)[1] for t in page.locator("#contact-states .chip").all_inner_texts()]
            marks = [m.get_attribute("data-state") for m in page.locator("#scene-view circle.contact").all()]
            assert marks == chips, (marks, chips)
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


def _chromium(pw: Any, profile: Path) -> Any:
    return pw.chromium.launch_persistent_context(
        str(profile), executable_path=str(CHROMIUM), headless=True, args=FLAGS,
        viewport={"width": 1280, "height": 1100})


@pytest.mark.slow
def test_docs_offline_and_job_state(tmp_path: Path) -> None:
    """/docs renders Swagger UI with every request off this server blocked; the vendored modules
    load through the import map; picking another example while a plan runs leaves no page error
    and no plan of the old scene; a plan job that finds no plan reads "no plan"."""
    if not CHROMIUM.exists():
        pytest.skip("no /usr/bin/chromium: install Debian's chromium (apt-get install chromium) to run the "
                    "browser test")
    from playwright.sync_api import expect, sync_playwright

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    server = start_server(tmp_path, port)
    profile = tmp_path / "chromium-profile"
    try:
        with sync_playwright() as pw:
            ctx = _chromium(pw, profile)
            blocked: list[str] = []

            def only_this_server(route: Any) -> None:
                if route.request.url.startswith(base + "/"):
                    route.continue_()
                else:
                    blocked.append(route.request.url)
                    route.abort()

            ctx.route("**/*", only_this_server)
            page = ctx.pages[0] if ctx.pages else ctx.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{base}/docs")
            expect(page.locator(".swagger-ui .info .title")).to_contain_text("Contact-state transition planner",
                                                                             timeout=30_000)
            expect(page.locator(".opblock-summary-path[data-path='/plans']").first).to_be_visible()
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "docs-offline.png"))
            assert not blocked, blocked
            # a plan started on the planar example, then another example picked at once
            page.goto(f"{base}/")
            expect(page.locator("body[data-ready='1']")).to_have_count(1, timeout=30_000)
            # the vendored ES modules load through index.html's import map, from this server only
            loaded = page.evaluate("""async () => {
                const THREE = await import("three");
                const { OrbitControls } = await import("three/addons/controls/OrbitControls.js");
                const { default: URDFLoader } = await import("urdf-loader");
                return [THREE.REVISION, typeof OrbitControls, typeof URDFLoader, typeof new URDFLoader().parse];
            }""")
            assert loaded == ["187", "function", "function", "function"], loaded
            page.click("#plan-btn")
            expect(page.locator("#job-status[data-job-id]")).to_have_count(1, timeout=30_000)
            job_id = page.locator("#job-status").get_attribute("data-job-id")
            page.select_option("#example-select", "sphere_four_finger_palm.json")
            expect(page.locator("#scene-info")).to_contain_text("3-D", timeout=30_000)
            expect(page.locator("#job-status")).to_have_text("no job")
            deadline = time.monotonic() + 180
            while True:  # the old job runs to its end on the server ...
                status = page.request.get(f"{base}/plans/{job_id}").json()["status"]
                if status in ("succeeded", "failed", "cancelled") or time.monotonic() > deadline:
                    break
                page.wait_for_timeout(300)
            assert status == "succeeded"
            page.wait_for_timeout(1500)  # ... and the page, had it kept polling, would have loaded it
            expect(page.locator("#player")).to_be_hidden()
            assert page.locator("#steps li").count() == 0
            expect(page.locator("#job-status")).to_have_text("no job")
            page.screenshot(path=str(ARTIFACTS / "dashboard-scene-switch.png"), full_page=True)
            # the Allegro grasp has no plan to active closure: the job succeeds, the page says "no plan"
            page.select_option("#example-select", "allegro_right_box.json")
            expect(page.locator("#scene-info")).to_contain_text("3-D", timeout=30_000)
            page.click("#plan-btn")
            expect(page.locator("#job-status[data-status='no-plan']")).to_have_count(1, timeout=300_000)
            status_text = page.locator("#job-status").inner_text()
            assert "no plan" in status_text and "succeeded" not in status_text, status_text
            page.screenshot(path=str(ARTIFACTS / "dashboard-no-plan.png"), full_page=True)
            assert not errors, errors
            assert not blocked, blocked
            ctx.close()
    finally:
        stop_server(server)
        shutil.rmtree(profile, ignore_errors=True)
