"""The command line through click's CliRunner: exit codes, messages, files written."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from mocap_exaggerate import convert
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate_cli.main import cli

from .helpers import MALFORMED, SAMPLE_DIR


@pytest.fixture
def runner():
    return CliRunner()


def test_exaggerate_writes_bvh_and_manifest(runner, sample_clip, tmp_path):
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path), "--sigma", "0.2s", "--omega", "5"])
    assert result.exit_code == 0, result.output
    bvh = tmp_path / "cmu_09_01_run_daz.bvh"
    info = json.loads((tmp_path / "cmu_09_01_run_daz.json").read_text())
    assert read_bvh(bvh)[0].num_frames == 149
    assert info["input"]["hash"].startswith("sha256:")
    assert info["config"]["extrapolate"]["omega"] == 5.0
    assert info["config"]["extrapolate"]["sigma"] == "0.2s"
    assert info["preset"] == "cartoon"
    assert info["version"]
    assert set(info["timings"]) >= {"read", "extrapolate", "correct", "write"}
    assert info["rest_frames"] == {"count": 4, "dropped": False}
    assert "wrote" in result.stderr


def test_outputs_are_deterministic(runner, sample_clip, tmp_path):
    for folder in ("a", "b"):
        assert runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / folder)]).exit_code == 0
    for suffix in (".bvh", ".glb", ".weights.npz"):
        name = "cmu_09_01_run_daz" + suffix
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), suffix
    a = json.loads((tmp_path / "a" / "cmu_09_01_run_daz.json").read_text())
    b = json.loads((tmp_path / "b" / "cmu_09_01_run_daz.json").read_text())
    a.pop("timings"), b.pop("timings")
    assert a == b


def test_refuses_to_overwrite_then_overwrites(runner, sample_clip, tmp_path):
    args = ["exaggerate", str(sample_clip), "-o", str(tmp_path)]
    assert runner.invoke(cli, args).exit_code == 0
    again = runner.invoke(cli, args)
    assert again.exit_code == 2
    assert "exists; pass --overwrite" in again.stderr
    assert runner.invoke(cli, args + ["--overwrite", "--omega", "2"]).exit_code == 0
    info = json.loads((tmp_path / "cmu_09_01_run_daz.json").read_text())
    assert info["config"]["extrapolate"]["omega"] == 2.0


def test_never_overwrites_its_input(runner, sample_clip, tmp_path):
    clip = tmp_path / "walk.bvh"
    shutil.copy(sample_clip, clip)
    before = clip.read_bytes()
    result = runner.invoke(cli, ["exaggerate", str(clip), "-o", str(tmp_path), "--overwrite"])
    assert result.exit_code == 2
    assert "would overwrite the input" in result.stderr
    assert clip.read_bytes() == before


def test_stdin_to_stdout(runner, sample_clip):
    result = runner.invoke(cli, ["exaggerate", "-", "-o", "-", "--preset", "subtle"], input=sample_clip.read_bytes())
    assert result.exit_code == 0, result.stderr
    motion, _ = read_bvh(result.stdout_bytes)
    assert motion.num_frames == 149
    assert all(len(c) == 6 for c in motion.skeleton.channels)


def test_stdin_to_folder_uses_name(runner, sample_clip, tmp_path):
    result = runner.invoke(cli, ["exaggerate", "-", "-o", str(tmp_path), "--name", "take1"], input=sample_clip.read_bytes())
    assert result.exit_code == 0, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take1.bvh", "take1.glb", "take1.json", "take1.pipeline.toml",
                                                             "take1.weights.npz"]


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_malformed_input_exit_2_one_line_no_output(runner, tmp_path, name):
    data, line, _ = MALFORMED[name]
    clip = tmp_path / "bad.bvh"
    clip.write_bytes(data)
    out = tmp_path / "out"
    result = runner.invoke(cli, ["exaggerate", str(clip), "-o", str(out)])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert f"bad.bvh:{line}:" in lines[0]
    assert isinstance(result.exception, SystemExit), result.exception  # a crash would be anything else
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize(
    "args, words",
    [
        (["--omega", "99"], "extrapolate.omega"),
        (["--sigma", "fast"], "sigma"),
        (["--delta", "0"], "correct.delta"),
        (["--weight", "Hips"], "NAME=WEIGHT"),
        (["--weight", "Tail=2"], "no joint or limb matches 'Tail'"),
        (["--preset", "wild"], "unknown preset"),
        (["--tpose", "maybe"], "maybe"),
        (["--config", "missing.toml"], "missing.toml"),
    ],
)
def test_bad_options_exit_2_naming_them(runner, sample_clip, tmp_path, args, words):
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "o"), *args])
    assert result.exit_code == 2, result.output
    assert words in result.stderr
    assert isinstance(result.exception, SystemExit), result.exception  # a crash would be anything else
    assert not (tmp_path / "o").exists()


def test_config_file_and_flags(runner, sample_clip, tmp_path):
    config = tmp_path / "p.toml"
    config.write_text('[extrapolate]\nomega = 3.0\n[extrapolate.weights]\nleft_arm = 2.0\n[correct]\nenabled = false\n')
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path), "--config", str(config), "--omega", "4"])
    assert result.exit_code == 0, result.stderr
    info = json.loads((tmp_path / "cmu_09_01_run_daz.json").read_text())
    assert info["config"]["extrapolate"]["omega"] == 4.0
    assert info["config"]["extrapolate"]["weights"] == {"left_arm": 2.0}
    assert info["stages"] == ["extrapolate", "subjoints", "springs", "constraints", "orient"]
    bad = tmp_path / "bad.toml"
    bad.write_text("[correct]\ndelta = 2\n")
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "x"), "--config", str(bad)])
    assert result.exit_code == 2
    assert "bad.toml: correct.delta" in result.stderr


def test_missing_input_and_folder_input(runner, tmp_path):
    result = runner.invoke(cli, ["exaggerate", str(tmp_path / "nope.bvh"), "-o", str(tmp_path)])
    assert result.exit_code == 2 and "no such file" in result.stderr
    result = runner.invoke(cli, ["exaggerate", str(tmp_path), "-o", str(tmp_path / "o")])
    assert result.exit_code == 2 and "is a folder" in result.stderr


def test_info(runner, sample_clip):
    result = runner.invoke(cli, ["info", str(sample_clip), "--limbs"])
    assert result.exit_code == 0, result.output
    for words in ["43 (+14 End Sites)", "ZXY x42", "149 at 120 fps", "1.233 s", "along Y", "4 leading",
                  "lShldr > lForeArm > lHand"]:
        assert words in result.output
    data = json.loads(runner.invoke(cli, ["info", str(sample_clip), "--json"]).output)
    assert data["frames"] == 149 and data["joints"] == 43 and data["rotation_orders"] == {"ZYX": 1, "ZXY": 42}


def test_info_fps_override(runner):
    from .helpers import shared

    clip = shared("cmu_16_01_jump_amc2bvh.bvh")
    result = runner.invoke(cli, ["info", str(clip), "--fps", "120", "--json"])
    data = json.loads(result.output)
    assert data["fps"] == 120.0
    assert data["duration_s"] == pytest.approx(321 / 120)


def test_presets_command(runner):
    result = runner.invoke(cli, ["presets"])
    assert result.exit_code == 0
    assert "cartoon (default):" in result.output and "looney:" in result.output and "subtle:" in result.output


@pytest.mark.parametrize("command", [[], ["exaggerate"], ["info"], ["presets"], ["preview"]])
def test_help_shows_an_example(runner, command):
    result = runner.invoke(cli, [*command, "--help"])
    assert result.exit_code == 0
    assert "Example" in result.output


def test_quiet_and_verbose(runner, sample_clip, tmp_path):
    quiet = runner.invoke(cli, ["-q", "exaggerate", str(sample_clip), "-o", str(tmp_path / "q")])
    assert quiet.exit_code == 0 and quiet.stderr == ""
    verbose = runner.invoke(cli, ["-v", "exaggerate", str(sample_clip), "-o", str(tmp_path / "v")])
    assert "rest-pose" in verbose.stderr


def test_fps_flag_changes_sigma_in_frames(runner, tmp_path):
    from .helpers import shared

    clip = shared("cmu_16_01_jump_amc2bvh.bvh")
    assert runner.invoke(cli, ["exaggerate", str(clip), "-o", str(tmp_path / "a")]).exit_code == 0
    assert runner.invoke(cli, ["exaggerate", str(clip), "-o", str(tmp_path / "b"), "--fps", "120"]).exit_code == 0
    a, _ = read_bvh(tmp_path / "a" / clip.name)
    b, _ = read_bvh(tmp_path / "b" / clip.name)
    assert b.frame_time == pytest.approx(1 / 120)
    assert not np.allclose(a.world_positions(), b.world_positions())


def test_rubber_options_and_original_skeleton(runner, sample_clip, tmp_path):
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "a"), "--subjoints", "6",
                                 "--blend", "0.7", "--stiffness", "100", "--damping", "4", "--link-stiffness", "50",
                                 "--spring-max-stretch", "1.3"])
    assert result.exit_code == 0, result.stderr
    info = json.loads((tmp_path / "a" / "cmu_09_01_run_daz.json").read_text())
    assert info["config"]["subjoints"]["per_link"] == 6
    assert info["config"]["springs"] == {"enabled": True, "stiffness": 100.0, "link_stiffness": 50.0,
                                         "damping": 4.0, "blend": 0.7, "max_stretch": 1.3, "min_length": 0.5}
    assert info["result"]["subjoints"] == read_bvh(tmp_path / "a" / "cmu_09_01_run_daz.bvh")[0].skeleton.num_joints
    assert ["chest", "lCollar", "lShldr", "lForeArm", "lHand"] in info["result"]["groups"]
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "b"), "--skeleton", "original"])
    assert result.exit_code == 0, result.stderr
    assert read_bvh(tmp_path / "b" / "cmu_09_01_run_daz.bvh")[0].skeleton.num_joints == 43
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "c"), "--no-subjoints",
                                 "--no-springs", "--sublink-length", "3%"])
    assert result.exit_code == 0, result.stderr
    info = json.loads((tmp_path / "c" / "cmu_09_01_run_daz.json").read_text())
    assert info["stages"] == ["extrapolate", "correct", "constraints", "orient"]


@pytest.mark.parametrize(
    "args, words",
    [
        (["--blend", "2"], "springs.blend"),
        (["--stiffness", "-5"], "springs.stiffness"),
        (["--subjoints", "0"], "subjoints.per_link"),
        (["--sublink-length", "long"], "subjoints.sublink_length"),
        (["--skeleton", "both"], "both"),
    ],
)
def test_bad_rubber_options_exit_2(runner, sample_clip, tmp_path, args, words):
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "o"), *args])
    assert result.exit_code == 2, result.output
    assert words in result.stderr
    assert not (tmp_path / "o").exists()


def test_info_groups(runner, sample_clip, tmp_path):
    result = runner.invoke(cli, ["info", str(sample_clip), "--groups"])
    assert result.exit_code == 0, result.output
    assert "group       chest | lCollar > lShldr > lForeArm > lHand" in result.output
    assert "group       hip | rButtock > rThigh > rShin > rFoot" in result.output
    assert "rigid       leftEye" in result.output
    assert "sub-joints  80: the default output's 123 joints" in result.output
    data = json.loads(runner.invoke(cli, ["info", str(sample_clip), "--groups", "--json"]).output)
    # The joints the default output writes (it said 103, the rubber hierarchy without the links' starts).
    written = convert(sample_clip, tmp_path, glb=False).outputs["bvh"]
    assert len(data["groups"]) == 5 and data["subjoints"] == read_bvh(written)[0].skeleton.num_joints == 123


def test_glb_options(runner, sample_clip, tmp_path):
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "a"), "--no-glb"])
    assert result.exit_code == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["cmu_09_01_run_daz.bvh", "cmu_09_01_run_daz.json",
                                                                  "cmu_09_01_run_daz.pipeline.toml"]
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "b"), "--units", "cm"])
    assert result.exit_code == 0, result.stderr
    info = json.loads((tmp_path / "b" / "cmu_09_01_run_daz.json").read_text())
    assert info["outputs"]["glb"] == "cmu_09_01_run_daz.glb" and info["outputs"]["units"] == "cm"
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "d"), "--influences", "8",
                                 "--skin", str(tmp_path / "b" / "cmu_09_01_run_daz.glb")])
    # A GLB made from this clip on the rubber skeleton (in cm) is a character for it: bound by name, the
    # sub-joints riding their links (`mocap_exaggerate.rig.binding`).
    assert result.exit_code == 0, result.stderr
    binding = json.loads((tmp_path / "d" / "cmu_09_01_run_daz.json").read_text())["skin_binding"]
    assert binding["by"]["name"] == 43 and binding["scale"] == pytest.approx(100.0, rel=1e-4)  # written in metres from cm
    for args, words in [(["--units", "furlong"], "units must be"), (["--skin", str(tmp_path / "none.npz")], "no such skin"),
                        (["--skin", str(sample_clip)], "skins are read from")]:
        result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "c"), *args])
        assert result.exit_code == 2 and words in result.stderr, result.stderr
        assert not (tmp_path / "c").exists()


def test_preview_writes_a_png(runner, sample_clip, tmp_path):
    target = tmp_path / "run.png"
    result = runner.invoke(cli, ["preview", str(sample_clip), "-o", str(target), "--frames", "3", "--preset", "looney"])
    assert result.exit_code == 0, result.stderr
    data = target.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    again = runner.invoke(cli, ["preview", str(sample_clip), "-o", str(target)])
    assert again.exit_code == 2 and "--overwrite" in again.stderr
    assert target.read_bytes() == data
    assert runner.invoke(cli, ["preview", str(sample_clip), "-o", str(tmp_path / "b.png"), "--frames", "3",
                               "--preset", "looney"]).exit_code == 0
    assert (tmp_path / "b.png").read_bytes() == data  # deterministic


TINY = {
    "root only": "ROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n}\n",
    "root and End Site": "ROOT Hips\n{\n  OFFSET 0 0 0\n"
                         "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
                         "  End Site\n  {\n    OFFSET 0 1 0\n  }\n}\n",
}


@pytest.mark.parametrize("name", sorted(TINY))
@pytest.mark.parametrize("frames", [1, 3])
def test_tiny_skeletons_and_single_frames_run_end_to_end(runner, tmp_path, name, frames):
    rows = "\n".join(f"{k} 0 0 0 {5 * k} 0" for k in range(frames))
    clip = tmp_path / "tiny.bvh"
    clip.write_text(f"HIERARCHY\n{TINY[name]}MOTION\nFrames: {frames}\nFrame Time: 0.1\n{rows}\n")
    result = runner.invoke(cli, ["exaggerate", str(clip), "-o", str(tmp_path / "out"), "--preset", "looney"])
    assert result.exit_code == 0, result.output
    motion, _ = read_bvh(tmp_path / "out" / "tiny.bvh")
    assert motion.num_frames == frames and np.all(np.isfinite(motion.world_positions()))
    assert (tmp_path / "out" / "tiny.glb").stat().st_size > 1000
    assert runner.invoke(cli, ["preview", str(clip), "-o", str(tmp_path / "p.png")]).exit_code == 0


# ---------------------------------------------------------------------------- as users run it: a real process


def command(*args, **kwargs):
    """``mocap-exaggerate ARGS`` in a new process (the installed module, as the console script runs it)."""
    import subprocess
    import sys

    kwargs.setdefault("stdout", subprocess.PIPE)
    return subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *map(str, args)],
                          stderr=subprocess.PIPE, text=True, timeout=120, **kwargs)


def test_verbosity_may_follow_the_subcommand(sample_clip, tmp_path):
    loud = command("exaggerate", sample_clip, "-o", tmp_path / "a", "--no-glb", "-v")
    assert loud.returncode == 0, loud.stderr
    assert "INFO" in loud.stderr and "rest-pose frame" in loud.stderr and "Traceback" not in loud.stderr
    quiet = command("exaggerate", sample_clip, "-o", tmp_path / "b", "--no-glb", "-q")
    assert quiet.returncode == 0 and quiet.stderr == ""
    before = command("-v", "info", sample_clip)
    assert before.returncode == 0 and "joints" in before.stdout


def test_a_reader_that_goes_away_gets_no_error_message(sample_clip):
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)  # like `| head` having exited: every write fails with EPIPE
    try:
        done = command("info", sample_clip, "--limbs", "--groups", stdout=write_end)
    finally:
        os.close(write_end)
    assert "Broken pipe" not in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_help_and_version_answer(tmp_path):
    done = command("--help")
    assert done.returncode == 0 and "exaggerate" in done.stdout
    assert command("--version").stdout.strip().endswith("0.1.0")


def test_set_reaches_any_setting_and_the_named_flags_win(tmp_path):
    # extrapolate.max_speed and springs.link_stiffness have no flag of their own.
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate",
                           str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh"), "-o", str(out), "--no-glb",
                           "--set", "extrapolate.max_speed=3", "--set", "springs.link_stiffness=90",
                           "--set", "extrapolate.smooth=0.1s", "--set", "springs.blend=0.2", "--blend", "0.3"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    from mocap_exaggerate.config import resolve_config

    written = resolve_config(None, (out / "cmu_09_01_run_daz.pipeline.toml").read_text())
    assert written.extrapolate.max_speed == 3 and written.springs.link_stiffness == 90
    assert written.extrapolate.smooth == "0.1s" and written.springs.blend == 0.3


@pytest.mark.parametrize(("setting", "says"), [
    ("x=1", "dotted key"), ("springs", "dotted key"), ("springs.nope=1", "unknown key springs.nope"),
    ("springs.blend=2", "springs.blend must be"), ("nope.blend=1", "unknown block"),
    ("extrapolate.max_speed=1e999", "max_speed"), ("springs.blend=[1,2]", "springs.blend"),
    ("springs.blend=" + "9" * 5000, "characters"), ("springs.blend=" + "x" * 5000, "characters"),
])
def test_a_bad_set_is_one_line_and_writes_nothing(tmp_path, setting, says):
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate",
                           str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh"), "-o", str(out), "--set", setting],
                          capture_output=True, text=True)
    assert done.returncode == 2 and says in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize(("option", "says"), [
    (["--sigma", "bad"], "sigma"), (["--units", "furlong"], "furlong"), (["--skin", "missing.glb"], "missing.glb"),
    (["--influences", "5"], "influences"), (["--path-file", "missing.json"], "missing.json"),
    (["--set", "glb.units=furlong"], "furlong"), (["--joint-map", "missing.map"], "give the skin too"),
])
def test_a_bad_option_is_said_before_an_existing_output(tmp_path, option, says):
    # Told about the option first: not "exists, pass --overwrite", then the option after --overwrite.
    out = tmp_path / "out"
    clip = str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh")
    main = [sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", clip, "-o", str(out)]
    assert subprocess.run(main + ["--no-glb"], capture_output=True).returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    done = subprocess.run(main + option, capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 2 and says in done.stderr and "exists" not in done.stderr, done.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


#: A bad value for every option of 'exaggerate' that takes one (and the GLB's settings by --set and
#: --config), with words of the one line that must say so.
BAD_OPTIONS = [
    (["--name", "../x"], "name"), (["--units", "furlong"], "glb.units"), (["--influences", "5"], "--influences"),
    (["--skin", "missing.glb"], "missing.glb"), (["--joint-map", "missing.map"], "give the skin too"),
    (["--skin", "hero.glb", "--joint-map", "missing.map"], "missing.map"), (["--path-file", "missing.json"], "missing.json"),
    (["--trails", "."], "directory"), (["--glb=yes"], "--glb"), (["--preset", "wild"], "unknown preset"),
    (["--preset", ""], "unknown preset"), (["--config", "missing.toml"], "missing.toml"), (["--config", ""], "empty"),
    (["--sigma", "bad"], "sigma"), (["--omega", "x"], "--omega"), (["--omega", "99"], "extrapolate.omega"),
    (["--weight", "Hips"], "NAME=WEIGHT"), (["--threshold", "-1"], "correct.threshold"), (["--delta", "0"], "correct.delta"),
    (["--max-stretch", "0.5"], "correct.max_stretch"), (["--max-iter", "0"], "correct.max_iter"),
    (["--subjoints", "0"], "subjoints.per_link"), (["--sublink-length", "long"], "subjoints.sublink_length"),
    (["--stiffness", "-5"], "springs.stiffness"), (["--link-stiffness", "-5"], "springs.link_stiffness"),
    (["--damping", "-1"], "springs.damping"), (["--blend", "2"], "springs.blend"), (["--skeleton", "both"], "--skeleton"),
    (["--bvh-positions", "sideways"], "--bvh-positions"), (["--stretch", "left_arm:20-60"], "--stretch"),
    (["--contacts", "on"], "--contacts"), (["--anchor", "moon"], "--anchor"), (["--target", "rFoot"], "JOINT@FRAME"),
    (["--tpose", "maybe"], "--tpose"), (["--fps", "nan"], "input.fps"), (["--root-offset", "both"], "--root-offset"),
    (["--up", "w"], "--up"), (["--set", "springs.blend=2"], "springs.blend"), (["--set", "glb.influences=5"], "glb.influences"),
    (["--set", "glb.skin=missing.glb"], "missing.glb"), (["--config", "glb.toml"], "glb.toml: glb.units"),
]


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A folder holding a run's outputs, and a character (this clip's own GLB, from another run) beside it."""
    folder = tmp_path_factory.mktemp("taken")
    clip = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
    result = CliRunner().invoke(cli, ["exaggerate", str(clip), "-o", str(folder / "character"), "--subjoints", "2"])
    assert result.exit_code == 0, result.stderr
    shutil.copy(folder / "character" / f"{clip.stem}.glb", folder / "hero.glb")
    (folder / "glb.toml").write_text('[glb]\nunits = "furlong"\n')
    result = CliRunner().invoke(cli, ["exaggerate", str(clip), "-o", str(folder / "out"), "--subjoints", "2"])
    assert result.exit_code == 0, result.stderr
    return folder


@pytest.mark.parametrize(("option", "says"), BAD_OPTIONS, ids=[" ".join(a) for a, _ in BAD_OPTIONS])
def test_every_option_is_checked_before_the_outputs_there(finished_run, monkeypatch, option, says):
    # An output folder with a finished run in it: the bad option is what is said, not "exists, pass --overwrite".
    monkeypatch.chdir(finished_run)
    out = finished_run / "out"
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    result = CliRunner().invoke(cli, ["exaggerate", str(SAMPLE_DIR / "cmu_09_01_run_daz.bvh"), "-o", str(out), *option])
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "exists" not in lines[0], result.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_the_glb_settings_come_from_a_config_file_and_the_flags_win(runner, sample_clip, tmp_path):
    config = tmp_path / "conf" / "p.toml"
    config.parent.mkdir()
    config.write_text('[glb]\nunits = "cm"\ninfluences = 8\n')
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "a"), "--config", str(config)])
    assert result.exit_code == 0, result.stderr
    info = json.loads((tmp_path / "a" / "cmu_09_01_run_daz.json").read_text())
    assert info["outputs"]["units"] == "cm" and info["config"]["glb"]["influences"] == 8
    result = runner.invoke(cli, ["exaggerate", str(sample_clip), "-o", str(tmp_path / "b"), "--config", str(config),
                                 "--units", "m", "--no-glb"])
    assert result.exit_code == 0, result.stderr
    info = json.loads((tmp_path / "b" / "cmu_09_01_run_daz.json").read_text())
    assert info["config"]["glb"] == {"enabled": False, "units": "m", "influences": 8, "usd": "", "fbx": False,
                                     "skin": "", "skin_sha256": "", "joint_map": "", "joint_map_sha256": ""}
    assert "glb" not in info["outputs"]


def test_a_saturated_omega_is_said_with_v_and_not_without(sample_clip, tmp_path):
    loud = command("exaggerate", sample_clip, "-o", tmp_path / "a", "--no-glb", "--omega", "30", "--no-subjoints", "-v")
    assert loud.returncode == 0, loud.stderr
    said = [line for line in loud.stderr.splitlines() if "speed limit" in line]
    assert len(said) == 1 and "extrapolate.max_speed" in said[0] and "%" in said[0], loud.stderr
    quiet = command("exaggerate", sample_clip, "-o", tmp_path / "b", "--no-glb", "--omega", "30", "--no-subjoints")
    assert quiet.returncode == 0 and "speed limit" not in quiet.stderr


def test_an_output_named_like_a_file_is_said_to_be_a_folder(tmp_path):
    """``-o walk_cartoon.bvh`` makes a folder of that name, the files inside: said once (it was silent)."""
    target = tmp_path / "walk_cartoon.bvh"
    done = command("exaggerate", SAMPLE_DIR / "cmu_09_01_run_daz.bvh", "-o", target, "--no-glb")
    assert done.returncode == 0 and "-o names a folder" in done.stderr and "'-o -'" in done.stderr, done.stderr
    assert (target / "cmu_09_01_run_daz.bvh").is_file()
    again = command("exaggerate", SAMPLE_DIR / "cmu_09_01_run_daz.bvh", "-o", target, "--no-glb", "--overwrite")
    assert again.returncode == 0 and "names a folder" not in again.stderr  # a folder already: nothing to say
