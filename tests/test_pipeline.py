"""The pipeline end to end on real clips: invariants, presets, configs, determinism."""

from dataclasses import replace

import numpy as np
import pytest

from mocap_exaggerate import exaggerate, load_bvh
from mocap_exaggerate.analysis.limbs import _side_from_name, find_limbs
from mocap_exaggerate.analysis.tpose import detect_rest_frames
from mocap_exaggerate.config import PipelineConfig, load_preset, preset_names, resolve_config
from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.core.rotations import quat_angle
from mocap_exaggerate.io.bvh import format_bvh, read_bvh
from mocap_exaggerate.pipeline import prepare, run
from mocap_exaggerate.stages.extrapolate import resolve_weights

from .helpers import SAMPLE_DIR as ROOT_SAMPLE
from .helpers import all_clip_params, shared, shared_clip_params

IDENTITY = {"extrapolate": {"omega": 1.0}, "correct": {"enabled": False}, "springs": {"enabled": False}}


@pytest.mark.parametrize("path", all_clip_params())
def test_written_file_reproduces_the_computed_positions(path):
    motion, _ = read_bvh(path)
    result = run(motion, load_preset("looney"))
    written, _ = read_bvh(format_bvh(result.motion))
    assert written.skeleton.names == result.motion.skeleton.names
    assert [written.skeleton.names[i] for i in result.original_index] == list(motion.skeleton.names)
    assert all(len(c) == 6 for c in written.skeleton.channels)
    rotations, positions = written.forward_kinematics()
    assert np.max(np.abs(positions - result.world_positions)) <= 1e-4 * motion.skeleton.height()
    assert np.max(quat_angle(rotations, result.world_rotations)) <= 1e-4
    # Exaggeration did something: some link got longer than captured.
    assert result.max_link_stretch > 1.01


@pytest.mark.parametrize("path", all_clip_params())
@pytest.mark.parametrize("skeleton", ["sub", "original"])
def test_omega_one_with_correction_and_springs_off_gives_the_input_back(path, skeleton):
    motion, _ = read_bvh(path)
    result = run(motion, resolve_config("cartoon", None, {**IDENTITY, "output": {"skeleton": skeleton}}))
    written, _ = read_bvh(format_bvh(result.motion))
    height = motion.skeleton.height()
    captured_rot, captured_pos = motion.forward_kinematics()
    index = result.original_index
    assert np.max(np.abs(result.world_positions[:, index] - captured_pos)) <= 1e-6 * height
    assert np.max(quat_angle(result.world_rotations[:, index], captured_rot)) <= 1e-6
    written_rot, written_pos = written.forward_kinematics()
    assert np.max(np.abs(written_pos[:, index] - captured_pos)) <= 1e-5 * height
    assert np.max(quat_angle(written_rot[:, index], captured_rot)) <= 1e-4


EXPECTED_REST_FRAMES = {
    "cmu_01_01_forward_jumps": 1,
    "cmu_12_01_walk": 1,
    "cmu_09_01_run_daz": 4,
    "cmu_10_01_soccer_kick_daz": 5,
    "cmu_14_19_laugh_idle_daz": 5,
}


@pytest.mark.parametrize("path", shared_clip_params())
def test_rest_pose_detection_on_real_clips(path):
    # SOURCES.md: the cgspeed mb2 and Daz conversions start with a T-pose; the Daz ones then
    # settle for a few frames; the iClone, 3dsMax, amc2bvh, boxing, mocapbank and MakeHuman
    # files have none.
    motion, _ = read_bvh(path)
    assert detect_rest_frames(motion) == EXPECTED_REST_FRAMES.get(path.stem, 0)


def test_a_first_frame_the_root_teleports_from_is_a_rest_frame_whatever_its_pose():
    # CMU 07_04 (iClone): frame 0 stands at the origin in the clip's own pose (every iClone joint is
    # turned 180 degrees from identity, so the T-pose test cannot see it), then the root jumps 1.59
    # heights to where the walk starts. One frame, not the walk's first steps.
    motion = load_bvh(shared("wide/cmu_07_04_slow_walk_iclone.bvh"))
    assert detect_rest_frames(motion) == 1
    # The same teleport put on a clip that starts well: the sample jump's frame 0 moved 0.4 heights
    # (its header says 30 fps: the bar is 10 heights a second, 0.33 a frame).
    jump = load_bvh(ROOT_SAMPLE / "cmu_16_01_jump_amc2bvh.bvh")
    assert detect_rest_frames(jump) == 0
    local = jump.local_positions.copy()
    local[0, 0, 0] -= 0.4 * jump.skeleton.height()
    assert detect_rest_frames(replace(jump, local_positions=local)) == 1
    local[0, 0, 0] += 0.1 * jump.skeleton.height()  # 0.3 heights at 30 fps (9 a second): fast, not a teleport
    assert detect_rest_frames(replace(jump, local_positions=local)) == 0
    local[0, 0, 0] += 0.2 * jump.skeleton.height()  # 0.1 heights: a fast step
    assert detect_rest_frames(replace(jump, local_positions=local)) == 0
    # A fast run's real steps (0.056 heights at most over the shared clips) are not a teleport.
    assert detect_rest_frames(load_bvh(shared("cmu_09_01_run_daz.bvh"))) == 4


def test_rest_frames_are_written_unchanged_and_kept_out_of_the_filter(sample_clip):
    motion, _ = read_bvh(sample_clip)
    auto = run(motion, load_preset("cartoon"))
    assert auto.rest_frames == 4
    captured_rot, captured_pos = motion.forward_kinematics()
    assert np.allclose(auto.world_positions[:4, auto.original_index], captured_pos[:4])
    assert np.max(quat_angle(auto.world_rotations[:4, auto.original_index], captured_rot[:4])) < 1e-9
    keep = run(motion, resolve_config("cartoon", None, {"input": {"tpose": "keep"}}))
    # With the T-pose filtered along, the jump rings into the frames after it.
    ringing = np.abs(keep.world_positions[4:40] - auto.world_positions[4:40]).max()
    assert ringing > 0.01 * motion.skeleton.height()
    drop = run(motion, resolve_config("cartoon", None, {"input": {"tpose": "drop"}}))
    assert drop.motion.num_frames == motion.num_frames - 4
    assert np.allclose(drop.world_positions, auto.world_positions[4:])


def test_same_input_same_bytes(sample_clip):
    motion, _ = read_bvh(sample_clip)
    first = format_bvh(run(motion, load_preset("looney")).motion)
    second = format_bvh(run(read_bvh(sample_clip)[0], load_preset("looney")).motion)
    assert first == second


def test_library_entry_points(sample_clip, tmp_path):
    from mocap_exaggerate import save_bvh

    out = exaggerate(load_bvh(sample_clip), preset="subtle")
    save_bvh(out, tmp_path / "x.bvh")
    assert read_bvh(tmp_path / "x.bvh")[0].num_frames == out.num_frames
    with pytest.raises(TypeError):
        exaggerate(load_bvh(sample_clip), sigma=3)


def test_presets_load_and_are_ordered_by_strength(sample_clip):
    assert preset_names() == ["cartoon", "looney", "subtle"]
    motion, _ = read_bvh(sample_clip)
    stretch = {name: run(motion, load_preset(name)).max_link_stretch for name in preset_names()}
    assert 1.0 < stretch["subtle"] < stretch["cartoon"] < stretch["looney"]


def test_toml_round_trip_and_precedence():
    config = resolve_config(
        "looney",
        '[extrapolate]\nomega = 3.0\nsigma = "12f"\n[extrapolate.weights]\nHips = 0.0\n',
        {"extrapolate": {"omega": 2.5}, "correct": {"enabled": False}},
    )
    assert config.extrapolate.omega == 2.5  # flag beats file
    assert config.extrapolate.sigma == "12f"  # file beats preset
    assert config.correct.max_stretch == load_preset("looney").correct.max_stretch  # preset fills the rest
    assert config.correct.enabled is False
    assert config.extrapolate.weights == (("Hips", 0.0),)
    again = PipelineConfig.from_toml(config.to_toml())
    assert again == config


@pytest.mark.parametrize(
    "text, words",
    [
        ("[extrapolat]\nomega = 2\n", "unknown block [extrapolat]"),
        ("[extrapolate]\nomegaa = 2\n", "unknown key extrapolate.omegaa"),
        ("[extrapolate]\nomega = 'x'\n", "extrapolate.omega"),
        ("[correct]\ndelta = 0\n", "correct.delta"),
        ("[input]\ntpose = 'sometimes'\n", "input.tpose"),
        ("[extrapolate\n", "not valid TOML"),
        ("[extrapolate.weights]\nHips = 'zero'\n", "weights"),
        ("[correct]\nenabled = 'yes'\n", "correct.enabled must be true or false"),
        ("[springs]\nblend = 1.5\n", "springs.blend must be a number in [0, 1]"),
        ("[subjoints]\ngroups = 'arm'\n", "subjoints.groups must be a list"),
        ("[output]\nskeleton = 'both'\n", "output.skeleton"),
    ],
)
def test_bad_config_names_file_and_key(text, words):
    with pytest.raises(ConfigError) as caught:
        resolve_config("cartoon", text, None, config_source="mine.toml")
    assert str(caught.value).startswith("mine.toml: ")
    assert words in str(caught.value)


def test_unknown_preset():
    with pytest.raises(ConfigError, match="unknown preset 'wild'.*cartoon"):
        resolve_config("wild")


def test_weights_by_joint_pattern_and_limb(sample_clip):
    skeleton = read_bvh(sample_clip)[0].skeleton
    weights = resolve_weights(skeleton, (("left_arm", 2.0), ("l*", 3.0), ("hip", 0.0), ("lHand", 5.0)))
    index = skeleton.index
    assert weights[index("hip")] == 0.0
    assert weights[index("lHand")] == 5.0
    assert weights[index("lForeArm")] == 3.0  # pattern after limb wins
    assert weights[index("lIndex1")] == 5.0  # a finger rides on its hand: it takes the hand's weight
    assert weights[index("rShldr")] == 1.0
    only_limb = resolve_weights(skeleton, (("left_arm", 2.0),))
    arm = {index(n) for n in ("lShldr", "lForeArm", "lHand", "lIndex1", "lThumb2")}
    assert set(np.flatnonzero(only_limb == 2.0)) >= arm
    assert only_limb[index("lCollar")] == 1.0
    with pytest.raises(ConfigError, match="no joint or limb matches 'Tail'"):
        resolve_weights(skeleton, (("Tail", 1.0),))


def test_weight_zero_keeps_a_joint_as_captured(sample_clip):
    motion, _ = read_bvh(sample_clip)
    config = resolve_config("cartoon", None, {"extrapolate": {"weights": {"hip": 0.0}}, "correct": {"enabled": False},
                                              "springs": {"enabled": False}})
    result = run(motion, config)
    assert np.allclose(result.world_positions[:, 0], motion.world_positions()[:, 0])


HUMANOID_LIMBS = ["left_arm", "right_arm", "left_leg", "right_leg", "spine", "neck"]


@pytest.mark.parametrize("path", shared_clip_params())
def test_limbs_found_on_every_shared_clip(path):
    motion = read_bvh(path)[0]
    skeleton = motion.skeleton
    limbs = find_limbs(skeleton)
    assert list(limbs) == HUMANOID_LIMBS
    # Rest poses are not reliable (Reallusion's has zero rotations meaning legs up), so look at
    # the captured motion: over most frames a leg goes down from thigh to ankle, below the arms.
    world = motion.world_positions()
    up = skeleton.up_axis()
    for side in ("left", "right"):
        arm, leg = limbs[f"{side}_arm"], limbs[f"{side}_leg"]
        assert np.median(world[:, leg.base, up] - world[:, leg.end, up]) > 0
        assert np.median(world[:, arm.base, up] - world[:, leg.end, up]) > 0
        assert np.median(world[:, limbs["neck"].end, up] - world[:, limbs["spine"].base, up]) > 0
        # Where names carry a side, the limb found for that side carries it too.
        for joint in arm.joints + leg.joints:
            named = _side_from_name(skeleton.names[joint])
            assert named in (None, side), skeleton.names[joint]


def test_limb_names_on_a_cmu_skeleton():
    skeleton = read_bvh(shared("cmu_16_01_jump_amc2bvh.bvh"))[0].skeleton
    names = {k: [skeleton.names[j] for j in v.joints] for k, v in find_limbs(skeleton).items()}
    assert names["left_arm"] == ["lhumerus", "lradius", "lwrist"]
    assert names["right_leg"] == ["rfemur", "rtibia", "rfoot"]
    assert names["neck"] == ["lowerneck", "upperneck", "head"]


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=40, deadline=None)
@given(
    omega=st.sampled_from([0.0, 1.0, 50.0]),
    sigma=st.sampled_from(["0f", "0.5f", "1s", "200f", "1000f"]),
    threshold=st.sampled_from([0.0, 10.0]),
    delta=st.sampled_from([1e-3, 1.0]),
    max_stretch=st.sampled_from([1.0, 10.0]),
    per_link=st.sampled_from([1, 32]),
    stiffness=st.sampled_from([1.0, 1e5]),
    link_stiffness=st.sampled_from([0.0, 1e5]),
    damping=st.sampled_from([0.0, 1e4]),
    blend=st.sampled_from([0.0, 1.0]),
    fps=st.sampled_from([None, 1.0, 10000.0]),
    sublink=st.sampled_from([None, "1%", "50%"]),
)
def test_no_nan_or_inf_at_the_limits_the_cli_accepts(
    omega, sigma, threshold, delta, max_stretch, per_link, stiffness, link_stiffness, damping, blend, fps, sublink
):
    motion = CLIP_FOR_SWEEP if fps is None else CLIP_FOR_SWEEP.replace(frame_time=1.0 / fps)
    subjoints = {"per_link": per_link} if sublink is None else {"sublink_length": sublink}
    config = resolve_config("cartoon", None, {
        "extrapolate": {"omega": omega, "sigma": sigma},
        "correct": {"threshold": threshold, "delta": delta, "max_stretch": max_stretch},
        "subjoints": subjoints,
        "springs": {"stiffness": stiffness, "link_stiffness": link_stiffness, "damping": damping, "blend": blend},
    })
    frames_sigma = config.extrapolate.sigma_frames(motion.frame_time)
    body = motion.num_frames - prepare(motion, config.input).first
    if frames_sigma > max(2 * body, 1000):  # wider than the clip allows: one clear refusal
        with pytest.raises(ConfigError, match="extrapolate.sigma .* takes at most .* twice its length"):
            run(motion, config)
        return
    result = run(motion, config)
    assert np.all(np.isfinite(result.world_positions))
    assert np.all(np.isfinite(result.world_rotations))
    data = format_bvh(result.motion)
    assert read_bvh(data)[0].num_frames == motion.num_frames


CLIP_FOR_SWEEP = read_bvh(ROOT_SAMPLE / "cmu_09_01_run_daz.bvh")[0].slice(slice(0, 40))


def test_running_a_one_frame_slice_leaves_the_clip_it_was_cut_from_alone(sample_clip):
    motion = read_bvh(sample_clip)[0]
    rotations, positions = motion.local_rotations.copy(), motion.local_positions.copy()
    run(motion.slice(slice(10, 11)), load_preset("cartoon"))
    assert np.array_equal(motion.local_rotations, rotations) and np.array_equal(motion.local_positions, positions)


def test_input_fps_in_the_config_is_honoured_by_run():
    motion, _ = read_bvh(shared("cmu_16_01_jump_amc2bvh.bvh"))
    config = load_preset("cartoon")
    retimed = run(motion, replace(config, input=replace(config.input, fps=120.0)))
    read_at_120 = run(read_bvh(shared("cmu_16_01_jump_amc2bvh.bvh"), fps=120.0)[0], config)
    assert retimed.motion.frame_time == pytest.approx(1 / 120)
    assert np.array_equal(retimed.world_positions, read_at_120.world_positions)


@pytest.mark.parametrize("preset", ["subtle", "cartoon", "looney"])
def test_omega_one_with_the_presets_corrections_on_is_still_the_identity(sample_clip, preset):
    # The held torso links and the accents must not shorten a link that is at its rest length.
    motion = read_bvh(sample_clip)[0]
    config = load_preset(preset)
    config = replace(config, extrapolate=replace(config.extrapolate, omega=1.0),
                     springs=replace(config.springs, enabled=False), subjoints=replace(config.subjoints, enabled=False),
                     output=replace(config.output, skeleton="original"))
    result = run(motion, config)
    assert np.abs(result.world_positions - motion.world_positions()).max() < 1e-9 * motion.skeleton.height()
    assert result.correct_report.frames_corrected == 0


def test_a_smoothing_wider_than_the_band_is_said_and_the_link_figure_skips_placeholders(sample_clip):
    motion = read_bvh(sample_clip)[0]
    config = load_preset("cartoon")
    result = run(motion, replace(config, extrapolate=replace(config.extrapolate, sigma="0.02s", smooth="0.2s")))
    assert any("extrapolate.smooth" in note and "half of sigma" in note for note in result.notes)
    # A link a micrometre long (Reallusion's pelvis) moved a centimetre is not a 10,000x stretch.
    from mocap_exaggerate.stages.correct import max_link_stretch

    parents = np.array([-1, 0, 1])
    lengths = np.array([0.0, 7e-5, 40.0])
    positions = np.array([[[0.0, 0, 0], [0.0, 1.0, 0], [0.0, 41.0, 0]]])
    assert max_link_stretch(positions, parents, lengths) == pytest.approx(1.0)


def test_stages_talk_through_typed_fields_and_one_with_nothing_to_do_is_not_listed(sample_clip):
    from mocap_exaggerate.pipeline import STAGES
    from mocap_exaggerate.stages.contacts import ConstraintPlan, constraints_stage
    from mocap_exaggerate.stages.state import StretchKey
    from mocap_exaggerate.stages.stretch import StretchEvent, StretchSpec

    motion = read_bvh(sample_clip)[0]
    config = load_preset("cartoon")
    quiet = replace(config, contacts=replace(config.contacts, enabled=False))
    assert "constraints" not in run(motion, quiet).stages  # no contacts, targets or stretches: nothing to do
    state = prepare(motion, quiet.input, limbs=find_limbs(motion.skeleton))
    assert constraints_stage(state, ConstraintPlan(quiet.contacts, ())) is state
    stretch = StretchSpec(limb="left_arm", start=20, end=40, scale=2.0)
    result = run(motion, replace(quiet, stretch=(stretch,)))
    assert result.stages[-3:] == ["springs", "constraints", "orient"]  # switched on by the stretch's key, not its settings
    (event,) = result.stretch.events
    assert isinstance(event, StretchEvent) and event.frames == (20, 40) and event.to_dict()["frames"] == [20, 40]
    (held,) = result.constraints["stretch_keys"]
    assert held["limb"] == "left_arm" and held["ratio"] == pytest.approx(1.0, abs=0.02)
    # The stretch stage adds its promises as typed keys the constraints stage reads.
    stretched = next(stage for stage in STAGES if stage.name == "stretch")
    after = stretched.apply(state, stretched.settings(replace(quiet, stretch=(stretch,))))
    (key,) = after.stretch_keys
    assert isinstance(key, StretchKey) and key.frame == 40 - after.first
    assert key.vectors.shape == (motion.num_frames - after.first, 3)
    # The extrapolation's speed limit reaches the later stages through the state, not their settings.
    extrapolated = STAGES[0].apply(state, config.extrapolate)
    assert extrapolated.speed_limit == config.extrapolate.max_speed and state.speed_limit == 0.0
