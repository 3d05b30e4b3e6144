"""Suspended mass-spring follow-through: identities, stability, and measured overshoot."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocap_exaggerate.config import load_preset
from mocap_exaggerate.core.errors import ConfigError
from mocap_exaggerate.core.timing import soft_limit
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.stages import springs
from mocap_exaggerate.stages.springs import (
    DAMPING_RANGE,
    STIFFNESS_RANGE,
    SpringConfig,
    limit_stretch,
    simulate_springs,
    spring_links,
    stable_link_stiffness,
    substeps_for,
)

from .helpers import SAMPLE_DIR, all_clip_params, shared

CHAIN = np.array([-1, 0, 1, 2, 3])
SETTINGS = dict(stiffness=150.0, link_stiffness=150.0, damping=6.0)


def moving_chain(velocity, frames=240, frame_time=1 / 120):
    """A straight 5-joint chain along Y translating with per-frame velocity (F, 3)."""
    rest = np.stack([np.zeros(5), np.arange(5.0), np.zeros(5)], 1)
    path = np.concatenate([[np.zeros(3)], np.cumsum(velocity[:-1] * frame_time, axis=0)])
    return rest[None] + path[:, None]


def test_blend_zero_is_the_identity():
    positions = np.random.default_rng(0).normal(size=(50, 5, 3))
    out = simulate_springs(positions, CHAIN, 1 / 60, blend=0.0, **SETTINGS)
    assert np.array_equal(out, positions)


def test_a_still_pose_stays_still():
    positions = np.repeat(np.random.default_rng(1).normal(size=(1, 5, 3)), 100, axis=0)
    out = simulate_springs(positions, CHAIN, 1 / 30, blend=1.0, **SETTINGS)
    assert np.max(np.abs(out - positions)) < 1e-12


def test_steady_gliding_trails_nothing():
    velocity = np.tile([3.0, 0.0, 1.0], (240, 1))
    positions = moving_chain(velocity)
    out = simulate_springs(positions, CHAIN, 1 / 120, blend=1.0, **SETTINGS)
    assert np.max(np.abs(out - positions)) < 1e-9


def test_a_motion_that_stops_dead_overshoots_and_settles():
    # Glide at 2 units/s along X for one second, then stop dead and hold for three.
    frame_time = 1 / 120
    velocity = np.zeros((480, 3))
    velocity[:120, 0] = 2.0
    positions = moving_chain(velocity, frames=480)
    out = simulate_springs(positions, CHAIN, frame_time, blend=1.0, **SETTINGS)
    ahead = out[:, :, 0] - positions[:, :, 0]  # (F, J) displacement along the motion
    after = ahead[121:]
    assert after.max() > 0.05  # overshoot past where the motion stopped, in units
    # Peaks of the wobble shrink: each half second holds less than the one before.
    windows = np.abs(after[:300].reshape(5, 60, -1)).max(axis=(1, 2))
    assert np.all(np.diff(windows) < 0), windows
    assert windows[-1] < 0.1 * windows[0]
    # Before the stop it glided with no lag.
    assert np.max(np.abs(ahead[:110])) < 1e-9


def test_compiled_kernel_equals_the_python_loop(sample_clip):
    motion, _ = read_bvh(sample_clip)
    positions = motion.world_positions()[4:60]
    kwargs = dict(stiffness=90.0, link_stiffness=400.0, damping=3.0, blend=0.7)
    fast = simulate_springs(positions, motion.skeleton.parents, motion.frame_time, **kwargs)
    slow = simulate_springs(positions, motion.skeleton.parents, motion.frame_time, compiled=False, **kwargs)
    assert np.allclose(fast, slow, atol=1e-9)
    assert not np.allclose(fast, positions)


@pytest.mark.parametrize("path", all_clip_params())
def test_the_compiled_time_loop_is_the_numpy_loop_on_every_clip(path):
    """core/_kernels.c's time loop against the NumPy one it stands in for, every particle of every clip
    (the whole skeleton suspended): the same bits, so an install without a C compiler writes the same
    bytes. Also where the follow-through is chaotic (the stiffest links the step can carry, no drag),
    where sums in any other order part from these by centimetres within seconds."""
    if springs._kernels is None:
        pytest.skip("core/_kernels.c was not built (no C compiler at install); the NumPy loop is what runs")
    motion, _ = read_bvh(path)
    positions = np.ascontiguousarray(motion.world_positions()[:400])
    links = spring_links(motion.skeleton.parents)
    for stiffness, link_stiffness, damping in ((150.0, 150.0, 8.0), (100.0, 1e5, 0.0)):
        substeps = substeps_for(motion.frame_time, stiffness, link_stiffness, links.degree)
        link_stiffness = stable_link_stiffness(motion.frame_time, link_stiffness, links.degree, substeps)
        args = (positions, links.link_a, links.link_b, motion.frame_time, substeps, stiffness, link_stiffness, damping)
        fast, numpy_loop = springs._integrate_compiled(*args), springs._integrate_vectorised(*args)
        assert fast.view(np.int64).tolist() == numpy_loop.view(np.int64).tolist()
        assert np.array_equal(fast[0], positions[0]) and not np.allclose(fast, positions)


def test_no_particle_suspended_leaves_the_motion_as_it_was():
    """No joint active (every link rigid): nothing to simulate, the positions come back (the compiled loop
    was handed no particles and refused them, and the NumPy loop could not shape them: a ValueError out of
    the pipeline either way)."""
    positions = np.random.default_rng(4).normal(size=(10, 3, 3))
    for compiled in (True, False):
        out = simulate_springs(positions, np.array([-1, 0, 1]), 1 / 30, blend=0.5, active=np.zeros(3, bool),
                               compiled=compiled, **SETTINGS)
        assert np.array_equal(out, positions)


def test_the_compiled_time_loop_refuses_what_it_cannot_read():
    """It checks its buffers, counts and indices: a ValueError, never a read outside an array."""
    if springs._kernels is None:
        pytest.skip("core/_kernels.c was not built (no C compiler at install)")
    kernels = springs._kernels
    follow, out, a, b = np.zeros((4, 3, 3)), np.zeros((4, 3, 3)), np.array([0, 1]), np.array([1, 2])
    kernels.springs(follow, out, a, b, 4, 3, 2, 0.1, 2, 150.0, 150.0, 8.0)  # a still pose stays still
    assert np.array_equal(out, follow)
    with pytest.raises(ValueError, match="outside"):
        kernels.springs(follow, out, a, np.array([1, 3]), 4, 3, 2, 0.1, 2, 150.0, 150.0, 8.0)
    with pytest.raises(ValueError, match="outside"):
        kernels.springs(follow, out, np.array([-1, 0]), b, 4, 3, 2, 0.1, 2, 150.0, 150.0, 8.0)
    with pytest.raises(ValueError, match="out"):
        kernels.springs(follow, out[:2], a, b, 4, 3, 2, 0.1, 2, 150.0, 150.0, 8.0)
    with pytest.raises(ValueError, match="substeps or constants"):
        kernels.springs(follow, out, a, b, 4, 3, 2, 0.1, 0, 150.0, 150.0, 8.0)
    with pytest.raises(ValueError, match="substeps or constants"):
        kernels.springs(follow, out, a, b, 4, 3, 2, float("nan"), 2, 150.0, 150.0, 8.0)
    with pytest.raises(ValueError, match="count|buffer"):
        kernels.springs(follow, out, a, b, 2**40, 2**40, 2, 0.1, 2, 150.0, 150.0, 8.0)
    frozen = out.copy()
    frozen.setflags(write=False)
    with pytest.raises(ValueError, match="read-only"):
        kernels.springs(follow, frozen, a, b, 4, 3, 2, 0.1, 2, 150.0, 150.0, 8.0)


def test_inactive_joints_are_copied():
    positions = np.random.default_rng(2).normal(size=(40, 5, 3))
    active = np.array([True, True, True, False, False])
    out = simulate_springs(positions, CHAIN, 1 / 60, blend=1.0, active=active, **SETTINGS)
    assert np.array_equal(out[:, 3:], positions[:, 3:])
    assert not np.allclose(out[:, :3], positions[:, :3])


def test_substeps_grow_with_link_stiffness_and_frame_time():
    assert substeps_for(1 / 120, 150.0, 150.0, 2) == 1
    assert substeps_for(1 / 24, 150.0, 1e5, 3) > substeps_for(1 / 120, 150.0, 1e5, 3) > 1


@settings(max_examples=40, deadline=None)
@given(
    stiffness=st.sampled_from([STIFFNESS_RANGE[0], 1.0, 300.0, STIFFNESS_RANGE[1]]),
    link_stiffness=st.sampled_from([STIFFNESS_RANGE[0], 50.0, STIFFNESS_RANGE[1]]),
    damping=st.sampled_from([DAMPING_RANGE[0], 0.5, 40.0, DAMPING_RANGE[1]]),
    blend=st.sampled_from([0.0, 0.5, 1.0]),
    frame_time=st.sampled_from([1 / 24, 1 / 120]),
    seed=st.integers(0, 1000),
)
def test_stable_for_every_value_the_cli_accepts(stiffness, link_stiffness, damping, blend, frame_time, seed):
    if stiffness == 0 and damping == 0:
        stiffness = 1.0  # the config refuses a body held by nothing
    SpringConfig(stiffness=stiffness, link_stiffness=link_stiffness, damping=damping, blend=blend)
    rng = np.random.default_rng(seed)
    positions = np.cumsum(rng.normal(scale=0.2, size=(60, 5, 3)), axis=0) + np.arange(5.0)[None, :, None]
    out = simulate_springs(positions, CHAIN, frame_time, stiffness=stiffness, link_stiffness=link_stiffness,
                           damping=damping, blend=blend)
    assert np.all(np.isfinite(out))
    # Bounded: the follow-through never flings a particle off by more than the motion's extent.
    extent = np.ptp(positions.reshape(-1, 3), axis=0).max()
    assert np.max(np.abs(out - positions)) < 10 * extent


@pytest.mark.parametrize("field, value", [("stiffness", -1.0), ("link_stiffness", 2e5), ("damping", -0.1),
                                          ("blend", 1.5), ("max_stretch", 0.9), ("min_length", -0.5), ("min_length", 2.0)])
def test_config_validates_naming_the_field(field, value):
    with pytest.raises(ConfigError, match=f"springs.{field}"):
        SpringConfig(**{field: value})


def test_springs_change_a_real_clip_but_not_its_rest_frames(sample_clip):
    motion, _ = read_bvh(sample_clip)
    result = run(motion, load_preset("looney"))
    assert result.substeps >= 1
    assert "springs" in result.timings


def test_blend_per_joint():
    positions = np.cumsum(np.random.default_rng(5).normal(size=(60, 5, 3)), axis=0)
    full = simulate_springs(positions, CHAIN, 1 / 30, blend=0.6, **SETTINGS)
    ramp = simulate_springs(positions, CHAIN, 1 / 30, blend=np.array([0.0, 0.0, 0.3, 0.6, 0.6]), **SETTINGS)
    assert np.array_equal(ramp[:, :2], positions[:, :2])  # no share: on the path
    assert np.allclose(ramp[:, 3:], full[:, 3:])  # the same share: the same result
    half = (ramp[:, 2] - positions[:, 2]) / np.where(full[:, 2] == positions[:, 2], 1.0, full[:, 2] - positions[:, 2])
    assert np.allclose(half[1:], 0.5)  # half the share, half the lag


def test_the_lag_stretches_a_link_softly_to_its_most_and_the_chain_below_follows():
    # A chain of unit links along Y; the springs stretched link 2 to 3x (frame 1) and 1.2x (frame 0).
    rest_pose = np.stack([np.zeros(5), np.arange(5.0), np.zeros(5)], 1)
    before = np.stack([rest_pose, rest_pose])
    after = before.copy()
    after[0, 2:, 1] += 0.2
    after[1, 2:, 1] += 2.0
    after[1, 4, 0] += 0.5  # the last link also turned: it keeps its own vector
    lengths = np.linalg.norm(np.diff(rest_pose, axis=0), axis=-1)
    rest = np.concatenate([[0.0], lengths])
    out = limit_stretch(after, before, CHAIN, rest, np.array([1, 2, 3, 4]), 2.0)
    # Under the knee (1.5x: half way from the rest length to the most) nothing moves, to the bit.
    assert np.array_equal(out[0], after[0])
    # Above it, a tanh into 2x: 1.5 + 0.5 tanh(1.5 / 0.5) = 1.9975, along the link's own direction.
    assert np.linalg.norm(out[1, 2] - out[1, 1]) == pytest.approx(1.5 + 0.5 * np.tanh(3.0))
    assert np.allclose(out[1, 2, [0, 2]], 0.0)
    # Everything below moved with it: the links after it are as the springs left them.
    assert np.allclose(np.diff(out[1, 2:], axis=0), np.diff(after[1, 2:], axis=0))
    assert np.array_equal(out[:, :2], after[:, :2])
    # A link the stretch pass had already made 3x long keeps that: the springs add nothing past it.
    longer = before.copy()
    longer[:, 2:, 1] += 2.0
    assert np.allclose(limit_stretch(after, longer, CHAIN, rest, np.array([1, 2, 3, 4]), 2.0), after)
    # Links not swung are left alone.
    assert np.array_equal(limit_stretch(after, before, CHAIN, rest, np.array([1, 3]), 2.0), after)
    # Only link 2 limited: the links below it, not limited themselves, follow its shortening exactly, and a
    # branch off joint 1 (a tree: 0-1-2-3-4 and 1-5) does not move.
    tree = np.array([-1, 0, 1, 2, 3, 1])
    branched = np.concatenate([after, after[:, 1:2] + [1.0, 0.0, 0.0]], axis=1)
    out = limit_stretch(branched, np.concatenate([before, before[:, 1:2] + [1.0, 0.0, 0.0]], axis=1), tree,
                        np.concatenate([rest, [1.0]]), np.array([2]), 2.0)
    shift = out[1, 2] - branched[1, 2]
    assert shift[1] == pytest.approx(1.5 + 0.5 * np.tanh(3.0) - 3.0) and np.allclose(shift[[0, 2]], 0.0)
    assert np.allclose(out[1, 3:5] - branched[1, 3:5], shift) and np.array_equal(out[:, [0, 1, 5]], branched[:, [0, 1, 5]])


def test_the_lag_squashes_a_link_softly_to_its_floor_and_the_chain_below_follows():
    # The same chain; the springs squashed link 2 to 0.9x (frame 0), 0.2x (frame 1) and 0.6x (frame 2,
    # where it was already 0.6x before them).
    rest_pose = np.stack([np.zeros(5), np.arange(5.0), np.zeros(5)], 1)
    before = np.stack([rest_pose] * 3)
    before[2, 2:, 1] -= 0.4
    after = np.stack([rest_pose] * 3)
    after[0, 2:, 1] -= 0.1
    after[1, 2:, 1] -= 0.8
    after[2, 2:, 1] -= 0.4
    rest = np.concatenate([[0.0], np.ones(4)])
    links = np.array([1, 2, 3, 4])
    out = limit_stretch(after, before, CHAIN, rest, links, 2.0, least=0.5)
    # Down to the knee (0.75x: half way from the rest length to the floor) nothing moves, to the bit, nor
    # a link the springs left no shorter than before them.
    assert np.array_equal(out[[0, 2]], after[[0, 2]])
    # Below it, a tanh into the floor, 0.5x (0.75 - 0.25 tanh(0.55 / 0.25) = 0.5062), along the link.
    assert np.linalg.norm(out[1, 2] - out[1, 1]) == pytest.approx(0.75 - 0.25 * np.tanh(0.55 / 0.25))
    assert np.allclose(np.diff(out[1, 2:], axis=0), np.diff(after[1, 2:], axis=0))
    # Without a floor (0, the paper's), the squash stays.
    assert np.array_equal(limit_stretch(after, before, CHAIN, rest, links, 2.0), after)


def test_the_lag_no_longer_squashes_a_looney_upper_arm_to_a_third():
    # The amc2bvh jump at looney: the hand lagging behind a fast elbow squashed an upper arm's sub-link to
    # 0.31 of its rest length in the springs' result; with the floor (the default 0.5, easing in from the
    # length before the springs) it keeps more than 0.4 of it. Measured before the contacts and body pass.
    from mocap_exaggerate import load_bvh
    from mocap_exaggerate.config import resolve_config
    from mocap_exaggerate.pipeline import STAGES, run

    motion = load_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", fps=120.0)
    stages = tuple(stage for stage in STAGES if stage.name != "constraints")

    def shortest(min_length: float) -> float:
        result = run(motion, resolve_config("looney", None, {"springs": {"min_length": min_length}}), stages=stages)
        skeleton = result.motion.skeleton
        rest = skeleton.link_lengths()
        links = np.flatnonzero(rest > 1e-3 * rest.max())
        pos = result.world_positions[result.rest_frames:]
        return float((np.linalg.norm(pos[:, links] - pos[:, skeleton.parents[links]], axis=-1) / rest[links]).min())

    assert shortest(0.0) < 0.35
    assert shortest(0.5) > 0.4


def test_no_link_of_a_looney_dance_stretches_past_the_presets_range():
    # The iClone pirouette at looney: a hand lagging behind a fast elbow stretched the forearm 2.42x
    # (the preset's follow-through is held to 1.75x, the correction's free stretch to 1.5x; the stages
    # after the springs do not stretch this clip further, though on others they may a little).
    motion, _ = read_bvh(shared("wide/cmu_05_11_dance_sideways_pirouette_iclone.bvh"))
    config = load_preset("looney")
    result = run(motion, config)
    parents = motion.skeleton.parents
    captured = motion.world_positions()
    out = result.world_positions[:, result.original_index]
    ratio = (np.linalg.norm(out[:, 1:] - out[:, parents[1:]], axis=-1)
             / np.maximum(np.linalg.norm(captured[:, 1:] - captured[:, parents[1:]], axis=-1), 1e-9))
    assert ratio.max() <= config.springs.max_stretch
    assert ratio.max() > 1.5  # still rubber: the lag stretches past the correction's free stretch


@pytest.mark.unit
def test_soft_limit_is_its_formula_in_any_memory_layout():
    """The soft limit takes its tanh only of the values over the knee; it must place them back where they
    came from whatever the arrays' layout (a Fortran-ordered or strided length once got them back unchanged)."""
    rng = np.random.default_rng(7)
    value = rng.uniform(0.0, 3.0, (300, 40))
    knee = rng.uniform(0.5, 1.5, (300, 40))
    top = knee + rng.uniform(-0.2, 1.0, (300, 40))  # some rooms <= 0: a hard minimum there
    room = top - knee
    eased = knee + room * np.tanh(np.divide(value - knee, room, out=np.zeros_like(room), where=room > 0))
    expected = np.where(value - knee <= 0, value, np.where(room > 0, eased, np.minimum(value, top)))
    assert np.any(value > knee) and np.any(value <= knee) and np.any((value > knee) & (room <= 0))
    for layout in (np.ascontiguousarray, np.asfortranarray):
        got = soft_limit(layout(value), layout(knee), layout(top))
        assert np.array_equal(got, expected)
    strided = np.repeat(value, 2, axis=1)[:, ::2]
    assert np.array_equal(soft_limit(strided, knee, top), expected)
    column = value[:, :1]  # broadcast against the knee and top
    assert np.array_equal(soft_limit(column, knee, top)[:, 5], soft_limit(value[:, 0], knee[:, 5], top[:, 5]))
    assert soft_limit(0.5, 1.0, 2.0) == 0.5 and soft_limit(9.0, 1.0, 2.0) == pytest.approx(1.0 + np.tanh(8.0))
    kept = value.copy()
    assert not np.shares_memory(soft_limit(value, knee, top), value) and np.array_equal(value, kept)
    # Where the difference to the knee is NaN the formula's branch is taken, as it was: the value or the top,
    # whichever is less, where the room is not a number; else NaN.
    with np.errstate(invalid="ignore"):  # (inf - inf: NumPy's warning, as the formula gives it)
        odd = soft_limit(np.array([0.5, 3.0, np.inf, -np.inf, np.nan]), np.array([np.nan, np.nan, np.inf, -np.inf, 1.0]),
                         3.0)
    assert np.array_equal(odd, [0.5, 3.0, 3.0, np.nan, np.nan], equal_nan=True)
