"""The Dockerfile cannot be built here, so its steps are run the same way: the files it copies
exist, ``pip install .`` yields a package that carries the dashboard, and the installed package
(outside the source tree, examples from ``CTP_EXAMPLES_DIR``, store from ``CTP_DATABASE_URL``)
serves the API, the dashboard and the examples under its ``CMD``; its HEALTHCHECK passes."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import httpx
import pytest
from service_helpers import ROOT, free_port

DOCKERFILE = (ROOT / "Dockerfile").read_text()


def test_dockerfile_copies_what_exists() -> None:
    for src in re.findall(r"^COPY (\S+) ", DOCKERFILE, flags=re.M):
        for part in src.split():
            assert (ROOT / part).exists(), part
    for line in re.findall(r"^COPY (.+)$", DOCKERFILE, flags=re.M):
        for part in line.split()[:-1]:
            assert (ROOT / part).exists(), part
    assert 'CMD ["uvicorn", "api.main:app", "--host", "0.0.0.0", "--port", "8000"]' in DOCKERFILE


@pytest.mark.slow
def test_installed_package_serves_like_the_image(tmp_path: Path) -> None:
    # the build context of the image: what the Dockerfile copies, nothing else
    context = tmp_path / "context"
    context.mkdir()
    for line in re.findall(r"^COPY (.+)$", DOCKERFILE, flags=re.M):
        for part in line.split()[:-1]:
            src = ROOT / part
            if src.is_dir():
                shutil.copytree(src, context / part, ignore=shutil.ignore_patterns("__pycache__"))
            else:
                shutil.copy(src, context / part)
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(context)],
                   check=True, cwd=tmp_path)
    wheel = next(wheels.glob("contact_transition_planner-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    for f in ("api/static/index.html", "api/static/app.js", "api/static/style.css", "api/main.py"):
        assert f in names, f
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, cwd=tmp_path)
    examples = context / "examples"  # CTP_EXAMPLES_DIR=/app/examples in the image
    data = tmp_path / "data"
    data.mkdir()
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(site), "CTP_DATABASE_URL": f"sqlite:///{data / 'ctp-jobs.db'}",
           "CTP_EXAMPLES_DIR": str(examples), "CTP_ANALYSIS_WORKERS": "1", "CTP_JOB_WORKERS": "1"}
    cmd = [sys.executable, "-m", "uvicorn", "api.main:app", "--host", "127.0.0.1", "--port", str(port)]
    proc = subprocess.Popen(cmd, cwd="/", env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
                            start_new_session=True)
    try:
        base = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 90
        while True:
            assert proc.poll() is None, "server exited"
            try:
                if httpx.get(f"{base}/health", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.2)
        code = "import api, sys; print(api.__file__)"
        where = subprocess.run([sys.executable, "-c", code], env=env, cwd="/", capture_output=True, text=True)
        assert where.stdout.startswith(str(site)), where.stdout  # the installed copy, not the source tree
        assert "/static/app.js" in httpx.get(base + "/", timeout=10).text
        assert len(httpx.get(base + "/scenes/examples", timeout=10).json()) >= 3
        health = re.search(r'HEALTHCHECK .*?CMD \["python", "-c", "(.+?)"\]', DOCKERFILE, flags=re.S)
        assert health is not None
        probe = health.group(1).replace("8000", str(port))
        subprocess.run([sys.executable, "-c", probe], check=True, env=env, cwd="/")
        assert (data / "ctp-jobs.db").exists()
    finally:
        proc.terminate()
        proc.wait(20)
