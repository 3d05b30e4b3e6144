"""A run's ``<name>.pipeline.toml`` rebuilds the run: for every option that changes an output,
``--config`` of the written file alone, from another working folder into another output folder,
gives the same bytes (BVH, GLB, weights, the pipeline file; the manifest but for its timings and
the input's path as given).

Options that are not settings and so are not recorded: ``-o``, ``--name``, ``--overwrite`` (where
and whether to write), ``--trails`` (a side file, written wherever it is asked), ``--path-file``
(hand-edited paths of one clip: an input of its own, like the clip), ``-v``/``-q``.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from click.testing import CliRunner

from mocap_exaggerate import convert
from mocap_exaggerate.config import PipelineConfig, config_preset, load_preset, resolve_config
from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.jobs.job import parameters_digest
from mocap_exaggerate_cli.main import cli

from .helpers import ROOT, SAMPLE_DIR

CLIP = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
SIT = SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh"
MAKEHUMAN = ROOT.parent / "shared" / "data" / "skin" / "makehuman_base.obj"


@pytest.fixture(scope="module")
def place(tmp_path_factory) -> Path:
    """``work/`` (the first runs start here: the clip, a character, a joint map, configs of one's
    own), ``elsewhere/deeper/`` (the rebuilds run here) and ``runs/`` (the outputs)."""
    root = tmp_path_factory.mktemp("rebuild")
    work = root / "work"
    (work / "characters").mkdir(parents=True)
    (work / "conf").mkdir()
    shutil.copy(CLIP, work / "clip.bvh")
    # A character: a GLB this tool made for another rig (the sit clip's), bound to the run by role and name.
    convert(SIT, root / "made", preset="subtle", name="hero")
    shutil.copy(root / "made" / "hero.glb", work / "characters" / "hero.glb")
    (work / "characters" / "hero.map").write_text("# clip joint = skin joint\nlFoot = LeftAnkle\n")
    (work / "conf" / "mine.toml").write_text('preset = "subtle"\n[extrapolate]\nomega = 3.0\n'
                                             '[extrapolate.weights]\nleft_arm = 2.0\n')
    # Relative to the file's own folder, not to where the command runs.
    (work / "conf" / "hero.toml").write_text('[glb]\nskin = "../characters/hero.glb"\nunits = "cm"\n')
    (root / "elsewhere" / "deeper").mkdir(parents=True)
    (root / "runs").mkdir()
    return root


def run_cli(args: list[str], cwd: Path, real: bool) -> tuple[int, str]:
    """``mocap-exaggerate ARGS`` in ``cwd``: a new process, or click's runner in this one."""
    if real:
        done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *args], cwd=cwd,
                              capture_output=True, text=True, timeout=300)
        return done.returncode, done.stderr
    before = Path.cwd()
    os.chdir(cwd)
    try:
        result = CliRunner().invoke(cli, args)
    finally:
        os.chdir(before)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result.exit_code, result.stderr


def assert_same_outputs(one: Path, two: Path) -> None:
    names = sorted(p.name for p in one.iterdir())
    assert names == sorted(p.name for p in two.iterdir())
    for name in names:
        first, second = (one / name).read_bytes(), (two / name).read_bytes()
        if name.endswith(".json"):  # the manifest: all but the timings and the input's path as given
            first, second = json.loads(first), json.loads(second)
            for manifest in (first, second):
                manifest.pop("timings")
                manifest["input"].pop("file")
        assert first == second, f"{name} differs"


#: Each option that changes an output, given on the first run (from work/, so relative paths are relative to it).
OPTIONS = {
    "defaults": [],
    "preset subtle": ["--preset", "subtle"],
    "preset looney": ["--preset", "looney"],
    "config of one's own": ["--config", "conf/mine.toml"],
    "config naming a character": ["--config", "conf/hero.toml"],
    "config and flags over it": ["--config", "conf/mine.toml", "--omega", "4.5", "--units", "dm"],
    "sigma": ["--sigma", "0.12s"],
    "omega": ["--omega", "3"],
    "weight": ["--weight", "left_arm=2", "--weight", "hip=0"],
    "no extrapolate": ["--no-extrapolate"],
    "threshold": ["--threshold", "0.01"],
    "delta": ["--delta", "0.3"],
    "max stretch": ["--max-stretch", "1.3"],
    "max iter": ["--max-iter", "3"],
    "no correct": ["--no-correct"],
    "subjoints": ["--subjoints", "2"],
    "sublink length": ["--sublink-length", "4%"],
    "no subjoints": ["--no-subjoints"],
    "stiffness": ["--stiffness", "100"],
    "link stiffness": ["--link-stiffness", "60"],
    "damping": ["--damping", "5"],
    "blend": ["--blend", "0.8"],
    "no springs": ["--no-springs"],
    "skeleton original": ["--skeleton", "original"],
    "bvh positions input": ["--bvh-positions", "input"],
    "no preserve volume": ["--no-preserve-volume"],
    "stretch": ["--stretch", "left_arm:20-60:2:axes=xz:ease_in=0.6,0.2"],
    "auto stretch": ["--auto-stretch", "--preset", "looney"],
    "contacts off": ["--contacts", "off"],
    "anchor exaggerated": ["--anchor", "exaggerated"],
    "no floor": ["--no-floor"],
    "target": ["--target", "rFoot@60"],
    "tpose drop": ["--tpose", "drop"],
    "tpose keep": ["--tpose", "keep"],
    "fps": ["--fps", "60"],
    "root offset add": ["--root-offset", "add"],
    "up y": ["--up", "y"],
    "set": ["--set", "extrapolate.max_speed=2.5", "--set", "springs.link_stiffness=90"],
    "set a glb key": ["--set", "glb.units=mm", "--set", "glb.influences=8"],
    "units": ["--units", "cm"],
    "influences": ["--influences", "8"],
    "no glb": ["--no-glb"],
    "skin": ["--skin", "characters/hero.glb"],
    "skin and joint map": ["--skin", "characters/hero.glb", "--joint-map", "characters/hero.map"],
    "skin units influences": ["--skin", "characters/hero.glb", "--units", "in", "--influences", "8"],
}
#: Run as a real process too (the rest in this process through click's runner).
REAL = {"defaults", "config naming a character", "skin and joint map", "preset looney"}


@pytest.mark.parametrize("case", sorted(OPTIONS))
def test_the_pipeline_file_rebuilds_every_option_byte_for_byte(place, case):
    real = case in REAL
    folder = place / "runs" / case.replace(" ", "_")
    one, two = folder / "one", folder / "two"
    code, stderr = run_cli(["exaggerate", "clip.bvh", "-o", os.path.relpath(one, place / "work"), *OPTIONS[case]],
                           place / "work", real)
    assert code == 0, stderr
    written = one / "clip.pipeline.toml"
    code, stderr = run_cli(["exaggerate", str(place / "work" / "clip.bvh"), "-o", str(two), "--config", str(written)],
                           place / "elsewhere" / "deeper", real)
    assert code == 0, stderr
    assert "pipeline file recorded" not in stderr, stderr  # the same character: nothing to warn of
    assert_same_outputs(one, two)


def test_the_makehuman_character_rebuilds_from_another_folder(place):
    if not MAKEHUMAN.exists():
        pytest.skip(f"the MakeHuman body is not at {MAKEHUMAN} (CI has ../shared beside the checkout)")
    one, two = place / "runs" / "makehuman" / "one", place / "runs" / "makehuman" / "two"
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", "clip.bvh", "-o", str(one),
                           "--skin", str(MAKEHUMAN), "--units", "cm", "--influences", "8"],
                          cwd=place / "work", capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    text = (one / "clip.pipeline.toml").read_text()
    assert f'skin = "{Path(os.path.relpath(MAKEHUMAN.resolve(), one.resolve())).as_posix()}"' in text
    assert f'skin_sha256 = "{hashlib.sha256(MAKEHUMAN.read_bytes()).hexdigest()}"' in text
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate",
                           str(place / "work" / "clip.bvh"), "-o", str(two), "--config", str(one / "clip.pipeline.toml")],
                          cwd="/", capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert_same_outputs(one, two)


def test_the_written_file_names_everything_it_used(place):
    one = place / "runs" / "named"
    code, stderr = run_cli(["exaggerate", "clip.bvh", "-o", "../runs/named", "--preset", "looney", "--skin",
                            "characters/hero.glb", "--joint-map", "characters/hero.map", "--units", "cm",
                            "--influences", "8"], place / "work", real=False)
    assert code == 0, stderr
    text = (one / "clip.pipeline.toml").read_text()
    assert text.startswith('preset = "looney"\n')
    hero = place / "work" / "characters" / "hero.glb"
    digest = hashlib.sha256(hero.read_bytes()).hexdigest()
    table = text.split("[glb]\n", 1)[1]
    assert table == ('enabled = true\nunits = "cm"\ninfluences = 8\nusd = ""\nfbx = false\n'
                     'skin = "../../work/characters/hero.glb"\n'
                     f'skin_sha256 = "{digest}"\njoint_map = "../../work/characters/hero.map"\n'
                     f'joint_map_sha256 = "{hashlib.sha256((hero.parent / "hero.map").read_bytes()).hexdigest()}"\n')
    manifest = json.loads((one / "clip.json").read_text())
    assert manifest["config"]["glb"]["skin"] == "../../work/characters/hero.glb" and manifest["preset"] == "looney"


def test_the_files_may_move_together(place, tmp_path):
    # The pipeline file names the character relative to its own folder: a tree moved (or mounted
    # elsewhere on a farm) whole still rebuilds.
    code, stderr = run_cli(["exaggerate", "clip.bvh", "-o", "out", "--skin", "characters/hero.glb"],
                           place / "work", real=False)
    assert code == 0, stderr
    moved = tmp_path / "moved"
    shutil.copytree(place / "work", moved)
    shutil.rmtree(place / "work" / "out")
    code, stderr = run_cli(["exaggerate", "clip.bvh", "-o", "again", "--config", "out/clip.pipeline.toml"], moved,
                           real=False)
    assert code == 0, stderr
    assert_same_outputs(moved / "out", moved / "again")


def test_flags_win_over_the_file_and_set_under_the_flags(place):
    written = place / "runs" / "units_file"
    assert run_cli(["exaggerate", "clip.bvh", "-o", str(written), "--units", "cm", "--influences", "8"],
                   place / "work", real=False)[0] == 0
    for args, units, influences in [([], "cm", 8), (["--units", "m"], "m", 8), (["--set", "glb.units=dm"], "dm", 8),
                                    (["--set", "glb.units=dm", "--units", "mm"], "mm", 8),
                                    (["--influences", "4"], "cm", 4), (["--no-glb"], "cm", 8)]:
        out = place / "runs" / ("flags_" + "_".join(a.strip("-").replace("=", "_") for a in args))
        code, stderr = run_cli(["exaggerate", "../work/clip.bvh", "-o", str(out), "--config",
                                str(written / "clip.pipeline.toml"), *args], place / "elsewhere", real=False)
        assert code == 0, stderr
        glb = resolve_config(None, (out / "clip.pipeline.toml").read_text()).glb
        assert (glb.units, glb.influences, glb.enabled) == (units, influences, "--no-glb" not in args), args
        assert (out / "clip.glb").exists() == glb.enabled
        manifest = json.loads((out / "clip.json").read_text())
        if glb.enabled:
            assert manifest["outputs"]["units"].split()[0] == units


def test_a_changed_character_is_used_and_said(place, tmp_path):
    # Warned, not refused: a revised character is a reason to rerun the same settings. The new file
    # records the new bytes; the manifest keeps the warning.
    characters = tmp_path / "characters"
    shutil.copytree(place / "work" / "characters", characters)
    one, two = tmp_path / "one", tmp_path / "two"
    assert run_cli(["exaggerate", str(CLIP), "-o", str(one), "--skin", str(characters / "hero.glb"), "--joint-map",
                    str(characters / "hero.map")], tmp_path, real=False)[0] == 0
    with open(characters / "hero.map", "a") as stream:
        stream.write("# a comment changes the bytes\n")
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(CLIP), "-o", str(two),
                           "--config", str(one / f"{CLIP.stem}.pipeline.toml")], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    warning = [line for line in done.stderr.splitlines() if line.startswith("WARNING")]
    assert len(warning) == 1 and "glb.joint_map" in warning[0] and "not the file the pipeline file recorded" in warning[0]
    assert "Traceback" not in done.stderr
    manifest = json.loads((two / f"{CLIP.stem}.json").read_text())
    assert any("glb.joint_map" in w for w in manifest["warnings"])
    recorded = resolve_config(None, (two / f"{CLIP.stem}.pipeline.toml").read_text()).glb
    assert recorded.joint_map_sha256 == hashlib.sha256((characters / "hero.map").read_bytes()).hexdigest()
    # A character given instead of the file's is another file: its hash is its own, no warning.
    three = tmp_path / "three"
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(CLIP), "-o", str(three),
                           "--config", str(one / f"{CLIP.stem}.pipeline.toml"), "--skin",
                           str(place / "work" / "characters" / "hero.glb"), "--joint-map",
                           str(place / "work" / "characters" / "hero.map")], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and "WARNING" not in done.stderr, done.stderr


def test_convert_takes_the_glb_settings_from_the_config_and_records_them(tmp_path):
    hero_folder = tmp_path / "characters"
    hero_folder.mkdir()
    convert(SIT, tmp_path / "made", preset="subtle", name="hero")
    shutil.copy(tmp_path / "made" / "hero.glb", hero_folder / "hero.glb")
    config = resolve_config("cartoon", None, {"glb": {"units": "cm", "influences": 8, "skin": str(hero_folder / "hero.glb")},
                                              "subjoints": {"per_link": 2}})
    first = convert(CLIP, tmp_path / "a", config, preset="cartoon")
    text = first.outputs["pipeline"].read_text()
    assert config_preset(text) == "cartoon"
    again = PipelineConfig.from_toml(text, folder=tmp_path / "a")
    assert again.glb.skin == os.path.join(tmp_path / "a", "../characters/hero.glb")
    os.chdir(tmp_path / "made")
    try:
        second = convert(CLIP, tmp_path / "b", again, preset="cartoon")
    finally:
        os.chdir(ROOT)
    assert_same_outputs(tmp_path / "a", tmp_path / "b")
    assert second.manifest["outputs"]["units"] == "cm"
    # Arguments win over the block; what was used is recorded.
    third = convert(CLIP, tmp_path / "c", again, units="m", influences=4, glb=True, skin=None)
    recorded = PipelineConfig.from_toml(third.outputs["pipeline"].read_text()).glb
    assert (recorded.units, recorded.influences, recorded.skin) == ("m", 4, "../characters/hero.glb")


def test_a_skin_given_as_an_object_is_noted_not_named(tmp_path):
    from mocap_exaggerate.io.skin import load_skin

    made = convert(SIT, tmp_path / "made", preset="subtle", name="hero")
    record = convert(CLIP, tmp_path / "out", load_preset("subtle"), skin=load_skin(made.outputs["glb"]))
    assert any("pipeline file names no skin" in note for note in record.notes)
    assert PipelineConfig.from_toml(record.outputs["pipeline"].read_text()).glb.skin == ""


@pytest.mark.parametrize(("table", "says"), [
    ({"units": "furlong"}, "glb.units"), ({"influences": 5}, "glb.influences"), ({"influences": True}, "glb.influences"),
    ({"enabled": "yes"}, "glb.enabled"), ({"skin": 3}, "glb.skin"), ({"skin": "a\x00b"}, "glb.skin"),
    ({"skin": "x.glb", "skin_sha256": "abc"}, "glb.skin_sha256"), ({"skin_sha256": "0" * 64}, "without glb.skin"),
    ({"joint_map": "x.map"}, "give the skin too"), ({"colour": "red"}, "unknown key glb.colour"),
])
def test_a_bad_glb_setting_names_its_key(table, says):
    with pytest.raises(ConfigError, match=says.replace(".", r"\.")):
        resolve_config("cartoon", None, {"glb": table})


def test_the_glb_units_are_the_writer_s():
    from mocap_exaggerate.config import GLB_UNITS
    from mocap_exaggerate.io.gltf import UNITS

    assert set(GLB_UNITS) == {"auto", *UNITS}


def test_naming_another_skin_forgets_the_recorded_hash():
    recorded = 'preset = "cartoon"\n[glb]\nskin = "a.glb"\nskin_sha256 = "' + "1" * 64 + '"\n'
    assert resolve_config(None, recorded, {"glb": {"skin": "b.glb"}}).glb.skin_sha256 == ""
    assert resolve_config(None, recorded, {"glb": {"units": "cm"}}).glb.skin_sha256 == "1" * 64
    assert resolve_config(None, recorded, {"glb": {"skin": ""}}).glb.skin == ""


def test_relative_paths_of_a_file_are_taken_from_its_folder(tmp_path):
    text = '[glb]\nskin = "../chars/x.glb"\njoint_map = "/abs/x.map"\n'
    config = resolve_config("cartoon", text, config_folder=tmp_path / "out")
    assert config.glb.skin == os.path.join(tmp_path / "out", "../chars/x.glb") and config.glb.joint_map == "/abs/x.map"
    assert resolve_config("cartoon", text).glb.skin == "../chars/x.glb"  # no folder: as written


def test_a_path_on_another_drive_is_written_whole(tmp_path, monkeypatch):
    from mocap_exaggerate.jobs import job

    def no_way(path, start):
        raise ValueError("path is on mount 'D:', start on mount 'C:'")

    skin = tmp_path / "skin.npz"
    skin.write_bytes(b"not read here")
    monkeypatch.setattr(job.os.path, "relpath", no_way)
    recorded = job.recorded_config(load_preset("cartoon"), tmp_path / "out", glb=True, units="auto", influences=4,
                                   skin=skin)
    assert recorded.glb.skin == skin.resolve().as_posix()


def test_the_parameters_change_with_every_glb_option():
    config = load_preset("cartoon")
    base = parameters_digest(config)
    changed = [parameters_digest(config, glb=False), parameters_digest(config, units="cm"),
               parameters_digest(config, influences=8), parameters_digest(config, preset="looney")]
    assert len({base, *changed}) == 1 + len(changed)
    # The [glb] block counts as what the job used, passed as these arguments; not twice.
    in_block = replace(config, glb=replace(config.glb, units="cm", influences=8))
    assert parameters_digest(in_block, units="cm", influences=8) == parameters_digest(config, units="cm", influences=8)


def test_resume_redoes_a_clip_whose_glb_options_changed(tmp_path):
    library = tmp_path / "mocap"
    library.mkdir()
    shutil.copy(CLIP, library / "run.bvh")
    runner = CliRunner()
    out = str(tmp_path / "out")
    first = runner.invoke(cli, ["batch", str(library), out, "-j", "1", "--subjoints", "2", "--json"])
    assert first.exit_code == 0, first.stderr
    same = runner.invoke(cli, ["batch", str(library), out, "-j", "1", "--subjoints", "2", "--resume", "--json"])
    assert json.loads(same.stdout.splitlines()[-1])["status"] == "skipped"
    for args in (["--units", "cm"], ["--influences", "8"], ["--set", "glb.units=dm"]):
        again = runner.invoke(cli, ["batch", str(library), out, "-j", "1", "--subjoints", "2", "--resume", "--json",
                                    *args])
        assert json.loads(again.stdout.splitlines()[-1])["status"] == "converted", args
