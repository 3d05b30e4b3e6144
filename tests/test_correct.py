import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocap_exaggerate.core.timing import spread_max
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.stages.bends import keep_bends
from mocap_exaggerate.stages.correct import CorrectConfig, accent_stretch, correct, floor_squash, stretch_error
from mocap_exaggerate.stages.extrapolate import extrapolate

from .helpers import SAMPLE_DIR, shared


def stretched_clip(path, omega=6.0):
    motion = read_bvh(path)[0]
    world = extrapolate(motion.world_positions(), sigma=0.25 / motion.frame_time, omega=omega)
    skeleton = motion.skeleton
    return world, skeleton.parents, skeleton.link_lengths()


def correct_slowly(world, parents, lengths, threshold, delta, max_stretch, max_iter):
    """Frame-by-frame, link-by-link oracle of the same algorithm."""
    out = world.copy()
    total = lengths[1:].sum()
    for f in range(len(out)):
        pos = out[f]
        for _ in range(max_iter):
            excess = np.zeros(len(parents))
            for c in range(1, len(parents)):
                excess[c] = max(0.0, np.linalg.norm(pos[c] - pos[parents[c]]) - max_stretch * lengths[c])
            if excess.sum() / total <= threshold:
                break
            shift = np.zeros_like(pos)
            for c in range(1, len(parents)):
                vec = pos[c] - pos[parents[c]]
                d = np.linalg.norm(vec)
                step = -delta * excess[c] / d * vec if d > 0 else 0 * vec
                shift[c] = shift[parents[c]] + step
            pos = pos + shift
        out[f] = pos
    return out


def test_vectorised_equals_slow_oracle(sample_clip):
    world, parents, lengths = stretched_clip(sample_clip)
    world = world[::7]
    fast, _ = correct(world, parents, lengths, threshold=0.05, delta=0.3, max_stretch=1.05)
    slow = correct_slowly(world, parents, lengths, 0.05, 0.3, 1.05, 500)
    assert np.allclose(fast, slow, atol=1e-9)


@pytest.mark.parametrize("delta", [0.05, 0.3, 0.5, 0.9, 1.0])
@pytest.mark.parametrize("threshold", [0.0, 0.01, 0.1])
def test_every_frame_ends_under_threshold_and_the_rest_is_untouched(sample_clip, delta, threshold):
    world, parents, lengths = stretched_clip(sample_clip)
    before = stretch_error(world, parents, lengths)
    out, report = correct(world, parents, lengths, threshold=threshold, delta=delta, max_iter=100000)
    after = stretch_error(out, parents, lengths)
    assert np.all(after <= threshold + 1e-9)
    calm = before <= threshold
    assert np.array_equal(out[calm], world[calm])
    assert np.array_equal(out[:, 0], world[:, 0])
    assert report.unconverged_frames == 0
    assert report.frames_corrected == int(np.sum(~calm))


def test_error_shrinks_geometrically_known_iteration_count():
    # One link of rest length 1 stretched to 3: excess 2 of total length 1, E0 = 2.
    # Each iteration keeps (1 - delta) of it: E_k = 2 * 0.5^k <= 0.1 needs k = 5 (2/32 = 0.0625).
    world = np.array([[[0.0, 0, 0], [3.0, 0, 0]]])
    out, report = correct(world, np.array([-1, 0]), np.array([0.0, 1.0]), threshold=0.1, delta=0.5)
    assert report.iterations == 5
    assert np.allclose(out[0, 1], [1 + 2 * 0.5**5, 0, 0])
    out, report = correct(world, np.array([-1, 0]), np.array([0.0, 1.0]), threshold=0.0, delta=1.0)
    assert report.iterations == 1
    assert np.allclose(out[0, 1], [1, 0, 0])


def test_link_directions_are_kept(sample_clip):
    world, parents, lengths = stretched_clip(sample_clip)
    out, _ = correct(world, parents, lengths, threshold=0.0, delta=1.0)
    before = world[:, 1:] - world[:, parents[1:]]
    after = out[:, 1:] - out[:, parents[1:]]
    n_before = np.linalg.norm(before, axis=-1)
    n_after = np.linalg.norm(after, axis=-1)
    ok = (n_before > 1e-6) & (n_after > 1e-6)
    cos = np.sum(before * after, axis=-1)[ok] / (n_before[ok] * n_after[ok])
    assert np.min(cos) > 1 - 1e-9
    assert np.all(n_after <= lengths[1:] + 1e-9)


@settings(max_examples=60, deadline=None)
@given(
    delta=st.floats(min_value=1e-3, max_value=1.0),
    threshold=st.floats(min_value=0.0, max_value=0.5),
    max_stretch=st.floats(min_value=1.0, max_value=2.0),
    seed=st.integers(0, 2**16),
)
def test_halts_under_threshold_for_any_delta(delta, threshold, max_stretch, seed):
    rng = np.random.default_rng(seed)
    parents = np.array([-1, 0, 1, 2, 1, 4, 0, 6])
    lengths = np.concatenate([[0.0], rng.uniform(0.0, 2.0, 7)])
    world = rng.normal(scale=3.0, size=(20, 8, 3))
    out, report = correct(world, parents, lengths, threshold=threshold, delta=delta,
                          max_stretch=max_stretch, max_iter=100000)
    assert np.all(stretch_error(out, parents, lengths, max_stretch=max_stretch) <= threshold + 1e-9)
    assert np.all(np.isfinite(out))
    assert report.unconverged_frames == 0


def test_on_the_longest_real_clip():
    world, parents, lengths = stretched_clip(shared("assimp_boxing_toes.bvh"))
    out, report = correct(world, parents, lengths, threshold=0.02, delta=0.5)
    assert report.max_error_before > 0.02
    assert report.max_error_after <= 0.02


@pytest.mark.parametrize(
    "field, value", [("threshold", -0.1), ("delta", 0.0), ("delta", 1.5), ("max_stretch", 0.5), ("max_iter", 0),
                     ("min_length", -0.1), ("min_length", 1.5), ("min_length", float("nan")), ("min_length", "half")]
)
def test_config_validates_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"correct.{field}"):
        CorrectConfig(**{field: value})


# ---------------------------------------------------------------------------- issue 11: smooth in time


def _exaggerated(sample_clip, omega=5.0):
    motion = read_bvh(sample_clip)[0]
    world = motion.world_positions()
    return motion, extrapolate(world, sigma=0.2 / motion.frame_time, omega=omega)


@pytest.mark.parametrize("threshold", [0.0, 0.03])
def test_smooth_correction_keeps_the_threshold_and_leaves_far_frames_alone(sample_clip, threshold):
    motion, world = _exaggerated(sample_clip)
    parents, lengths = motion.skeleton.parents, motion.skeleton.link_lengths()
    radius = 12
    out, report = correct(world, parents, lengths, threshold=threshold, max_stretch=1.1, smooth=radius)
    assert np.all(stretch_error(out, parents, lengths, max_stretch=1.1) <= threshold + 1e-9)
    over = stretch_error(world, parents, lengths, max_stretch=1.1) > threshold
    near = np.convolve(over, np.ones(4 * radius + 1), mode="same") > 0  # within 2 radii of a frame over it
    assert np.array_equal(out[~near], world[~near]) and report.frames_corrected >= over.sum()
    assert np.array_equal(out[:, 0], world[:, 0])  # the root never moves


def test_smooth_correction_pulls_back_smoothly():
    # The laugh: a frame just over the threshold is pulled back and its neighbour is not, and
    # neighbours needing 3 or 4 halvings keep 1/8 or 1/16 of their excess: jerk, frame by frame.
    motion = read_bvh(shared("cmu_14_19_laugh_idle_daz.bvh"))[0]
    world = extrapolate(motion.world_positions(), sigma=0.2 / motion.frame_time, omega=5.0, smooth=6.0)
    parents, lengths = motion.skeleton.parents, motion.skeleton.link_lengths()

    def jerk(out):  # the 99th percentile of |third difference| over frames and joints
        return np.percentile(np.linalg.norm(np.diff(out, 3, axis=0), axis=-1), 99)

    paper, _ = correct(world, parents, lengths, threshold=0.03, max_stretch=1.1)
    smooth, _ = correct(world, parents, lengths, threshold=0.03, max_stretch=1.1, smooth=12)
    assert jerk(smooth) < 0.4 * jerk(paper), (jerk(smooth), jerk(paper))  # measured 0.67 vs 3.56
    assert jerk(smooth) < 1.2 * jerk(world)  # barely more than the exaggeration's own


def test_free_stretch_only_at_accents():
    fps, height = 100.0, 170.0
    t = np.arange(0.0, 2.0, 1.0 / fps)
    captured = np.zeros((len(t), 3, 3))
    captured[:, 1] = [0.0, 50.0, 0.0]  # a joint that stays put relative to the root
    x = np.clip((t - 1.0) / 0.1, 0.0, 1.0)
    captured[:, 2, 0] = 0.5 * height * x  # a hand thrown half a body height in 0.1 s: 5 h/s
    limits = accent_stretch(captured, 1 / fps, height, max_stretch=1.5, accent_speed=3.0, radius=5)
    assert np.all(limits[:, 1] == 1.0) and np.all(limits[:50, 2] == 1.0)  # held: rest length only
    assert limits[105, 2] == pytest.approx(1.5)  # the fast middle of the throw: all of it
    assert np.all(np.diff(limits[:105, 2]) >= 0)  # and it builds up smoothly before


def test_held_links_never_stretch_past_their_free_length(sample_clip):
    motion, world = _exaggerated(sample_clip)
    parents, lengths = motion.skeleton.parents, motion.skeleton.link_lengths()
    hard = np.zeros(len(parents), bool)
    hard[[3, 4, 5]] = True
    for smooth in (0, 12):
        out, _ = correct(world, parents, lengths, threshold=10.0, max_stretch=1.05, smooth=smooth, hard=hard)
        ratio = np.linalg.norm(out[:, hard] - out[:, parents[hard]], axis=-1) / lengths[hard]
        assert ratio.max() <= 1.05 + 1e-9
        others = ~hard
        others[0] = False
        assert np.array_equal(out[:, 0], world[:, 0])
        # a threshold of 10 corrects nothing else
        assert np.allclose(np.linalg.norm(out[:, others] - out[:, parents[others]], axis=-1),
                           np.linalg.norm(world[:, others] - world[:, parents[others]], axis=-1))


@given(values=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=60), radius=st.integers(1, 6))
@settings(max_examples=200, deadline=None)
def test_spread_max_is_never_below_its_input_and_zero_two_radii_away(values, radius):
    values = np.array(values)
    spread = spread_max(values, radius)
    assert np.all(spread >= values)
    nonzero = np.flatnonzero(values > 0)
    frames = np.arange(len(values))
    far = np.all(np.abs(frames[:, None] - nonzero[None, :]) > 2 * radius, axis=1) if len(nonzero) else np.ones(len(values), bool)
    assert np.all(spread[far] == 0.0)


def test_a_knee_pushed_behind_the_leg_comes_back_and_a_bent_one_is_left_alone():
    # Hip at the top, ankle below; the captured knee bends forward (+z) a little.
    captured = np.array([[[0.0, 1.0, 0.0], [0.0, 0.5, 0.05], [0.0, 0.0, 0.0], [0.0, 0.0, 0.15]]] * 3)
    exaggerated = captured.copy()
    exaggerated[0, 1, 2] = -0.08  # hyperextended: behind the hip-ankle line
    exaggerated[1, 1, 2] = 0.3  # bent further forward: fine
    out = keep_bends(exaggerated, captured, [(0, 1, 2, 3)])
    assert out[0, 1, 2] > 0.0  # in front of the line again
    assert np.array_equal(out[1], exaggerated[1]) and np.array_equal(out[2], exaggerated[2])
    assert np.array_equal(out[:, [0, 2, 3]], exaggerated[:, [0, 2, 3]])  # only the knee moves


# ---------------------------------------------------------------------------- the squash floor


def _squashed_chain(lengths: np.ndarray) -> np.ndarray:
    """(F, 3, 3): a root, a unit link along X squashed to ``lengths`` (F,), and a unit link up from its end."""
    pos = np.zeros((len(lengths), 3, 3))
    pos[:, 1, 0] = lengths
    pos[:, 2, 0] = lengths
    pos[:, 2, 1] = 1.0
    return pos


PARENTS = np.array([-1, 0, 1])
REST = np.array([0.0, 1.0, 1.0])


def test_the_squash_floor_by_hand_and_only_past_its_knee():
    # Floor 0.5: the room is half the length, its knee two fifths of that (0.2). A link squashed to 0.1
    # (0.9 short) is 0.2 + 0.3 tanh(0.7 / 0.3) short after it: 0.50560 long.
    lengths = np.array([1.0, 0.95, 0.8, 0.1, 0.0001])
    out, moved = floor_squash(_squashed_chain(lengths), PARENTS, REST, 0.5)
    assert moved == 2
    assert out[3, 1, 0] == pytest.approx(1.0 - (0.2 + 0.3 * np.tanh(0.7 / 0.3)), abs=1e-12)
    assert out[3, 1, 0] == pytest.approx(0.50559, abs=1e-5)
    # Down to the knee (0.8 long) nothing moves, to the bit; the child carries its subtree along.
    assert np.array_equal(out[:3], _squashed_chain(lengths)[:3])
    assert np.allclose(out[:, 2] - out[:, 1], [0.0, 1.0, 0.0])
    assert np.all(out[:, 1, 0] > 0.5)  # eased into the floor, never reaching it


def test_the_squash_floor_is_smooth_in_time_and_off_at_zero():
    # A link squashing steadily from its length to nothing and back: its floored length never falls
    # below half, never jumps, and its speed has no corner (the tanh meets the line with its slope).
    t = np.linspace(0.0, 1.0, 2001)
    lengths = 1.0 - np.sin(np.pi * t) * 0.999
    out, _ = floor_squash(_squashed_chain(lengths), PARENTS, REST, 0.5)
    floored = out[:, 1, 0]
    assert floored.min() > 0.5 and floored.min() < 0.51
    speed = np.diff(floored)
    assert np.abs(np.diff(speed)).max() < 4 * np.abs(np.diff(np.diff(lengths))).max()
    assert np.all(np.sign(speed[:1000]) <= 0) and np.all(np.sign(speed[1001:]) >= 0)
    same, moved = floor_squash(_squashed_chain(lengths), PARENTS, REST, 0.0)
    assert moved == 0 and np.array_equal(same, _squashed_chain(lengths))


def test_the_squash_floor_keeps_a_captured_squash_and_gives_a_collapsed_link_the_captured_direction():
    # A rig keyframed with a link at 0.3 of its rest length (the Quaternius robot's body squashes so):
    # measured against the capture, the capture comes through untouched.
    lengths = np.array([1.0, 0.6, 0.3, 0.3])
    captured = _squashed_chain(lengths)
    out, moved = floor_squash(captured, PARENTS, REST, 0.5, captured)
    assert moved == 0 and np.array_equal(out, captured)
    # Squashed further than the capture: floored from the captured length (half of 0.3 at most).
    squashed = _squashed_chain(np.array([1.0, 0.6, 0.05, 0.3]))
    out, moved = floor_squash(squashed, PARENTS, REST, 0.5, captured)
    assert moved == 1 and 0.15 < out[2, 1, 0] < 0.16
    # Collapsed to nothing (no direction of its own): the captured link's direction, at the floored length.
    gone = squashed.copy()
    gone[3, 1] = 0.0
    gone[3, 2] = [0.0, 1.0, 0.0]
    out, _ = floor_squash(gone, PARENTS, REST, 0.5, captured)
    floored = 0.3 - (0.06 + 0.09 * np.tanh((0.3 - 0.06) / 0.09))  # the room 0.15 of 0.3, its knee 0.06
    assert np.allclose(out[3, 1], [floored, 0.0, 0.0], rtol=0.0, atol=1e-12)
    assert np.allclose(out[3, 2] - out[3, 1], [0.0, 1.0, 0.0])  # its child carried along


def test_a_looney_jump_keeps_its_upper_arm_at_half_its_length_or_more():
    # The amc2bvh jump at looney: two arm joints pushed toward each other squashed the upper arm to 0.21
    # of its length after the correction (and to 0.16 in the end), and its sub-links spun as it came back.
    from mocap_exaggerate import load_bvh
    from mocap_exaggerate.config import resolve_config
    from mocap_exaggerate.pipeline import pipeline_limbs, prepare
    from mocap_exaggerate.stages.correct import correct_stage
    from mocap_exaggerate.stages.extrapolate import extrapolate_stage

    motion = load_bvh(SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", fps=120.0)
    skeleton = motion.skeleton
    rest = skeleton.link_lengths()
    links = np.flatnonzero(rest > 1e-3 * rest.max())

    def shortest(min_length: float) -> float:
        config = resolve_config("looney", None, {"correct": {"min_length": min_length}})
        state = prepare(motion, config.input, limbs=pipeline_limbs(skeleton, config))
        state = correct_stage(extrapolate_stage(state, config.extrapolate), config.correct)
        pos = state.positions[state.first:]
        return float((np.linalg.norm(pos[:, links] - pos[:, skeleton.parents[links]], axis=-1) / rest[links]).min())

    assert shortest(0.0) < 0.3  # the paper's correction only shortens
    assert 0.5 < shortest(0.5) < 0.55  # the preset's floor (0.5 is the default)


def test_positions_rebuilt_from_their_links_by_the_kernel_are_the_loops():
    """`_rebuild` down a branching hierarchy: the compiled pass gives the joint-by-joint NumPy loop's bits
    (links scaled, a zero-length link kept), and a hierarchy whose parent comes after its child is refused."""
    from mocap_exaggerate.core.native import kernels
    from mocap_exaggerate.stages.correct import _rebuild

    rng = np.random.default_rng(11)
    parents = np.array([-1, 0, 1, 2, 1, 4, 0, 6, 7])
    pos = rng.normal(size=(300, len(parents), 3))
    vec = pos[:, 1:] - pos[:, parents[1:]]
    vec[:, 2] = 0.0
    length = np.linalg.norm(vec, axis=-1)
    new_length = length * rng.uniform(0.5, 1.5, length.shape)
    ours = _rebuild(pos.copy(), parents, vec, length, new_length)
    theirs = _rebuild(pos.copy(), parents, vec, length, new_length, compiled=False)
    assert np.array_equal(ours, theirs)
    assert np.allclose(np.linalg.norm(ours[:, 1:] - ours[:, parents[1:]], axis=-1)[:, [0, 1, 3]],
                       new_length[:, [0, 1, 3]])
    if kernels is not None:
        with pytest.raises(ValueError, match="parents"):
            kernels.chain_add(pos.copy(), np.array([-1, 2, 0, 1, 1, 4, 0, 6, 7]), np.ascontiguousarray(vec), 300, 9)
        with pytest.raises(ValueError):
            kernels.chain_add(pos.copy(), parents, np.ascontiguousarray(vec[:-1]), 300, 9)
