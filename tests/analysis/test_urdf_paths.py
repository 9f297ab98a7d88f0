"""``example-robot-data:`` URDF paths stay inside the package's robots folder (symbolic links
resolved) and their errors never show the server's folders."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from analysis.exceptions import SceneError
from analysis.urdf import example_robot_data_dir, load_urdf_model, resolve_urdf_path


@pytest.fixture
def robots(tmp_path: Path, monkeypatch: Any) -> Path:
    """A robots folder of our own (EXAMPLE_ROBOT_DATA_MODEL_DIR), next to a secret outside it."""
    root = tmp_path / "share" / "robots"
    (root / "hand" / "urdf").mkdir(parents=True)
    (root / "hand" / "urdf" / "ok.urdf").write_text("<robot name='ok'/>")
    secret = tmp_path / "secret.urdf"
    secret.write_text("<robot name='secret'/>")
    os.symlink(secret, root / "hand" / "urdf" / "escape.urdf")  # a link out of the folder
    os.symlink(root / "hand", root / "alias")  # a link that stays inside
    monkeypatch.setenv("EXAMPLE_ROBOT_DATA_MODEL_DIR", str(root))
    assert example_robot_data_dir() == root
    return root


@pytest.mark.parametrize("spec", [
    "example-robot-data:/etc/passwd",
    "example-robot-data:../../secret.urdf",
    "example-robot-data:hand/urdf/escape.urdf",
    "example-robot-data:hand/urdf/missing.urdf",
    "example-robot-data:hand",
])
def test_outside_missing_or_escaping_files_are_not_found_without_server_paths(robots: Path, spec: str) -> None:
    with pytest.raises(SceneError) as info:
        resolve_urdf_path(spec)
    message = str(info.value)
    assert info.value.loc == ("urdf", "file") and "not found" in message
    assert spec in message  # names what was asked for ...
    assert str(robots) not in message and str(robots.parent.parent) not in message  # ... and no server folder
    assert "site-packages" not in message and "/etc/passwd" not in message.replace(spec, "")


def test_files_inside_resolve_through_links_that_stay_inside(robots: Path) -> None:
    assert resolve_urdf_path("example-robot-data:hand/urdf/ok.urdf") == robots / "hand/urdf/ok.urdf"
    assert resolve_urdf_path("example-robot-data:alias/urdf/ok.urdf") == robots / "alias/urdf/ok.urdf"


def test_an_unreadable_urdf_names_the_file_not_its_folder(robots: Path) -> None:
    bad = robots / "hand" / "urdf" / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'>")
    with pytest.raises(SceneError) as info:
        load_urdf_model(bad)
    assert "bad.urdf" in str(info.value) and str(robots) not in str(info.value)


def test_the_installed_package_path_is_not_shown() -> None:
    root = example_robot_data_dir()
    if root is None:
        pytest.skip("example-robot-data is not installed")
    with pytest.raises(SceneError) as info:
        resolve_urdf_path("example-robot-data:/etc/passwd")
    assert str(root) not in str(info.value) and "site-packages" not in str(info.value)
