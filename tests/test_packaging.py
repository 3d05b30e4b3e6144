"""The wheel a user installs holds everything the checkout runs from.

The tests run on an editable install, which reads the checkout's folders as they are: a
module, preset or web file that ``pyproject.toml`` leaves out of the wheel would pass every
other test and break ``pip install .``. So this builds the wheel from the tracked files, as
pip does on a fresh machine, and compares.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.process


def tracked_files() -> list[str]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the tracked files are not known")
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return [name for name in listed.decode().split("\0") if name and (ROOT / name).is_file()]


def test_the_wheel_holds_every_module_preset_and_web_file(tmp_path):
    source = tmp_path / "source"
    files = tracked_files()
    for name in files:
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, source / name)
    # No compiler (the optional modules are left out, as on a machine without one): quicker, and
    # the install must go on without them.
    env = dict(os.environ, CC="/bin/false")
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-v", "-w", str(tmp_path / "wheel"),
                            str(source)], capture_output=True, text=True, env=env, timeout=600)
    if built.returncode != 0 and "satisfies the requirement setuptools" in built.stdout + built.stderr:
        pytest.skip("pip cannot fetch setuptools to build the wheel (no network, no PIP_FIND_LINKS)")
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-2000:]
    assert "absent from the `packages` configuration" not in built.stdout + built.stderr
    (wheel,) = (tmp_path / "wheel").glob("mocap_exaggerate-*.whl")
    inside = set(zipfile.ZipFile(wheel).namelist())
    wanted = {name for name in files if name.startswith("mocap_exaggerate/") and not name.endswith(".c")}
    wanted |= {"mocap_exaggerate_cli/" + name.removeprefix("cli/") for name in files
               if name.startswith("cli/") and name.endswith(".py")}
    assert wanted - inside == set()
    assert {"mocap_exaggerate/presets/cartoon.toml", "mocap_exaggerate/viz/web/viewer.js"} <= inside
