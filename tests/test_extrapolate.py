from dataclasses import replace

import numpy as np
import pytest

from mocap_exaggerate import load_preset
from mocap_exaggerate.analysis.limbs import find_limbs
from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.core.timing import gaussian_average, parse_duration
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.stages.contacts import find_ground
from mocap_exaggerate.stages.extrapolate import ExtrapolateConfig, crouch_lift, extrapolate

from .helpers import SAMPLE_DIR, shared


def test_omega_one_is_the_identity(sample_clip):
    world = read_bvh(sample_clip)[0].world_positions()
    assert np.array_equal(extrapolate(world, sigma=24.0, omega=1.0), world)


def test_sinusoid_matches_the_closed_form():
    # j(t) = A sin(2 pi t / T); its Gaussian average is exp(-(2 pi sigma / T)^2 / 2) j(t), so
    # e(t) = (omega + (1 - omega) g) j(t). The clip spans whole periods from a zero crossing,
    # where point reflection continues the sine exactly, so the ends obey it too.
    period, sigma, omega, amplitude = 60.0, 6.0, 5.0, 3.0
    t = np.arange(0, 4 * period + 1)
    j = amplitude * np.sin(2 * np.pi * t / period)
    world = np.stack([j, 2 * j, -j], axis=-1)[:, None, :]
    gain = np.exp(-((2 * np.pi * sigma / period) ** 2) / 2)
    expected = (omega + (1 - omega) * gain) * world
    out = extrapolate(world, sigma=sigma, omega=omega)
    assert np.max(np.abs(out - expected)) < 1e-3 * amplitude


def test_constant_velocity_is_untouched_even_at_the_ends():
    # A root walking in a straight line at constant speed, far from the origin.
    t = np.arange(200.0)
    world = np.stack([1000 + 0.7 * t, np.full_like(t, 90.0), -500 + 0.2 * t], axis=-1)[:, None, :]
    out = extrapolate(world, sigma=20.0, omega=5.0)
    assert np.max(np.abs(out - world)) < 1e-9


def test_standing_still_far_from_origin_stays_put():
    world = np.full((50, 3, 3), 123.0)
    assert np.allclose(gaussian_average(world, 10.0), world)
    assert np.allclose(extrapolate(world, sigma=10.0, omega=8.0), world)


def test_weights_scale_each_joints_deviation():
    rng = np.random.default_rng(3)
    world = np.cumsum(rng.normal(size=(300, 3, 3)), axis=0)
    base = extrapolate(world, sigma=8.0, omega=3.0)
    out = extrapolate(world, sigma=8.0, omega=3.0, weights=np.array([0.0, 1.0, 2.0]))
    assert np.array_equal(out[:, 0], world[:, 0])
    assert np.allclose(out[:, 1], base[:, 1])
    assert np.allclose(out[:, 2] - world[:, 2], 2 * (base[:, 2] - world[:, 2]))


def test_batched_equals_joint_by_joint(sample_clip):
    world = read_bvh(sample_clip)[0].world_positions()
    whole = extrapolate(world, sigma=12.0, omega=4.0)
    for j in (0, 5, 20):
        assert np.allclose(whole[:, j : j + 1], extrapolate(world[:, j : j + 1], sigma=12.0, omega=4.0))


def test_sigma_in_seconds_is_frame_rate_independent():
    # The same motion sampled at 60 and 120 fps, sigma in seconds: same exaggeration.
    def clip(fps):
        t = np.linspace(0, 3, 3 * fps + 1)
        x = np.sin(2 * np.pi * 0.8 * t) + 0.3 * np.sin(2 * np.pi * 2.1 * t)
        return t, np.stack([x, x**2, 0 * x], axis=-1)[:, None, :]

    config = ExtrapolateConfig(sigma="0.1s", omega=4.0)
    t60, w60 = clip(60)
    t120, w120 = clip(120)
    e60 = extrapolate(w60, sigma=config.sigma_frames(1 / 60), omega=4.0)
    e120 = extrapolate(w120, sigma=config.sigma_frames(1 / 120), omega=4.0)
    assert np.max(np.abs(e120[::2] - e60)) < 0.02


@pytest.mark.parametrize(
    "value, frames",
    [(0.2, 24.0), ("0.2s", 24.0), ("0.2", 24.0), ("200ms", 24.0), ("18f", 18.0), ("18 frames", 18.0), ("0", 0.0)],
)
def test_parse_duration(value, frames):
    assert parse_duration(value, 1 / 120) == pytest.approx(frames)


@pytest.mark.parametrize("value", ["fast", "-1s", "1h", "", "1e"])
def test_bad_sigma_is_a_config_error_naming_it(value):
    with pytest.raises(ConfigError, match="sigma"):
        ExtrapolateConfig(sigma=value)


@pytest.mark.parametrize("omega", [-1.0, 51.0, float("nan")])
def test_bad_omega_is_a_config_error(omega):
    with pytest.raises(ConfigError, match="omega"):
        ExtrapolateConfig(omega=omega)


def test_shape_is_checked():
    with pytest.raises(ValueError, match=r"positions must be \(F, J, 3\), got \(120, 31\)"):
        extrapolate(np.zeros((120, 31)), sigma=2.0, omega=2.0)


@pytest.mark.parametrize("sigma", [0.6, 3.0, 17.5, 60.0])
def test_gaussian_average_equals_scipys_filter_on_the_padded_clip(sample_clip, sigma):
    from scipy.ndimage import gaussian_filter1d

    world = read_bvh(sample_clip)[0].world_positions()
    radius = int(4.0 * sigma + 0.5)
    padded = np.pad(world, [(radius, radius), (0, 0), (0, 0)], mode="reflect", reflect_type="odd")
    expected = gaussian_filter1d(padded, sigma, axis=0, mode="nearest", truncate=4.0)[radius:-radius]
    np.testing.assert_allclose(gaussian_average(world, sigma), expected, rtol=0, atol=1e-9 * np.abs(world).max())


# ---------------------------------------------------------------------------- issue 11: a band, not the noise


def _swing_and_jitter(fps=120.0, seconds=4.0, seed=11):
    t = np.arange(0.0, seconds, 1.0 / fps)
    swing = np.sin(2 * np.pi * 0.8 * t)  # a 1.25 s swing
    jitter = np.random.default_rng(seed).normal(scale=0.002, size=t.shape)  # marker noise
    world = np.zeros((len(t), 1, 3))
    world[:, 0, 0] = swing
    return world, jitter


def test_jitter_passes_through_unamplified_while_the_swing_is_exaggerated():
    world, jitter = _swing_and_jitter()
    noisy = world.copy()
    noisy[:, 0, 0] += jitter
    sigma, smooth = 0.2 * 120, 0.05 * 120
    core = slice(2 * int(sigma), -2 * int(sigma))  # away from the reflected ends
    band = extrapolate(world, sigma=sigma, omega=4.0, smooth=smooth)
    # The swing: its deviation from a 0.2 s average, (1 - 0.60) of it, amplified 3x on top: about 2.1x.
    assert np.abs(band[core, 0, 0]).max() > 1.8
    # The jitter: what the noisy clip adds to the output, compared with the jitter itself.
    added = extrapolate(noisy, sigma=sigma, omega=4.0, smooth=smooth)[core, 0, 0] - band[core, 0, 0]
    paper = extrapolate(noisy, sigma=sigma, omega=4.0)[core, 0, 0] - extrapolate(world, sigma=sigma, omega=4.0)[core, 0, 0]
    assert np.std(added) < 1.25 * np.std(jitter[core])  # passed through, barely touched
    assert np.std(paper) > 3.0 * np.std(jitter[core])  # eq. (1) multiplies it by nearly omega


def test_the_exaggeration_fades_in_at_the_first_frame_and_out_at_the_last():
    world, _ = _swing_and_jitter()
    world = world + np.array([0.0, 0.0, 3.0])  # start mid-swing, away from the origin
    world[:, 0, 0] += 0.3
    out = extrapolate(world, sigma=24.0, omega=5.0, smooth=6.0, ramp=24.0)
    assert np.array_equal(out[0], world[0]) and np.array_equal(out[-1], world[-1])
    # No jump where a kept rest pose would end: the first steps are the capture's, give or take.
    steps = np.linalg.norm(np.diff(out[:4, 0], axis=0), axis=-1)
    captured = np.linalg.norm(np.diff(world[:4, 0], axis=0), axis=-1)
    assert np.all(steps <= 1.1 * captured + 1e-12)
    assert np.abs(out[48:-48] - world[48:-48]).max() > 0.5  # and in between it is exaggerated


@pytest.mark.parametrize("max_speed", [1.5, 2.0])
def test_no_joint_moves_faster_than_max_speed_times_its_own_top_captured_speed(sample_clip, max_speed):
    world = read_bvh(sample_clip)[0].world_positions()
    out = extrapolate(world, sigma=24.0, omega=5.0, smooth=6.0, max_speed=max_speed)
    top = np.linalg.norm(np.diff(world, axis=0), axis=-1).max(axis=0)
    fastest = np.linalg.norm(np.diff(out, axis=0), axis=-1).max(axis=0)
    moving = top > 1e-9
    assert np.all(fastest[moving] <= (max_speed + 0.02) * top[moving])
    free = extrapolate(world, sigma=24.0, omega=5.0, smooth=6.0)
    assert (np.linalg.norm(np.diff(free, axis=0), axis=-1).max(axis=0)[moving] / top[moving]).max() > max_speed + 0.2
    # The extremes of the poses keep most of their exaggeration.
    assert np.abs(out - world).mean() > 0.6 * np.abs(free - world).mean()



@pytest.mark.xfail(strict=True, reason="known: the speed limit's margin is taken on every frame (docs/status.md)")
def test_a_fast_moment_calms_only_itself_not_the_rest_of_the_clip():
    """The speed limit should be local: a flick at one moment should leave other joints, and frames far
    from it, as they were. Its margin of 0.98 is taken on every frame of every pass, over or not, so
    one fast frame calms every joint of the whole clip by 2 % a pass. Taking it only where a step is
    over keeps 4 % more of calm frames' exaggeration on the shared clips. Without a floor on a link's
    squash that tipped the looney amc2bvh jump past the quality bar for twist flips (57.9 -> 60.6
    degrees in a frame, its upper arm squashed to 15 % of its length); with the floor (correct.min_length,
    springs.min_length) it takes the cartoon sit-down's jerk ratio from 1.91 to 1.99, at the bar of 2.0
    (docs/status.md)."""
    # Slow swings (a 600-frame period against sigma 12): exaggerated about 1.03x, well within the limit.
    t = np.arange(1200.0)[:, None, None]
    world = 40.0 * np.sin(2 * np.pi * t / 600.0 + np.arange(3.0)[None, :, None]) * np.array([1.0, 0.5, 0.2])
    settings = dict(sigma=12.0, omega=5.0, smooth=6.0, max_speed=1.75)
    before = extrapolate(world, **settings)
    assert np.allclose(before, extrapolate(world, **(settings | {"max_speed": 0.0})))  # nothing was over
    jerked = world.copy()  # one joint's quick flick (a fifth of a second)
    jerked[:, 1, 0] += 20.0 * np.exp(-0.5 * ((np.arange(1200.0) - 600.0) / 5.0) ** 2)
    after = extrapolate(jerked, **settings)
    assert not np.allclose(after, extrapolate(jerked, **(settings | {"max_speed": 0.0})))  # the flick was over
    top = np.linalg.norm(np.diff(jerked, axis=0), axis=-1).max(axis=0)
    assert np.linalg.norm(np.diff(after, axis=0), axis=-1).max(axis=0)[1] <= 1.75 * top[1] * (1 + 1e-9)
    reach = 48 + 4 * (2 * 4 + 1) + 1  # the band (4 sigma) and the limit's passes (radius sigma / 3 each side)
    far = np.r_[: 600 - reach, 600 + reach + 1 : len(world)]
    assert np.array_equal(after[:, [0, 2]], before[:, [0, 2]])
    assert np.allclose(after[far, 1], before[far, 1], rtol=0.0, atol=1e-9)

def test_a_joint_standing_still_stays_where_it_was_captured():
    fps, sigma = 120.0, 0.3 * 120
    t = np.arange(0.0, 6.0, 1.0 / fps)
    x = np.clip((t - 2.5) / 0.5, 0.0, 1.0)  # still 2.5 s, a half-second move, still again
    world = np.zeros((len(t), 1, 3))
    world[:, 0, 0] = 10.0 * x * x * (3 - 2 * x)
    still = 0.05 * 170.0 / fps  # 0.05 body heights a second for a 170-unit body, per frame
    out = extrapolate(world, sigma=sigma, omega=5.0, smooth=6.0, still=still)
    plain = extrapolate(world, sigma=sigma, omega=5.0, smooth=6.0)
    waiting = (t < 2.5 - 2.2 * sigma / fps) | (t > 3.0 + 2.2 * sigma / fps)
    assert np.abs(plain[waiting] - world[waiting]).max() > 0.05  # the average drifts over the wait...
    assert np.array_equal(out[waiting], world[waiting])  # ...the joint does not
    assert np.abs(out - world).max() > 1.0  # and the move itself is exaggerated (anticipation, overshoot)


def test_the_torso_rides_with_the_root_and_swings_a_share_of_its_own():
    world, _ = _swing_and_jitter()
    root = world[:, 0]
    body = np.stack([root, root + [0.0, 5.0, 0.0], root + [0.0, 5.0, 0.0] + world[:, 0] * [0.0, 0.0, 0.5]], axis=1)
    out = extrapolate(body, sigma=24.0, omega=5.0, smooth=6.0, torso=(np.array([1, 2]), 0.5))
    free = extrapolate(body, sigma=24.0, omega=5.0, smooth=6.0)
    # Joint 1 moves exactly as the root: it keeps its offset, whatever the torso share.
    assert np.allclose(out[:, 1] - out[:, 0], [0.0, 5.0, 0.0])
    # Joint 2's own swing (along z) is exaggerated half as much.
    own, free_own = out[:, 2, 2] - body[:, 2, 2], free[:, 2, 2] - body[:, 2, 2]
    assert np.allclose(own, 0.5 * free_own)


def test_smooth_and_max_speed_are_checked():
    assert ExtrapolateConfig(smooth="0s", max_speed=0).max_speed == 0
    for bad in ({"max_speed": 0.5}, {"smooth": "-1s"}, {"still": -1.0}, {"torso": float("nan")}):
        with pytest.raises(ConfigError, match="extrapolate"):
            ExtrapolateConfig(**bad)
    # smooth never takes the whole band: at most half of sigma is used.
    assert ExtrapolateConfig(sigma="0.04s", smooth="0.05s").smooth_frames(1 / 100) == pytest.approx(2.0)


def test_time_on_another_axis_and_zero_weights_in_the_torso(sample_clip):
    world = read_bvh(sample_clip)[0].world_positions()
    common = dict(sigma=24.0, omega=4.0, smooth=6.0, ramp=24.0, max_speed=1.75, torso=(np.array([3, 4, 5]), 0.5))
    weights = np.ones(world.shape[1])
    weights[[4, 7]] = 0.0
    along = extrapolate(world, weights=weights, **common)
    across = extrapolate(world.swapaxes(0, 1), weights=weights, axis=1, **common)
    assert np.allclose(across.swapaxes(0, 1), along)
    # A weight of 0 keeps a joint as captured, in the torso too.
    assert np.array_equal(along[:, [4, 7]], world[:, [4, 7]])


@pytest.mark.parametrize("make", [
    lambda v: __import__("mocap_exaggerate.stages.correct", fromlist=["x"]).CorrectConfig(smooth=v),
    lambda v: __import__("mocap_exaggerate.stages.contacts", fromlist=["x"]).ContactConfig(blend=v),
    lambda v: __import__("mocap_exaggerate.stages.contacts", fromlist=["x"]).TargetSpec(joint="rFoot", frame=10, window=v),
])
def test_time_settings_longer_than_10_s_are_refused_in_seconds_and_in_frames(make):
    """They once let through up to 10,000 s (the frame cap applied to seconds)."""
    for fine in ("9s", "500ms", "5000f", 2.0):
        make(fine)
    for absurd in ("3600s", "11s", "20000f", 3600.0):
        with pytest.raises(ConfigError, match="at most 10 s"):
            make(absurd)


def test_what_the_speed_limit_took_is_the_share_of_the_displacement_it_removed():
    """Known answer: a joint asked to move 2 and kept at 1 in every frame lost half; one untouched lost none."""
    from mocap_exaggerate.stages.extrapolate import Limited

    asked = np.array([[2.0, 1.0], [2.0, 1.0], [2.0, 0.0]])
    kept = np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 0.0]])
    assert np.allclose(Limited(asked, kept).taken(), [0.5, 0.0])
    assert np.allclose(Limited(np.zeros((3, 1)), np.zeros((3, 1))).taken(), [0.0])


def test_omega_that_saturates_says_so_and_the_manifest_records_it(sample_clip):
    """More omega against the speed limit: what it takes grows, and past a quarter of a joint's
    exaggeration the run says where and how much; under it, or with no limit, nothing is said."""
    from mocap_exaggerate.config import resolve_config
    from mocap_exaggerate.jobs.outputs import manifest
    from mocap_exaggerate.pipeline import run

    motion = read_bvh(sample_clip)[0]

    def ran(omega, max_speed=1.75):
        return run(motion, resolve_config("cartoon", None, {"extrapolate": {"omega": omega, "max_speed": max_speed},
                                                            "subjoints": {"enabled": False},
                                                            "springs": {"enabled": False}}))

    taken = [ran(omega).speed_report.taken for omega in (2, 8, 30)]
    assert taken[0] < taken[1] < taken[2] and taken[2] > 0.5, taken
    strong = ran(30)
    report = strong.speed_report
    said = [note for note in strong.notes if "speed limit" in note]
    assert len(said) == 1 and report.joints and report.joints[0][0] in said[0] and "max_speed" in said[0]
    assert all(share > 0.25 for _, share in report.joints)
    assert report.seconds is not None and 0 <= report.seconds[0] < report.seconds[1] <= motion.duration + 1e-9
    assert not [note for note in ran(1.2).notes if "speed limit" in note]
    assert ran(30, max_speed=0).speed_report is None  # no limit, nothing taken
    info = manifest(input_name="clip", input_hash="sha256:0", config=resolve_config("cartoon"), preset="cartoon",
                    result=strong, outputs={}, reader_warnings=[], frames_in=motion.num_frames, fps=motion.fps,
                    timings={})
    assert info["result"]["speed_limit"]["taken"] == round(report.taken, 4)
    assert said[0] in info["warnings"]


def test_a_sigma_under_a_frame_is_said(sample_clip):
    """``--sigma 0`` ran, said "max link stretch 1.00x" and nothing else (a new user's trial): an average
    over less than a frame is the motion itself. It is a warning now, and only where omega would do something."""
    from mocap_exaggerate.config import PipelineConfig
    from mocap_exaggerate.pipeline import run

    motion, _ = read_bvh(sample_clip)
    for sigma, omega, said in (("0", 3.0, True), ("0.5f", 3.0, True), ("0", 1.0, False), ("0.2s", 3.0, False)):
        config = PipelineConfig.from_dict({"extrapolate": {"sigma": sigma, "omega": omega}})
        warned = [w for w in run(motion, config).warnings if "extrapolate.sigma" in w]
        assert bool(warned) == said, (sigma, omega, warned)


# ---------------------------------------------------------------------------- the crouch floor


def test_the_crouch_floor_by_hand_and_only_past_its_knee():
    # Floor 0.5 of a captured height of 1: the room is 0.5, the knee two fifths of it (a drop of 0.2).
    captured = np.ones(6)
    height = np.array([1.3, 1.0, 0.85, 0.8, 0.4, -0.2])
    lift = crouch_lift(captured, height, 0.5)
    assert np.array_equal(lift[:4], np.zeros(4))  # above, at or under the knee: not lifted
    # A drop of 0.6 becomes 0.2 + 0.3 tanh(0.4 / 0.3): lifted by the rest.
    assert lift[4] == pytest.approx(0.6 - (0.2 + 0.3 * np.tanh(0.4 / 0.3)), abs=1e-12)
    assert np.all(height + lift > 0.5)  # eased into the floor, never on it, even from below the ground
    # The lift is the drop's excess past the soft floor: a deeper drop is lifted more, never less.
    drops = crouch_lift(np.ones(50), np.linspace(1.0, -1.0, 50), 0.5)
    assert np.all(np.diff(drops) >= 0) and np.all(np.diff(np.linspace(1.0, -1.0, 50) + drops) <= 0)


def _hips_ratio(motion, config) -> float:
    """The lowest, over frames, of the hips' height above the floor written over their captured height."""
    captured = motion.world_positions()
    ground = find_ground(motion.skeleton, captured)
    limbs = find_limbs(motion.skeleton)
    hips = [limbs[name].joints[0] for name in ("left_leg", "right_leg")]
    result = run(motion, config)
    written = result.world_positions[:, result.original_index]
    above = [ground.heights(p[:, hips].mean(axis=1)) - ground.floor for p in (written, captured)]
    return float((above[0] / above[1]).min())


def test_a_crouch_asked_to_stay_high_is_lifted_smoothly():
    # The amc2bvh jump at looney sinks its hips to 0.61 of their captured height as it crouches to take
    # off; with the crouch floor at 0.9 they stay above 0.9 of it, and nothing pops.
    from mocap_exaggerate.analysis.quality import motion_quality
    from mocap_exaggerate.config import resolve_config

    motion, _ = read_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", fps=120.0)
    free = resolve_config("looney", None, {"extrapolate": {"crouch": 0.0}})
    high = resolve_config("looney", None, {"extrapolate": {"crouch": 0.9}})
    assert _hips_ratio(motion, free) < 0.65
    assert _hips_ratio(motion, high) > 0.9
    quality = {name: motion_quality(motion, run(motion, config)) for name, config in (("free", free), ("high", high))}
    assert quality["high"]["jump_ratio"] <= quality["free"]["jump_ratio"] + 0.05
    assert quality["high"]["jerk_ratio"] <= quality["free"]["jerk_ratio"] + 0.05


def test_the_crouch_floor_leaves_a_root_kept_as_captured_and_needs_the_contacts():
    # --weight root=0 keeps the root's path as captured: the lift (driven by the thighs, still exaggerated)
    # does not move it. And with the contacts or the floor off nothing would put the feet back down after
    # the body is lifted: no lift then.
    from mocap_exaggerate.config import resolve_config
    from mocap_exaggerate.pipeline import pipeline_limbs, prepare
    from mocap_exaggerate.stages.extrapolate import extrapolate_stage

    motion, _ = read_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", fps=120.0)
    high = {"extrapolate": {"crouch": 0.9}}
    config = resolve_config("looney", None, {"extrapolate": {"crouch": 0.9, "weights": [["root", 0]]}})
    state = prepare(motion, config.input, limbs=pipeline_limbs(motion.skeleton, config))
    after = extrapolate_stage(state, config.extrapolate).positions[:, 0]
    assert np.abs(after - motion.world_positions()[:, 0]).max() < 1e-12 * motion.skeleton.height()
    for off in ({"enabled": False}, {"floor": False}):
        plain = run(motion, resolve_config("looney", None, {"contacts": off, "extrapolate": {"crouch": 0.0}}))
        asked = run(motion, resolve_config("looney", None, {"contacts": off, **high}))
        assert np.array_equal(asked.world_positions, plain.world_positions)


def test_a_jumps_crouch_no_longer_sinks_to_the_floor():
    # Found by an animator's review: the Daz jump-balance at cartoon took the hips from 0.32 to 0.08 of
    # the height above the floor (0.30 of their captured height): the legs crumpled into a heap.
    motion, _ = read_bvh(shared("wide/cmu_02_04_jump_balance_daz.bvh"))
    config = load_preset("cartoon")
    assert _hips_ratio(motion, replace(config, extrapolate=replace(config.extrapolate, crouch=0.0))) < 0.35
    assert _hips_ratio(motion, config) > 0.5


@pytest.mark.parametrize("value", [-0.1, 1.5, float("nan"), "deep", True])
def test_the_crouch_setting_is_checked(value):
    with pytest.raises(ValueError, match="extrapolate.crouch"):
        ExtrapolateConfig(crouch=value)
