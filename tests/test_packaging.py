"""The wheel ships the resources, and an installed wheel finds them (not only a source checkout)."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Build the project's wheel (no network: the build backend is already installed)."""
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            str(ROOT),
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(out),
        ],
        check=True,
        timeout=240,
    )
    wheels = list(out.glob("urdaemon-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def test_wheel_contains_every_resource_and_the_typing_marker(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {p.relative_to(ROOT).as_posix() for p in (ROOT / "resources").rglob("*") if p.is_file()}
    assert shipped, "resources/ is empty"
    for resource in shipped:
        assert f"urdaemon/{resource}" in names, f"{resource} missing from the wheel"
    assert "urdaemon/py.typed" in names
    assert any(n.endswith("entry_points.txt") for n in names)


def test_installed_wheel_finds_its_resources_and_builds_a_cell(wheel: Path, tmp_path: Path) -> None:
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    script = f"""
import urdaemon, urdaemon.paths
from pathlib import Path
from urdaemon.cell import load_cell
from urdaemon.daemon import describe_cell
site = Path({str(site)!r}).resolve()
assert Path(urdaemon.__file__).resolve().is_relative_to(site), urdaemon.__file__
found = urdaemon.paths.resources_dir().resolve()
assert found == site / "urdaemon" / "resources", found
description = describe_cell(load_cell({str(ROOT / "configs" / "dual_robot_mock.yaml")!r}))
assert sorted(description.limits) == ["alice", "bob"]
assert "alice_tool0" in description.urdf
print("ok", urdaemon.paths.resources_dir())
"""
    env = {**os.environ, "PYTHONPATH": str(site)}
    # run outside the checkout so that the current directory cannot supply the package
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("ok ")
    assert str(site) in done.stdout
