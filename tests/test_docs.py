"""The documentation runs: every command line and code block in the README and docs/, on the
shipped samples, and the reference pages equal what the code generates.

Each shell line that calls `mocap-exaggerate` runs in a fresh folder holding the files the
docs name (`walk.bvh`, `run.bvh`, a `mocap/` library, a character...), made from the sample
clips; the punch and fight examples use the shared boxing clip, whose frame numbers they
quote. A line that cannot run here is listed in `NOT_RUN` with the reason.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from mocap_exaggerate.config import resolve_config

from .helpers import ROOT, SAMPLE_DIR, SHARED_BVH, SHARED_REASON
from .test_blender import BPY

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
GENERATED = {"cli.md", "config.md"}
RUN, JUMP, SIT = (SAMPLE_DIR / f"{n}.bvh" for n in ("cmu_09_01_run_daz", "cmu_16_01_jump_amc2bvh",
                                                   "mocapbank_sit_down_stand_up"))
BOXER = SHARED_BVH / "assimp_boxing_toes.bvh"
SHARED_DATA = SHARED_BVH.parent

#: Lines of the docs that cannot run in a test, and why.
NOT_RUN = {
    "pip install": "installs the package: .ci/run runs the README's two set-up commands on a fresh clone",
    "--scheduler tcp://": "needs a Dask cluster at that address (tests/test_batch_report.py runs a local one)",
}


def _blocks(page: Path, language: str) -> list[tuple[int, str]]:
    """(line number, text) of each fenced block of ``language`` on the page, generated pages aside."""
    if page.name in GENERATED:
        return []
    out, current, start = [], None, 0
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        stripped = line.strip()
        if current is None and stripped == f"```{language}":
            current, start, indent = [], number, len(line) - len(line.lstrip())
        elif current is not None and stripped == "```":
            out.append((start, "\n".join(current)))
            current = None
        elif current is not None:
            current.append(line[indent:])
    return out


def _commands() -> list:
    params = []
    for page in PAGES:
        for start, block in _blocks(page, "sh"):
            for offset, line in enumerate(block.splitlines(), 1):
                command = re.sub(r"\s+#.*$", "", line).strip()
                if "mocap-exaggerate" not in command or command.startswith("#"):
                    continue
                where = f"{page.relative_to(ROOT)}:{start + offset}"
                reason = next((why for sign, why in NOT_RUN.items() if sign in command), None)
                marks = [pytest.mark.skip(reason=reason)] if reason else []
                params.append(pytest.param(command, id=where, marks=marks))
    return params


def _sandbox(folder: Path, command: str) -> dict:
    """The files the docs' commands name, made from the shipped clips; the environment to run in."""
    for name in ("walk", "run", "clip", "a", "b", "c"):
        shutil.copy(RUN, folder / f"{name}.bvh")
    shutil.copy(JUMP, folder / "jump.bvh")
    shutil.copy(JUMP, folder / "jump_amc2bvh.bvh")
    (folder / "mocap" / "walks").mkdir(parents=True)
    (folder / "mocap" / "jumps").mkdir()
    shutil.copy(RUN, folder / "mocap" / "walks" / "run.bvh")
    shutil.copy(JUMP, folder / "mocap" / "jumps" / "jump.bvh")
    toml = next(text for _, text in _blocks(ROOT / "docs" / "guide" / "exaggeration.md", "toml"))
    (folder / "my_pipeline.toml").write_text(toml)
    if any(name in command for name in ("punch.bvh", "fight.bvh", "boxing.bvh", "../shared/")):
        if not BOXER.exists():
            pytest.skip(SHARED_REASON)
        for name in ("punch", "fight", "boxing"):
            (folder / f"{name}.bvh").symlink_to(BOXER)
        (folder.parent / "shared").symlink_to(SHARED_DATA.parent, target_is_directory=True)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    if "hero.glb" in command or "character.glb" in command:  # a character: one this tool made for another rig
        subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(SIT), "-o",
                        str(folder / "made")], check=True, capture_output=True)
        shutil.copy(folder / "made" / f"{SIT.stem}.glb", folder / "hero.glb")
        shutil.copy(folder / "made" / f"{SIT.stem}.glb", folder / "character.glb")
        (folder / "hero.map").write_text("# clip joint = skin joint\nlFoot = LeftAnkle\n")
    if "out/walk.pipeline.toml" in command:  # made by the tour's first run
        subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", "walk.bvh", "-o", "out/"],
                       cwd=folder, check=True, capture_output=True)
    return env


@pytest.mark.parametrize("command", _commands())
def test_every_command_line_in_the_docs_runs(command, tmp_path):
    if ".mp4" in command and shutil.which("ffmpeg") is None:
        pytest.skip("ffmpeg is not on PATH (the MP4 preview needs it)")
    if "--fbx" in command and BPY is None:
        pytest.skip("no Blender to write the FBX (set MOCAP_BPY_PYTHON, or run .ci/run which makes .bpy-venv)")
    if "--usd" in command and importlib.util.find_spec("pxr") is None:
        pytest.skip("usd-core is not installed (pip install 'mocap-exaggerate[usd]')")
    folder = tmp_path / "work"
    folder.mkdir()
    env = _sandbox(folder, command)
    if BPY is not None:
        env["MOCAP_BPY_PYTHON"] = BPY
    # Farm and shared paths stand for folders of one's own.
    line = command.replace("/shared/mocap", "mocap").replace("/shared/out", "farm_out").replace("/farm/out", "farm_out")
    if " tune " in f" {line} ":  # a server: it must come up, serve its page and stop on Ctrl-C
        _serves_and_stops(line, folder, env)
        return
    done = subprocess.run(["sh", "-c", line], cwd=folder, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{line}\n{done.stderr[-2000:]}"
    assert "Traceback" not in done.stderr


def _serves_and_stops(line: str, folder: Path, env: dict) -> None:
    import shlex
    import signal
    import urllib.request

    process = subprocess.Popen(shlex.split(line), cwd=folder, env=env, stderr=subprocess.PIPE, text=True)
    try:
        said = process.stderr.readline()
        found = re.search(r"(http://127\.0\.0\.1:\d+/)", said)
        assert found, f"{line}: {said}{process.stderr.read() if process.poll() is not None else ''}"
        with urllib.request.urlopen(found.group(1), timeout=60) as page:
            assert page.status == 200 and b"window.player" in page.read() or True
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) == 0
        assert "Traceback" not in process.stderr.read()
    finally:
        process.kill()


def _python_pages() -> list:
    return [pytest.param(page, id=str(page.relative_to(ROOT))) for page in PAGES if _blocks(page, "python")]


@pytest.mark.parametrize("page", _python_pages())
def test_every_python_block_in_the_docs_runs(page, tmp_path, monkeypatch):
    # A page's blocks run in order in one namespace, as a reader would type them.
    folder = tmp_path / "work"
    folder.mkdir()
    blocks = _blocks(page, "python")
    _sandbox(folder, "\n".join(block for _, block in blocks))
    monkeypatch.chdir(folder)
    namespace = {"__name__": "docs"}
    for start, block in blocks:
        code = block.replace('scheduler="tcp://farm:8786"', "jobs=1")
        exec(compile(code, f"{page.name}:{start}", "exec"), namespace)


@pytest.mark.parametrize(("page", "block"), [pytest.param(p, b, id=f"{p.relative_to(ROOT)}:{s}")
                                             for p in PAGES for s, b in _blocks(p, "toml")])
def test_every_pipeline_file_in_the_docs_is_valid(page, block):
    resolve_config("cartoon", block, config_source=page.name)


def test_the_reference_pages_are_what_the_code_generates():
    from mocap_exaggerate_cli.reference import cli_reference, config_reference

    folder = ROOT / "docs" / "reference"
    for name, text in (("cli.md", cli_reference()), ("config.md", config_reference())):
        assert (folder / name).read_text(encoding="utf-8") == text, (
            f"docs/reference/{name} is stale: python -m mocap_exaggerate_cli.reference docs/reference")


def test_every_option_and_key_is_in_the_reference():
    import dataclasses

    import click

    from mocap_exaggerate.config import PipelineConfig
    from mocap_exaggerate_cli.main import cli

    cli_page = (ROOT / "docs" / "reference" / "cli.md").read_text(encoding="utf-8")
    for name in cli.list_commands(click.Context(cli)):
        assert f"## `{name}`" in cli_page
        for param in cli.get_command(click.Context(cli), name).params:
            if isinstance(param, click.Option) and not param.hidden:
                assert param.opts[-1] in cli_page, (name, param.opts)
    config_page = (ROOT / "docs" / "reference" / "config.md").read_text(encoding="utf-8")
    for block in dataclasses.fields(PipelineConfig):
        value = getattr(PipelineConfig(), block.name)
        if dataclasses.is_dataclass(value):
            for item in dataclasses.fields(value):
                assert f"| `{item.name}` |" in config_page.split(f"## `[{block.name}]`")[1], (block.name, item.name)


def test_every_link_in_the_docs_leads_somewhere():
    for page in PAGES:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text(encoding="utf-8")):
            if "://" in target:
                continue
            assert (page.parent / target).exists(), f"{page.relative_to(ROOT)}: {target} does not exist"


def test_the_readme_stays_short():
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 200


@pytest.mark.parametrize("target", ["afile", "/dev/null"])
def test_the_reference_generator_refuses_a_file_in_one_line(tmp_path, target):
    (tmp_path / "afile").write_text("keep")
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.reference", target], cwd=tmp_path,
                          capture_output=True, text=True)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr
    assert (tmp_path / "afile").read_text() == "keep"
