import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.stages.correct import CorrectConfig, correct, stretch_error
from mocap_exaggerate.stages.extrapolate import extrapolate

from .helpers import shared


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
    "field, value", [("threshold", -0.1), ("delta", 0.0), ("delta", 1.5), ("max_stretch", 0.5), ("max_iter", 0)]
)
def test_config_validates_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"correct.{field}"):
        CorrectConfig(**{field: value})
