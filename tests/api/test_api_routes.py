"""Every route of the service through TestClient: status codes and payloads, on real workers."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cube_planes import cube_in_planes
from fastapi.testclient import TestClient
from service_helpers import example, settings_for, wait_for

from analysis.combination import analyze_combination
from analysis.contacts import build_system
from analysis.enumerate import enumerate_combinations
from analysis.exceptions import SceneError
from analysis.loader import scene_from_dict
from api.main import create_app

PLANAR = example("planar_disk_envelope")


# -- health, examples, dashboard ---------------------------------------------------------------


def test_health(client: TestClient) -> None:
    r = client.get("/health")
    assert r.status_code == 200
    body = r.json()
    assert body["status"] == "ok" and body["database"] == "sqlite"
    assert body["analysis_workers"] == 1 and body["executor"] == "processes (1)"


def test_examples_are_valid_scenes(client: TestClient) -> None:
    r = client.get("/scenes/examples")
    assert r.status_code == 200
    items = r.json()
    names = {i["file"] for i in items}
    assert {"planar_disk_envelope.json", "sphere_four_finger_palm.json"} <= names
    for item in items:
        sc = scene_from_dict(item["scene"])
        assert item["dim"] == sc.dim and item["contacts"] == len(sc.contacts)


def test_dashboard_and_openapi(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and "text/html" in r.headers["content-type"]
    assert "/static/app.js" in r.text
    assert client.get("/static/app.js").status_code == 200
    spec = client.get("/openapi.json").json()
    for path in ("/analyses", "/plans", "/plans/{plan_id}", "/plans/{plan_id}/result", "/scenes/examples",
                 "/health", "/enumerations"):
        assert path in spec["paths"], path
    assert client.get("/docs").status_code == 200


# -- POST /analyses ----------------------------------------------------------------------------


def test_analysis_table_matches_the_enumeration(client: TestClient) -> None:
    r = client.post("/analyses", json={"scene": PLANAR})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["kind"] == "enumeration" and body["scene"] == "planar-disk-envelope"
    expected, _ = enumerate_combinations(build_system(scene_from_dict(PLANAR)), workers=1)
    assert [row["combination"] for row in body["combinations"]] == [s.combination for s in expected]
    assert [row["feasible"] for row in body["combinations"]] == [s.feasible for s in expected]
    assert body["feasible"] == sum(s.feasible for s in expected) > 0
    assert body["semantics"]


def test_analysis_of_one_combination(client: TestClient) -> None:
    system = build_system(scene_from_dict(PLANAR))
    feasible = next(s for s in enumerate_combinations(system, workers=1)[0] if s.feasible)
    r = client.post("/analyses", json={"scene": PLANAR, "combination": feasible.combination})
    assert r.status_code == 200, r.text
    rep = r.json()["report"]
    ref = analyze_combination(system, feasible.combination).to_json()
    assert rep["combination"] == feasible.combination and rep["feasible"] is True
    assert rep["dafc"]["dim"] == ref["dafc"]["dim"]
    np.testing.assert_allclose(rep["stationary"]["tau"], ref["stationary"]["tau"], atol=1e-9)
    # with a direction: the torque set for that direction
    d = rep["example_direction"]
    r2 = client.post("/analyses", json={"scene": PLANAR, "combination": feasible.combination, "direction": d,
                                        "nu": 0.8})
    assert r2.status_code == 200, r2.text
    rep2 = r2.json()["report"]
    assert rep2["direction_test"]["member"] is True
    assert "friction_uncertainty" in rep2


@pytest.mark.parametrize(
    ("mutate", "field"),
    [
        (lambda s: s["contacts"][2].__setitem__("normal", [1.0, 1.0]), "scene.contacts.2.normal"),
        (lambda s: s["contacts"][1].__setitem__("body", "thumb/0"), "scene.contacts.1.body"),
        (lambda s: s["contacts"][0].__setitem__("mu", -0.5), "scene.contacts.0.mu"),
        (lambda s: s["contacts"][0].__setitem__("point", [0.1, 0.2, 0.3]), "scene.contacts.0.point"),
        (lambda s: s["fingers"][0]["links"][0].__setitem__("length", -1), "scene.fingers.0.links.0.length"),
        (lambda s: s.__setitem__("dim", 4), "scene.dim"),
        # contacts omitted are found from the geometry (issue 10); here the object touches nothing
        (lambda s: (s.pop("contacts"), s["object"]["pose"].__setitem__("position", [0.0, 3.0])), "scene.contacts"),
        (lambda s: s["object"]["shape"].__setitem__("radius", "big"), "scene.object.shape.radius"),
    ],
)
def test_bad_scene_is_422_naming_the_field(client: TestClient, mutate: object, field: str) -> None:
    scene = copy.deepcopy(PLANAR)
    mutate(scene)  # type: ignore[operator]
    r = client.post("/analyses", json={"scene": scene})
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["detail"].startswith(field + ":"), body["detail"]
    assert [str(p) for p in body["errors"][0]["loc"]] == field.split(".")


def test_nan_and_malformed_json_are_422(client: TestClient) -> None:
    scene = copy.deepcopy(PLANAR)
    scene["external_wrench"] = [0.0, math.nan, 0.0]
    r = client.post("/analyses", content=json.dumps({"scene": scene}), headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.json()["detail"].startswith("scene.external_wrench.1:")
    r = client.post("/analyses", content=b'{"scene": {', headers={"content-type": "application/json"})
    assert r.status_code == 422 and "JSON" in r.json()["detail"]
    r = client.post("/analyses", content=b"\xff\xfe{", headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.json()["detail"].startswith("body:")
    r = client.post("/analyses", json={"scene": PLANAR, "extra": 1})
    assert r.status_code == 422 and r.json()["detail"].startswith("extra:")


@pytest.mark.parametrize(
    ("extra", "field"),
    [
        ({"combination": "FFDD"}, "combination"),
        ({"combination": "FFDDX"}, "combination"),
        ({"combination": "FFDDN"}, "combination.4"),  # N on a frictional contact
        ({"combination": "FFDDF", "direction": [1.0, 0.0]}, "direction"),
        ({"direction": [1.0, 0.0, 0.0]}, "direction"),
        ({"nu": 0.5}, "nu"),
        ({"combination": "FFDDF", "nu": 2.0}, "nu"),
    ],
)
def test_bad_request_fields_are_422(client: TestClient, extra: dict[str, object], field: str) -> None:
    r = client.post("/analyses", json={"scene": PLANAR, **extra})
    assert r.status_code == 422, r.text
    assert r.json()["detail"].startswith(field + ":"), r.json()["detail"]


def test_urdf_outside_the_package_is_refused(client: TestClient) -> None:
    scene = example("allegro_right_box")
    scene["fingers"][0]["urdf"]["file"] = "/etc/passwd"
    r = client.post("/analyses", json={"scene": scene})
    assert r.status_code == 422 and "fingers.0.urdf.file" in r.json()["detail"]


def test_allegro_urdf_scene_is_analysed(client: TestClient) -> None:
    r = client.post("/analyses", json={"scene": example("allegro_right_box")})
    assert r.status_code == 200, r.text
    assert len(r.json()["combinations"]) == 3 ** 6


def test_too_many_contacts_is_413_with_the_limit(client: TestClient) -> None:
    r = client.post("/analyses", json={"scene": example("sphere_four_finger_wrap")})  # 9 contacts > 6
    assert r.status_code == 413
    assert r.json()["limit"] == 6 and "max_contacts" in r.json()["detail"]
    r = client.post("/enumerations", json={"scene": example("sphere_four_finger_wrap")})
    assert r.status_code == 413


def test_the_contact_limit_is_for_enumerations_only(client: TestClient) -> None:
    # a cube in a corner of five planes: 20 contacts, over this server's max_contacts (6)
    cube = cube_in_planes(5)
    letters = "F" * 4 + "D" * 16  # on the floor only: the floor carries the weight, nothing moves
    r = client.post("/analyses", json={"scene": cube, "combination": letters})
    assert r.status_code == 200, r.text
    report = r.json()["report"]
    assert report["combination"] == letters and report["motion_space"]["a_bar"] == 0
    assert report["stationary"] is not None and not report["feasible"]
    assert client.post("/analyses", json={"scene": cube}).status_code == 413
    assert client.post("/enumerations", json={"scene": cube}).status_code == 413


def test_body_too_large_is_413(client: TestClient) -> None:
    big = {"scene": {**PLANAR, "description": "x" * 300_000}}
    r = client.post("/analyses", json=big)
    assert r.status_code == 413 and r.json()["limit"] == 200_000
    data = json.dumps(big).encode()

    def chunks() -> Iterator[bytes]:  # no Content-Length: counted while it streams in
        for k in range(0, len(data), 65536):
            yield data[k:k + 65536]

    r = client.post("/analyses", content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413 and r.json()["limit"] == 200_000


# -- scenes ------------------------------------------------------------------------------------


def test_geometry_is_forward_kinematics(client: TestClient) -> None:
    q = [0.3, 0.2, 1.5, -0.4]
    r = client.post("/scenes/geometry", json={"scene": PLANAR, "configurations": [PLANAR["fingers"][0]["q"] +
                                                                                  PLANAR["fingers"][1]["q"], q]})
    assert r.status_code == 200, r.text
    frames = r.json()["frames"]
    left = frames[1]["fingers"][0]["links"]
    base = np.array(PLANAR["fingers"][0]["base"]["position"])
    e1 = base + 0.9 * np.array([math.cos(0.3), math.sin(0.3)])
    e2 = e1 + 0.9 * np.array([math.cos(0.5), math.sin(0.5)])
    np.testing.assert_allclose(left[0]["a"], base, atol=1e-8)
    np.testing.assert_allclose(left[0]["b"], e1, atol=1e-8)
    np.testing.assert_allclose(left[1]["b"], e2, atol=1e-8)
    # in the scene's own configuration the contact points lie on their links
    c0 = np.array(PLANAR["contacts"][0]["point"])
    a, b = (np.array(frames[0]["fingers"][0]["links"][0][k]) for k in "ab")
    t = np.dot(c0 - a, b - a) / np.dot(b - a, b - a)
    assert np.linalg.norm(a + t * (b - a) - c0) < 1e-6
    r = client.post("/scenes/geometry", json={"scene": PLANAR, "configurations": [[0.0, 1.0]]})
    assert r.status_code == 422 and r.json()["detail"].startswith("configurations.0:")


def test_geometry_of_a_3d_scene(client: TestClient) -> None:
    r = client.post("/scenes/geometry", json={"scene": example("sphere_four_finger_palm")})
    assert r.status_code == 200
    links = r.json()["frames"][0]["fingers"][0]["links"]
    assert all(len(link["a"]) == 3 for link in links)


def test_upload_json_and_yaml(client: TestClient, tmp_path: Path) -> None:
    import yaml

    r = client.post("/scenes/upload", files={"file": ("s.json", json.dumps(PLANAR), "application/json")})
    assert r.status_code == 200 and r.json()["name"] == PLANAR["name"]
    r = client.post("/scenes/upload", files={"file": ("s.yaml", yaml.safe_dump(PLANAR), "text/yaml")})
    assert r.status_code == 200 and len(r.json()["contacts"]) == 5
    bad = copy.deepcopy(PLANAR)
    bad["contacts"][3]["normal"] = [0.0, 2.0]
    r = client.post("/scenes/upload", files={"file": ("s.json", json.dumps(bad), "application/json")})
    assert r.status_code == 422 and r.json()["detail"].startswith("scene.contacts.3.normal:")
    r = client.post("/scenes/upload", files={"file": ("s.json", "{not json", "application/json")})
    assert r.status_code == 422 and "cannot parse JSON" in r.json()["detail"]


# -- jobs: enumerations (the same machinery as plans) ------------------------------------------


def test_enumeration_job_life_cycle(client: TestClient) -> None:
    r = client.post("/enumerations", json={"scene": PLANAR})
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["status"] in ("queued", "running") and r.headers["location"] == f"/enumerations/{job['id']}"
    done = wait_for(client, job["url"])
    assert done["status"] == "succeeded", done
    assert done["progress"] == 1.0 and done["elapsed_seconds"] > 0 and done["attempts"] == 1
    assert done["finished_at"] >= done["started_at"] >= done["created_at"]
    res = client.get(done["result_url"])
    assert res.status_code == 200
    direct = client.post("/analyses", json={"scene": PLANAR}).json()
    assert res.json()["combinations"] == direct["combinations"]
    listed = client.get("/enumerations").json()
    assert job["id"] in [j["id"] for j in listed["items"]]
    only_ok = client.get("/enumerations", params={"status": "succeeded"}).json()["items"]
    assert all(j["status"] == "succeeded" for j in only_ok)
    # a finished job cannot be cancelled any more: DELETE answers 409 and changes nothing
    r = client.delete(job["url"])
    assert r.status_code == 409 and "already succeeded" in r.json()["detail"], r.text
    assert client.get(job["url"]).json()["status"] == "succeeded"
    assert client.get(done["result_url"]).status_code == 200


def test_unknown_jobs_are_404(client: TestClient) -> None:
    assert client.get("/plans/nope").status_code == 404
    assert client.get("/plans/nope/result").status_code == 404
    assert client.delete("/plans/nope").status_code == 404
    job = client.post("/enumerations", json={"scene": PLANAR}).json()
    assert client.get(f"/plans/{job['id']}").status_code == 404  # an enumeration is not a plan
    wait_for(client, job["url"])
    r = client.get("/plans", params={"status": "bogus"})
    assert r.status_code == 422 and r.json()["detail"].startswith("query.status:")
    assert client.get("/plans", params={"limit": 0}).status_code == 422


# -- plans -------------------------------------------------------------------------------------


def test_plan_goal_validation(client: TestClient) -> None:
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "sideways"}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal.type:")
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "combination"}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal:")
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "combination", "combination": "FF"}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal.combination:")
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "pose", "pose": [0, 0, 0, 0, 0, 0]}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal.pose:")
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "displacement",
                                                               "displacement": [0, 0.1, 0, 0, 0, 0]}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal.displacement:"), r.text
    assert r.json()["errors"][0]["loc"] == ["goal", "displacement"]
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "contact", "body": "left/1"}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal:"), r.text  # contact needs body and point
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "contact", "body": "left/1", "point": [0, 0, 0]}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal.point:"), r.text
    assert r.json()["errors"][0]["loc"] == ["goal", "point"]
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "displacement"}})
    assert r.status_code == 422 and "displacement" in r.json()["detail"], r.text
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "time_limit": 1e9})
    assert r.status_code == 422 and r.json()["detail"].startswith("time_limit")


def test_plan_life_cycle(client: TestClient) -> None:
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}})
    assert r.status_code == 202, r.text
    done = wait_for(client, r.json()["url"], timeout=120)
    assert done["status"] in ("succeeded", "failed"), done
    if done["status"] == "succeeded":
        plan = client.get(done["result_url"]).json()
        assert "steps" in plan and "found" in plan
        for step in plan["steps"]:
            assert {"kind", "combination"} <= set(step)
    else:
        assert done["error"]
        assert client.get(f"/plans/{done['id']}/result").status_code == 409


def test_plan_job_without_a_plan_says_found_false_and_why(client: TestClient) -> None:
    """The job ran to its end (succeeded); its result says at the top level that no plan was found
    and why, with no steps."""
    scene = copy.deepcopy(PLANAR)
    scene["contacts"] = [c for c in scene["contacts"] if c["body"] == "palm"]
    scene["external_wrench"] = [1.0, 0.0, 0.0]  # pushed sideways off the palm: nothing holds it
    r = client.post("/plans", json={"scene": scene, "goal": {"type": "active"}})
    assert r.status_code == 202, r.text
    done = wait_for(client, r.json()["url"], timeout=120)
    assert done["status"] == "succeeded", done
    plan = client.get(done["result_url"]).json()
    assert plan["found"] is False and plan["outcome"] == "no_plan" and plan["steps"] == []
    assert "no stationary grasp (18)" in plan["reason"]


def test_plan_goal_tolerances_and_letters_are_validated(client: TestClient) -> None:
    goal = {"type": "pose", "pose": [0.0, 0.55, 0.0]}
    for field, value in (("position_tolerance", -0.01), ("rotation_tolerance", "loose"), ("free_axes", ["up"])):
        r = client.post("/plans", json={"scene": PLANAR, "goal": {**goal, field: value}})
        assert r.status_code == 422 and r.json()["detail"].startswith(f"goal.{field}"), r.text
    # a combination letter that does not fit its contact (N on a contact with friction)
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "combination", "combination": "NFFFD"}})
    assert r.status_code == 422 and r.json()["detail"].startswith("goal.combination"), r.text
    assert "letter 0 is N" in r.json()["detail"]
    # a model validator's own words, without pydantic's "Value error, " prefix
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active", "free_axes": ["x"]}})
    assert r.status_code == 422, r.text
    assert r.json()["detail"] == "goal: free_axes is for goal types 'pose' and 'displacement'", r.text


# -- limits, cancellation, recovery (an app with tight limits) ---------------------------------


@pytest.fixture(scope="module")
def tight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = create_app(settings_for(tmp_path_factory.mktemp("tight"), max_contacts=9, request_time_limit=1.5,
                                  job_time_limit=60.0))
    with TestClient(app) as c:
        yield c


def test_sync_time_limit_stops_the_worker(tight: TestClient) -> None:
    wrap = example("sphere_four_finger_wrap")  # 19,683 combinations: far more than 1.5 s
    r = tight.post("/analyses", json={"scene": wrap})
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["limit"] == 1.5 and "time limit" in body["detail"] and "/enumerations" in body["detail"]
    # the stopped worker was replaced: the next request is answered
    r = tight.post("/analyses", json={"scene": PLANAR, "combination": "FFFFF"})
    assert r.status_code == 200, r.text
    assert tight.get("/health").json()["analysis_workers"] == 1


def test_job_time_limit_fails_the_job_with_the_reason(tight: TestClient) -> None:
    r = tight.post("/enumerations", json={"scene": example("sphere_four_finger_wrap"), "time_limit": 1.0})
    assert r.status_code == 202
    done = wait_for(tight, r.json()["url"])
    assert done["status"] == "failed" and "time limit" in done["error"]
    r = tight.get(f"{done['url']}/result")
    assert r.status_code == 409 and "failed" in r.json()["detail"]
    r = tight.post("/enumerations", json={"scene": PLANAR, "time_limit": 1e6})
    assert r.status_code == 422 and r.json()["detail"].startswith("time_limit:") and r.json()["limit"] == 60.0


def test_cancel_running_and_queued_jobs(tight: TestClient) -> None:
    wrap = example("sphere_four_finger_wrap")
    running = tight.post("/enumerations", json={"scene": wrap}).json()
    queued = tight.post("/enumerations", json={"scene": PLANAR}).json()  # one job worker: waits
    wait_for(tight, running["url"], statuses=("running",))
    r = tight.get(f"{queued['url']}/result")
    assert r.status_code == 409
    assert tight.delete(queued["url"]).json()["status"] == "cancelled"
    r = tight.delete(running["url"])
    assert r.status_code == 200 and r.json()["status"] in ("running", "cancelled")
    done = wait_for(tight, running["url"], timeout=20)
    assert done["status"] == "cancelled"
    # the worker that ran it was replaced; the next job runs
    nxt = tight.post("/enumerations", json={"scene": PLANAR}).json()
    assert wait_for(tight, nxt["url"])["status"] == "succeeded"
    assert wait_for(tight, queued["url"])["status"] == "cancelled"


# -- geometric scene errors: the same field and message as a scene file gets --------------------


@pytest.mark.parametrize("route", ["/analyses", "/enumerations", "/plans", "/scenes/geometry"])
def test_geometric_scene_errors_are_422_naming_the_field(client: TestClient, route: str) -> None:
    bad = copy.deepcopy(PLANAR)
    bad["contacts"][1]["point"][0] += 0.05  # off the surface of its link
    with pytest.raises(SceneError) as expected:
        scene_from_dict(bad)
    body: dict[str, object] = {"scene": bad}
    if route == "/plans":
        body["goal"] = {"type": "active"}
    jobs_before = client.get(route).json()["count"] if route in ("/enumerations", "/plans") else 0
    r = client.post(route, json=body)
    assert r.status_code == 422, r.text
    out = r.json()
    assert out["detail"] == f"scene.{expected.value}"
    assert out["errors"][0]["loc"] == ["scene", "contacts", 1, "point"]
    if route in ("/analyses", "/scenes/geometry"):  # found by the worker: the error says which lane
        assert r.headers["x-lane"] == ("light" if route == "/scenes/geometry" else "heavy")
    if route in ("/enumerations", "/plans"):  # refused at the door: no job was stored
        assert client.get(route).json()["count"] == jobs_before


def test_plan_options_are_the_planners_switches_stored_as_given(client: TestClient) -> None:
    """``options`` of ``POST /plans``: each switch is a ``PlannerOptions`` field with the same
    default; the job stores the switches given (none: the request keeps its former form, so
    earlier jobs and cache keys are unchanged); unknown or non-boolean switches are 422 naming them."""
    import dataclasses

    from api.schemas import PlannerSwitches
    from planner.options import PlannerOptions

    defaults = {f.name: f.default for f in dataclasses.fields(PlannerOptions)}
    for name, field in PlannerSwitches.model_fields.items():  # effort_weight null: the planner's default
        assert name in defaults and field.default == (None if name == "effort_weight" else defaults[name]), name
    store = client.app.state.store  # type: ignore[attr-defined]
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "time_limit": 5,
                                    "options": {"contact_slides": True, "sliding_motions": False}})
    assert r.status_code == 202, r.text
    assert store.get(r.json()["id"]).request["options"] == {"contact_slides": True, "sliding_motions": False}
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "time_limit": 5})
    assert "options" not in store.get(r.json()["id"]).request
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "options": {"fly": True}})
    assert r.status_code == 422 and r.json()["detail"].startswith("options.fly:"), r.text
    r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "options": {"link_sliding": "yes"}})
    assert r.status_code == 422 and r.json()["detail"].startswith("options.link_sliding:"), r.text


def test_plan_effort_weight_is_a_finite_non_negative_number_stored_when_given(client: TestClient) -> None:
    """``options.effort_weight``: stored as given (0 included); null is the planner's default and
    stored as not given (the request's former form); -1, NaN, infinity, a string or a boolean are
    422 naming ``options.effort_weight``, and no job is stored."""
    store = client.app.state.store  # type: ignore[attr-defined]
    for given, stored in ((0, {"effort_weight": 0.0}), (0.25, {"effort_weight": 0.25}),
                          ({"effort_weight": None, "link_sliding": True}, {"link_sliding": True}),
                          ({"effort_weight": None}, {})):
        options = given if isinstance(given, dict) else {"effort_weight": given}
        r = client.post("/plans", json={"scene": PLANAR, "goal": {"type": "active"}, "time_limit": 5,
                                        "options": options})
        assert r.status_code == 202, r.text
        assert store.get(r.json()["id"]).request["options"] == stored, given
    before = client.get("/plans").json()["count"]
    for bad in ("-1", "NaN", "Infinity", "-Infinity", '"0.1"', "true"):  # raw JSON: NaN is not in json=
        text = json.dumps({"scene": PLANAR, "goal": {"type": "active"}, "options": {"effort_weight": 0}})
        text = text.replace('"effort_weight": 0}', f'"effort_weight": {bad}}}')
        r = client.post("/plans", content=text, headers={"content-type": "application/json"})
        assert r.status_code == 422, (bad, r.text)
        assert r.json()["detail"].startswith("options.effort_weight:"), (bad, r.text)
    assert client.get("/plans").json()["count"] == before


def test_a_plan_job_runs_the_planner_with_its_options(monkeypatch: pytest.MonkeyPatch) -> None:
    import planner
    from api.tasks import run_plan
    from planner.options import PlannerOptions

    seen: list[PlannerOptions | None] = []
    real = planner.plan

    def spy(*args: Any, options: PlannerOptions | None = None, **kwargs: Any) -> Any:
        seen.append(options)
        return real(*args, options=options, max_expansions=1, **kwargs)

    monkeypatch.setattr(planner, "plan", spy)
    run_plan({"scene": PLANAR, "goal": {"type": "active"}, "options": {"link_replacement": True}})
    assert seen[-1] == PlannerOptions(link_replacement=True)
    run_plan({"scene": PLANAR, "goal": {"type": "active"}, "options": {"effort_weight": 0.0, "sliding_motions": False}})
    assert seen[-1] == PlannerOptions(effort_weight=0.0, sliding_motions=False)
    run_plan({"scene": PLANAR, "goal": {"type": "active"}})
    assert seen[-1] is None
