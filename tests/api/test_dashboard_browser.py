"""The dashboard in a real browser: Playwright driving Debian's chromium headless against a real
server. Loads the page, sees the scene drawn, runs an analysis of an example, starts a plan (or,
while the planner is not part of the build, an enumeration job), sees it finish; writes a
screenshot to test-artifacts/."""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from service_helpers import ROOT, free_port, start_server, stop_server

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = ROOT / "test-artifacts"
# no GPU on a CI machine: WebGL through ANGLE on SwiftShader (software), which chromium only
# allows when told to; never --disable-gpu, which takes WebGL away
FLAGS = ["--headless", "--no-sandbox", "--disable-quic", "--no-first-run", "--use-angle=swiftshader",
         "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]

# counts the pixels of the 3-D canvas inside the robots' screen box that differ from the
# background, with the robots shown and hidden (the test's own reading of the canvas)
COUNT_ROBOT_PIXELS = """() => {
    const view = window.ctpDashboard.view3d();
    const count = () => {
        view.renderNow();
        const b = view.robotScreenBox(), c = document.createElement("canvas");
        c.width = view.canvas.width; c.height = view.canvas.height;
        const g = c.getContext("2d");
        g.drawImage(view.canvas, 0, 0);
        const w = b.x1 - b.x0, h = b.y1 - b.y0, px = g.getImageData(b.x0, b.y0, w, h).data;
        let n = 0;
        for (let i = 0; i < px.length; i += 4) {
            if (Math.abs(px[i] - 0xfb) + Math.abs(px[i + 1] - 0xfc) + Math.abs(px[i + 2] - 0xfd) > 24) n += 1;
        }
        return [n, w * h];
    };
    const shown = count();
    view.setRobotsVisible(false);
    const hidden = count();
    view.setRobotsVisible(true);
    view.renderNow();
    return { shown: shown[0], hidden: hidden[0], area: shown[1], context: !!view.renderer.getContext() };
}"""


@contextlib.contextmanager
def _dashboard_page(tmp_path: Path, **env: str) -> Iterator[tuple[str, Any, list[str], list[str]]]:
    """A server on a free port (``env``: its settings) and Debian's chromium on it, every request
    off this server blocked: yields ``(base URL, page, page errors, blocked URLs)``; skips without
    chromium; stops both and removes the browser profile afterwards."""
    if not CHROMIUM.exists():
        pytest.skip("no /usr/bin/chromium: install Debian's chromium (apt-get install chromium) to run the "
                    "browser test")
    from playwright.sync_api import sync_playwright

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    server = start_server(tmp_path, port, **env)
    profile = tmp_path / "chromium-profile"
    try:
        with sync_playwright() as pw:
            ctx = _chromium(pw, profile)
            blocked = _only_this_server(ctx, base)
            page = ctx.pages[0] if ctx.pages else ctx.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            yield base, page, errors, blocked
            ctx.close()
    finally:
        stop_server(server)
        shutil.rmtree(profile, ignore_errors=True)


@pytest.mark.slow
def test_dashboard_in_chromium(tmp_path: Path) -> None:
    from playwright.sync_api import expect

    with _dashboard_page(tmp_path) as (base, page, errors, blocked):
        page.goto(f"{base}/")
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
        # the DAFC in two linked panels, with axis labels and units
        assert page.locator("#dafc-trans circle").count() == page.locator("#dafc-rot circle").count() > 0
        assert "[m]" in (page.locator("#dafc-trans").text_content() or "")
        assert "[rad]" in (page.locator("#dafc-rot").text_content() or "")
        page.locator("#dafc-trans circle.dafc-in").last.hover()  # the topmost of coinciding samples
        assert page.locator("#dafc-rot circle.hl").count() == 1  # the same sample, in the other panel
        expect(page.locator("#dafc-caption")).to_contain_text("rad")
        # the report as the CLI prints it: stationary torques by joint name and unit, DPFC, regrasp
        report = page.locator("#report-text").inner_text()
        for part in ("stationary grasp (18", "left/joint 0", "[N·m]", "DPFC (28)", "regrasp cone (33)"):
            assert part in report, (part, report)
        # the reason column, search and paging (a table of 12,000 rows stays paged)
        assert page.locator("#combo-table thead th").nth(2).inner_text() == "reason"
        page.uncheck("#feasible-only")
        n_rows = page.evaluate("window.ctpDashboard.state.rows.length")
        expect(page.locator("#page-info")).to_contain_text(f"of {n_rows} ")
        expect(page.locator("#combo-table tbody tr")).to_have_count(min(n_rows, 100))
        page.fill("#combo-search", "FSFSS")
        expect(page.locator("#combo-table tbody tr")).to_have_count(1)
        page.fill("#combo-search", "F?FS?")  # ? = any state
        assert 1 < page.locator("#combo-table tbody tr").count() <= 9
        assert page.locator("#combo-table tbody tr td.reason").first.inner_text()
        page.fill("#combo-search", "")
        page.evaluate("""() => {
            const letters = "FSD", rows = [];
            for (let i = 0; i < 12000; i++) {
                let c = "", k = i;
                for (let j = 0; j < 9; j++) { c += letters[k % 3]; k = Math.floor(k / 3); }
                rows.push({combination: c, feasible: i % 7 === 0,
                           reason: i % 7 ? "no stationary grasp" : "feasible",
                           dim_dafc: 1, dim_dpfc: 2, example_direction: null});
            }
            window.ctpDashboard.showRows({combinations: rows, feasible: rows.filter((r) => r.feasible).length});
        }""")
        expect(page.locator("#combo-table tbody tr")).to_have_count(100)
        expect(page.locator("#page-info")).to_contain_text("of 12000")
        page.click("#page-next")
        expect(page.locator("#page-info")).to_contain_text("rows 101–200")
        page.fill("#combo-search", "FFFFFFFFF")
        expect(page.locator("#combo-table tbody tr")).to_have_count(1)
        page.check("#feasible-only")
        # a 3-D example is drawn in WebGL, and the camera orbits when dragged
        page.select_option("#example-select", "sphere_four_finger_palm.json")
        expect(page.locator("#scene-info")).to_contain_text("3-D", timeout=30_000)
        expect(page.locator("body[data-scene-ready='1']")).to_have_count(1, timeout=60_000)
        expect(page.locator("#scene-3d canvas")).to_be_visible()
        expect(page.locator("#scene-view")).to_be_hidden()
        n_contacts = page.evaluate("window.ctpDashboard.state.scene.contacts.length")
        assert page.locator("#scene-3d").get_attribute("data-contacts") == str(n_contacts)
        cam = "window.ctpDashboard.view3d().camera.position.toArray()"
        before = page.evaluate(cam)
        box = page.locator("#scene-3d canvas").bounding_box()
        assert box is not None
        page.mouse.move(box["x"] + 300, box["y"] + 200)
        page.mouse.down()
        page.mouse.move(box["x"] + 380, box["y"] + 230, steps=5)
        page.mouse.up()
        after = page.evaluate(cam)
        assert max(abs(a - b) for a, b in zip(after, before, strict=True)) > 1e-3, (before, after)
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#scene-3d").screenshot(path=str(ARTIFACTS / "dashboard-3d-sphere.png"))
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
        expect(page.locator("#player[data-frames]")).to_have_count(1, timeout=60_000)  # its frames loaded
        expect(page.locator("#player")).to_be_visible()
        assert page.locator("#steps li").count() > 0  # the planar grasp has a plan to active closure
        # the job id is shown in full, and the API knows it by what is shown
        job_id = page.locator("#job-status").get_attribute("data-job-id")
        assert job_id and job_id in page.locator("#job-status").inner_text()
        assert page.request.get(f"{base}/plans/{job_id}").status == 200
        # frame 0 of the plan: the contact markers carry the plan's states, as the chips do
        chips = [t.rsplit(": ", 1)[1] for t in page.locator("#contact-states .chip").all_inner_texts()]
        marks = [m.get_attribute("data-state") for m in page.locator("#scene-view circle.contact").all()]
        assert marks == chips, (marks, chips)
        # the plan as an animation: frames between the waypoints, no jumps, contacts in every frame
        frames = page.evaluate("""() => window.ctpDashboard.state.frames.map((f) => ({
            step: f.step, links: f.fingers.flatMap((fi) => fi.links.flatMap((l) => [...l.a, ...l.b])),
            contacts: f.contacts.map((c) => [c.state, c.normal !== null, ...c.point]) }))""")
        waypoints = page.evaluate(
            "window.ctpDashboard.state.plan.steps.reduce((s, x) => s + x.joint_path.length, 0)")
        assert len(frames) > waypoints, (len(frames), waypoints)
        assert all(f["contacts"] and all(c[1] for c in f["contacts"]) for f in frames)
        jumps = [max(abs(a - b) for a, b in zip(f["links"], g["links"], strict=True))
                 for f, g in itertools.pairwise(frames)]
        assert max(jumps) < 0.05, max(jumps)  # metres per frame, on a scene a metre across
        svg0 = page.locator("#scene-view").inner_html()
        page.screenshot(path=str(ARTIFACTS / "dashboard-plan-frame0.png"), full_page=True)
        page.click("#play-btn")
        page.wait_for_timeout(800)
        assert page.locator("#torque-bars rect.torque-bar").count() > 0
        names = page.locator("#torque-bars text.joint-name").all_text_contents()
        assert names[:2] == ["left/joint 0", "left/joint 1"], names
        playing = int(page.locator("#player").get_attribute("data-frame") or 0)
        assert playing > 0
        assert page.locator("#scene-view").inner_html() != svg0
        # colours of the current frame: the markers carry the frame's states, as the chips do
        chips = [t.rsplit(": ", 1)[1] for t in page.locator("#contact-states .chip").all_inner_texts()]
        marks = [m.get_attribute("data-state") for m in page.locator("#scene-view circle.contact").all()]
        assert marks == chips and len(marks) > 0, (marks, chips)
        page.screenshot(path=str(ARTIFACTS / "dashboard-plan-playing.png"), full_page=True)
        page.click("#play-btn")  # pause
        # the step list is clickable: the last step is shown
        n_steps = page.locator("#steps li").count()
        page.locator("#steps li button").last.click()
        expect(page.locator("#steps li.current")).to_have_count(1)
        assert page.locator("#steps li").nth(n_steps - 1).get_attribute("class") == "current"
        expect(page.locator("#frame-label")).to_contain_text(f"step {n_steps - 1} ")
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
        assert not blocked, blocked


def _chromium(pw: Any, profile: Path) -> Any:
    return pw.chromium.launch_persistent_context(
        str(profile), executable_path=str(CHROMIUM), headless=True, args=FLAGS,
        viewport={"width": 1280, "height": 1100})


def _only_this_server(ctx: Any, base: str) -> list[str]:
    """Every request of the browser context that is not to ``base`` is aborted and listed."""
    blocked: list[str] = []

    def route(r: Any) -> None:
        if r.request.url.startswith(base + "/"):
            r.continue_()
        else:
            blocked.append(r.request.url)
            r.abort()

    ctx.route("**/*", route)
    return blocked


@pytest.mark.slow
def test_docs_offline_and_job_state(tmp_path: Path) -> None:
    """/docs renders Swagger UI with every request off this server blocked; the vendored modules
    load through the import map; picking another example while a plan runs leaves no page error
    and no plan of the old scene; a plan job that finds no plan reads "no plan"."""
    from playwright.sync_api import expect

    with _dashboard_page(tmp_path) as (base, page, errors, blocked):
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
        # two planner options ticked (box-object edges: the disk's plan is the same) go with the plan
        page.click("#plan-options summary")
        page.check("#plan-options input[data-option='contact_slides']")
        page.check("#plan-options input[data-option='link_replacement']")
        # an effort weight below 0 is refused on the page: said so, no plan posted
        posted: list[str] = []
        page.on("request", lambda r: posted.append(r.url) if r.method == "POST" else None)
        page.fill("#effort-weight", "-1")
        page.click("#plan-btn")
        expect(page.locator("#job-error")).to_contain_text("effort_weight: a number >= 0")
        assert not posted, posted
        page.fill("#effort-weight", "0")  # 0 is sent as a number (empty: not sent, the planner's 0.1)
        with page.expect_request(lambda r: r.method == "POST" and r.url.endswith("/plans")) as sent:
            page.click("#plan-btn")
        assert json.loads(sent.value.post_data or "{}")["options"] == {"contact_slides": True,
                                                                       "link_replacement": True, "effort_weight": 0}
        page.uncheck("#plan-options input[data-option='contact_slides']")  # the later plans without them
        page.uncheck("#plan-options input[data-option='link_replacement']")
        page.fill("#effort-weight", "")
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
        # the Allegro hand in WebGL with its real meshes, served by this server (nothing else reachable)
        page.select_option("#example-select", "allegro_right_box.json")
        expect(page.locator("#scene-info")).to_contain_text("3-D", timeout=30_000)
        expect(page.locator("body[data-scene-ready='1']")).to_have_count(1, timeout=120_000)
        assert page.locator("#scene-3d").get_attribute("data-robots") == "1"
        assert int(page.locator("#scene-3d").get_attribute("data-meshes") or 0) >= 16
        assert page.locator("#scene-error").inner_text() == ""
        # the meshes sit where /scenes/geometry puts the links (urdf-loader's and pinocchio's kinematics)
        gap = page.evaluate("""() => {
            const o = window.ctpDashboard.view3d().linkOrigins(), g = window.ctpDashboard.state.geometry;
            let worst = 0, n = 0;
            for (const f of g.frames[0].fingers) for (const l of f.links) {
                if (!o[l.body]) continue;
                n += 1;
                worst = Math.max(worst, Math.hypot(...o[l.body].map((x, i) => x - l.a[i])));
            }
            return [worst, n];
        }""")
        assert gap[1] >= 8 and gap[0] < 1e-4, gap
        px = page.evaluate(COUNT_ROBOT_PIXELS)
        assert px["context"], px
        assert px["shown"] > 0.05 * px["area"] and px["shown"] > px["hidden"] + 0.03 * px["area"], px
        page.locator("#scene-3d").screenshot(path=str(ARTIFACTS / "dashboard-3d-allegro.png"))
        # a frame of another configuration (as a plan's animation shows it): the meshes move to where
        # /scenes/geometry puts the links for that configuration, and the picture changes
        moved = page.evaluate("""async () => {
            const d = window.ctpDashboard, view = d.view3d(), scene = d.state.scene;
            const q = d.state.geometry.frames[0].q.map((x, i) => (i < 4 ? x - 0.4 : x));
            const r = await fetch("/scenes/geometry", {
                method: "POST", headers: {"content-type": "application/json"},
                body: JSON.stringify({scene, configurations: [q]})});
            const g = await r.json();
            const grab = () => { view.renderNow(); return view.canvas.toDataURL(); };
            const before = grab();
            view.update({index: 1, fingers: g.frames[0].fingers, q, pose: null, contacts: [], stateOf: {}});
            const after = grab(), o = view.linkOrigins();
            let worst = 0, n = 0;
            for (const f of g.frames[0].fingers) for (const l of f.links) {
                if (!o[l.body]) continue;
                n += 1;
                worst = Math.max(worst, Math.hypot(...o[l.body].map((x, i) => x - l.a[i])));
            }
            return {worst, n, differs: before !== after};
        }""")
        assert moved["differs"] and moved["n"] >= 8 and moved["worst"] < 1e-4, moved
        page.select_option("#example-select", "planar_disk_envelope.json")
        page.select_option("#example-select", "allegro_right_box.json")
        expect(page.locator("body[data-scene-ready='1']")).to_have_count(1, timeout=120_000)
        # the Allegro grasp has no plan to active closure: the job succeeds, the page says "no plan"
        page.click("#plan-btn")
        expect(page.locator("#job-status[data-status='no-plan']")).to_have_count(1, timeout=300_000)
        status_text = page.locator("#job-status").inner_text()
        assert "no plan" in status_text and "succeeded" not in status_text, status_text
        page.screenshot(path=str(ARTIFACTS / "dashboard-no-plan.png"), full_page=True)
        # a cancelled job reads "cancelled", with nothing to play
        page.click("#plan-btn")
        expect(page.locator("#cancel-btn")).to_be_enabled(timeout=30_000)
        page.click("#cancel-btn")
        expect(page.locator("#job-status[data-status='cancelled']")).to_have_count(1, timeout=60_000)
        assert "cancelled" in page.locator("#job-status").inner_text()
        expect(page.locator("#player")).to_be_hidden()
        assert not errors, errors
        assert not blocked, blocked


def _robot_archive(path: Path) -> Path:
    """The Panda of example-robot-data as an archive a user would upload: its own package
    ``my_arm`` (visual and collision meshes), the URDFs' mesh URIs pointing into it."""
    import tarfile

    from analysis.urdf import example_robot_data_dir

    erd = example_robot_data_dir()
    assert erd is not None
    with tarfile.open(path, "w:gz") as t:
        for p in sorted((erd / "panda_description").rglob("*")):
            if not p.is_file():
                continue
            data = p.read_bytes()
            if p.suffix == ".urdf":
                data = data.replace(b"package://example-robot-data/robots/panda_description/", b"package://my_arm/")
            info = tarfile.TarInfo("my_arm/" + p.relative_to(erd / "panda_description").as_posix())
            info.size = len(data)
            t.addfile(info, io.BytesIO(data))
    return path


@pytest.mark.slow
def test_an_uploaded_robot_is_placed_and_drawn(tmp_path: Path) -> None:
    """Upload a URDF archive on the dashboard, pick its chain, place its forearm on the current
    example's box: the found scene (robot:<hash>/... URDF, a contact on the touched link) is drawn
    in WebGL with the upload's own meshes, with every request off this server blocked."""
    from playwright.sync_api import expect

    archive = _robot_archive(tmp_path / "my_arm.tar.gz")
    with _dashboard_page(tmp_path, CTP_DATA_DIR=str(tmp_path / "data")) as (base, page, errors, blocked):
        page.goto(f"{base}/")
        expect(page.locator("body[data-ready='1']")).to_have_count(1, timeout=30_000)
        page.select_option("#example-select", "panda_forearm_box.json")  # the box and table to use
        expect(page.locator("body[data-scene-ready='1']")).to_have_count(1, timeout=120_000)
        page.click("#robot-panel summary")
        page.set_input_files("#robot-file", str(archive))
        expect(page.locator("#robot-chain")).to_be_visible(timeout=60_000)
        assert page.locator("#robot-error").inner_text() == ""
        page.select_option("#robot-urdf", label="my_arm/urdf/panda.urdf")
        page.select_option("#robot-root", "panda_link0")
        page.select_option("#robot-tip", "panda_link7")
        page.select_option("#robot-touch", "panda_link4")
        page.click("#robot-detect")
        page.wait_for_function(
            "() => document.getElementById('scene-info').textContent.includes('contacts found')"
            " || document.getElementById('robot-error').textContent !== ''", timeout=120_000)
        assert page.locator("#robot-error").inner_text() == "", page.locator("#robot-error").inner_text()
        expect(page.locator("body[data-scene-ready='1']")).to_have_count(1, timeout=120_000)
        assert page.locator("#robot-error").inner_text() == ""
        scene = page.evaluate("() => window.ctpDashboard.state.scene")
        assert scene["fingers"][0]["urdf"]["file"].startswith("robot:")
        assert "robot/panda_link4" in [c["body"] for c in scene["contacts"]], scene["contacts"]
        # the upload's own meshes, fetched from /robots/<hash>/files/..., in WebGL
        assert page.locator("#scene-3d").get_attribute("data-robots") == "1"
        assert int(page.locator("#scene-3d").get_attribute("data-meshes") or 0) >= 8
        assert page.locator("#scene-error").inner_text() == ""
        pixels = page.evaluate(COUNT_ROBOT_PIXELS)
        assert pixels["context"] and pixels["shown"] > pixels["hidden"] + 100, pixels
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "dashboard-uploaded-robot.png"), full_page=True)
        assert not blocked, blocked
        assert not errors, errors


# the three.js objects of the player's object paths and ghost, read from the scene graph
READ_PATHS = """() => {
    const view = window.ctpDashboard.view3d();
    const find = (name) => view.root.getObjectByName(name);
    const pos = (o) => (o ? Array.from(o.geometry.attributes.position.array) : null);
    const ghost = find("ghost:replay");
    return { replay: pos(find("path:replay")), planned: pos(find("path:planned")),
             ghost: ghost ? { visible: ghost.visible, matrix: ghost.matrix.toArray() } : null };
}"""

# pixels of the 3-D canvas near the MuJoCo path colour (#c2185b), and a hash of the whole canvas
COUNT_REPLAY_PIXELS = """() => {
    const view = window.ctpDashboard.view3d();
    view.renderNow();
    const c = document.createElement("canvas");
    c.width = view.canvas.width; c.height = view.canvas.height;
    const g = c.getContext("2d");
    g.drawImage(view.canvas, 0, 0);
    const px = g.getImageData(0, 0, c.width, c.height).data;
    let n = 0, h = 0;
    for (let i = 0; i < px.length; i += 4) {
        if (Math.abs(px[i] - 0xc2) + Math.abs(px[i + 1] - 0x18) + Math.abs(px[i + 2] - 0x5b) < 60) n += 1;
        h = (h * 31 + px[i] + 7 * px[i + 1] + 13 * px[i + 2]) % 1000000007;
    }
    return { replay: n, hash: h };
}"""


@pytest.mark.slow
def test_a_replayed_3d_plan_plays_with_the_mujoco_path(tmp_path: Path) -> None:
    """A 3-D plan asked with the MuJoCo replay (the sphere example to active closure: five steps,
    the last lifts the sphere 2 cm off the palm; 20-60 s to plan on 2 shared cores, 5 s of CPU to
    replay): the MuJoCo object path is a three.js line of as many points as the result's sampled
    path, at its positions; the ghost follows the frames; the animation advances and changes the
    picture; the errors are shown with units; then the planar plan to active closure, whose lift
    the SVG view draws planned and simulated. (The only quicker 3-D plan found, goal FFFDF, is one
    release step of two frames in which the sphere moves by 1e-5 m: nothing to see.)"""
    import numpy as np
    from playwright.sync_api import expect

    with _dashboard_page(tmp_path) as (base, page, errors, blocked):
        page.goto(f"{base}/")
        expect(page.locator("body[data-ready='1']")).to_have_count(1, timeout=30_000)
        page.select_option("#example-select", "sphere_four_finger_palm.json")
        expect(page.locator("#scene-info")).to_contain_text("3-D", timeout=30_000)
        expect(page.locator("body[data-scene-ready='1']")).to_have_count(1, timeout=60_000)
        expect(page.locator("#goal-combination")).to_be_hidden()
        page.select_option("#goal-select", "combination")
        expect(page.locator("#goal-combination")).to_be_visible()
        page.select_option("#goal-select", "active")
        page.check("#replay-check")
        page.click("#plan-btn")
        expect(page.locator("#job-status[data-status='succeeded']")).to_have_count(1, timeout=400_000)
        expect(page.locator("#player[data-frames]")).to_have_count(1, timeout=60_000)
        job_id = page.locator("#job-status").get_attribute("data-job-id")
        result = page.request.get(f"{base}/plans/{job_id}/result").json()
        rep = result["replay"]
        assert rep["status"] == "done" and not rep["dropped"], rep.get("error")
        poses = np.asarray(rep["object_path"]["poses"])  # (T, 6)
        # the replay's outcome in words, with units
        expect(page.locator("#replay-panel")).to_be_visible()
        info = page.locator("#replay-info").inner_text()
        assert f"{len(poses)} samples" in info and "object dropped: no" in info, info
        assert " m (" in info and " rad (" in info and "within the 5.0 % tolerance" in info, info
        legend = page.locator("#path-legend").inner_text()
        assert "planned object path" in legend and "MuJoCo object path" in legend
        assert "MuJoCo moved" in page.locator("#steps li .replay-step").first.inner_text()
        # the three.js scene: the MuJoCo path has one point per sample, at the sample's position
        drawn = page.evaluate(READ_PATHS)
        pts = np.asarray(drawn["replay"]).reshape(-1, 3)
        assert pts.shape == (len(poses), 3)
        np.testing.assert_allclose(pts, poses[:, :3], atol=1e-6)  # float32 buffer of metres
        planned = [result["start_pose"], *[p for s in result["steps"] for p in s["object_path"]]]
        np.testing.assert_allclose(np.asarray(drawn["planned"]).reshape(-1, 3),
                                   np.asarray(planned)[:, :3], atol=1e-6)
        assert drawn["ghost"] is not None and drawn["ghost"]["visible"]
        # ghost at frame 0: where step 0 starts in MuJoCo, the last sample of the start ramp
        # (the object settled under the holding torque, a few micrometres below the scene's pose)
        first = rep["object_path"]["steps"].index(0)
        assert rep["object_path"]["steps"][first - 1] == -1
        np.testing.assert_allclose(np.asarray(drawn["ghost"]["matrix"])[12:15], poses[first - 1, :3], atol=1e-6)
        assert page.locator("#scene-3d").get_attribute("data-replay-points") == str(len(poses))
        # the zoomed inset: both paths (the lift is 2 cm, a few pixels in the 3-D view) and both dots
        assert page.locator("#path-inset polyline.inset-replay").get_attribute("data-points") == str(len(poses))
        assert page.locator("#path-inset polyline.inset-planned").get_attribute("data-points") == str(len(planned))
        assert page.locator("#path-inset circle.inset-now-replay").count() == 1
        assert "z up [m]" in (page.locator("#path-inset").text_content() or "")  # the lift is vertical
        px0 = page.evaluate(COUNT_REPLAY_PIXELS)
        assert px0["replay"] > 0, px0  # the MuJoCo path's dots and the ghost are on the canvas
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#scene-3d").screenshot(path=str(ARTIFACTS / "dashboard-3d-replay-frame0.png"))
        # play: the frames advance, the finger moves (the canvas changes), the ghost follows
        n_frames = int(page.locator("#player").get_attribute("data-frames") or 0)
        assert n_frames > 2
        page.click("#play-btn")
        page.wait_for_function("Number(document.querySelector('#player').dataset.frame) >= "
                               f"{n_frames - 1}", timeout=60_000)
        last = page.evaluate(COUNT_REPLAY_PIXELS)
        assert last["hash"] != px0["hash"]
        ghost = [float(x) for x in (page.locator("#scene-3d").get_attribute("data-ghost") or "").split()]
        np.testing.assert_allclose(ghost[:3], poses[-1, :3], atol=1e-6)  # the last frame: the final pose
        page.locator("#scene-3d").screenshot(path=str(ARTIFACTS / "dashboard-3d-replay-last.png"))
        page.locator("#plan-panel").screenshot(path=str(ARTIFACTS / "dashboard-3d-replay-player.png"))
        # a 2-D plan with its replay: the lift drawn planned (dashed) and simulated, and a ghost
        page.select_option("#example-select", "planar_disk_envelope.json")
        expect(page.locator("#scene-info")).to_contain_text("2-D", timeout=30_000)
        expect(page.locator("#replay-panel")).to_be_hidden()
        page.select_option("#goal-select", "active")
        expect(page.locator("#goal-combination")).to_be_hidden()
        page.click("#plan-btn")  # the box is still checked
        expect(page.locator("#job-status[data-status='succeeded']")).to_have_count(1, timeout=180_000)
        expect(page.locator("#player[data-frames]")).to_have_count(1, timeout=60_000)
        job_id = page.locator("#job-status").get_attribute("data-job-id")
        rep2 = page.request.get(f"{base}/plans/{job_id}/result").json()["replay"]
        assert rep2["status"] == "done", rep2.get("error")
        line = page.locator("#scene-view polyline.replay-path")
        assert line.get_attribute("data-points") == str(len(rep2["object_path"]["poses"]))
        assert page.locator("#scene-view polyline.planned-path").count() == 1
        assert page.locator("#path-inset polyline.inset-replay").get_attribute("data-points") == str(
            len(rep2["object_path"]["poses"]))
        page.evaluate("window.ctpDashboard.setFrame(window.ctpDashboard.state.frames.length - 1)")
        g = page.locator("#scene-view g.replay-ghost")
        expect(g).to_have_count(1)
        shown = [float(x) for x in (g.get_attribute("data-pose") or "").split()]
        np.testing.assert_allclose(shown, rep2["simulated_final_pose"], atol=1e-6)  # the last frame
        assert shown[1] > rep2["start_pose"][1] + 0.9 * rep2["planned"][1] > rep2["start_pose"][1]  # lifted
        page.screenshot(path=str(ARTIFACTS / "dashboard-2d-replay.png"), full_page=True)
        assert not errors, errors
        assert not blocked, blocked
