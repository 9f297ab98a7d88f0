"""Jobs as Ray tasks (``CTP_RAY_ADDRESS``): the same life cycle on a local Ray instance."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from service_helpers import example, settings_for, wait_for

from api.main import create_app


@pytest.mark.slow
def test_jobs_run_as_ray_tasks(tmp_path: Path) -> None:
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        app = create_app(settings_for(tmp_path, ray_address="local", job_workers=2, max_contacts=9))
        with TestClient(app) as client:
            assert client.get("/health").json()["executor"] == "ray (local)"
            ok = client.post("/enumerations", json={"scene": example("planar_disk_envelope")}).json()
            slow = client.post("/enumerations", json={"scene": example("sphere_four_finger_wrap"),
                                                      "time_limit": 1.5}).json()
            done = wait_for(client, ok["url"], timeout=120)
            assert done["status"] == "succeeded", done
            assert len(client.get(done["result_url"]).json()["combinations"]) == 243
            failed = wait_for(client, slow["url"], timeout=60)
            assert failed["status"] == "failed" and "time limit" in failed["error"]
            third = client.post("/enumerations", json={"scene": example("sphere_four_finger_wrap")}).json()
            wait_for(client, third["url"], statuses=("running",), timeout=60)
            client.delete(third["url"])
            assert wait_for(client, third["url"], timeout=30)["status"] == "cancelled"
    finally:
        ray.shutdown()
