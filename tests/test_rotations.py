import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocap_exaggerate.core import rotations
from mocap_exaggerate.core.rotations import (
    euler_blocks,
    quat_angle,
    quat_from_euler,
    quat_from_joint_euler,
    quat_inv,
    quat_mul,
    quat_rotate,
    quat_to_euler,
    quat_unroll,
)

from .helpers import assert_same_bits_or_ulps

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]


@pytest.mark.parametrize("order", ORDERS)
def test_from_euler_matches_scipy_intrinsic(order):
    rng = np.random.default_rng(701)
    euler = rng.uniform(-180, 180, (500, 3))
    ours = quat_from_euler(euler, order)
    theirs = Rotation.from_euler(order, euler, degrees=True).as_quat()
    assert np.max(quat_angle(ours, theirs)) < 1e-12


def test_joint_euler_is_each_joints_own_order_and_the_kernel_gives_numpys_bits():
    """Every joint in its own order (the six Tait-Bryan ones, a repeated-axis one the kernel leaves to
    NumPy), angles past whole turns: the compiled pass against `quat_from_euler` joint by joint, bit for
    bit where NumPy's sine is the C library's; and against scipy."""
    orders = ORDERS + ["zxy", "XYX"]
    euler = np.random.default_rng(705).uniform(-900, 900, (300, len(orders), 3))
    ours = quat_from_joint_euler(euler, orders)
    slow = quat_from_joint_euler(euler, orders, compiled=False)
    by_joint = np.stack([quat_from_euler(euler[:, j], order) for j, order in enumerate(orders)], axis=1)
    assert np.array_equal(slow, by_joint)
    if rotations._kernels is not None:
        assert_same_bits_or_ulps(ours, slow)
    for j, order in enumerate(orders):
        theirs = Rotation.from_euler(order.upper(), euler[:, j], degrees=True).as_quat()
        assert np.max(quat_angle(ours[:, j], theirs)) < 1e-12


def test_mul_and_rotate_match_scipy():
    rng = np.random.default_rng(702)
    a, b = Rotation.random(200, random_state=1), Rotation.random(200, random_state=2)
    v = rng.normal(size=(200, 3))
    assert np.max(quat_angle(quat_mul(a.as_quat(), b.as_quat()), (a * b).as_quat())) < 1e-12
    assert np.allclose(quat_rotate(a.as_quat(), v), a.apply(v))
    assert np.allclose(quat_rotate(quat_inv(a.as_quat()), a.apply(v)), v)


@pytest.mark.parametrize("order", ORDERS)
def test_to_euler_keeps_reference_angles_exactly(order):
    rng = np.random.default_rng(703)
    # Angles outside the canonical ranges (|middle| > 90, beyond 180) come back unchanged.
    euler = rng.uniform(-400, 400, (300, 3))
    q = quat_from_euler(euler, order)
    back = quat_to_euler(q, order, reference=euler)
    assert np.array_equal(back, euler)


@pytest.mark.parametrize("order", ORDERS)
def test_to_euler_nearest_reference_when_rotation_changed(order):
    rng = np.random.default_rng(704)
    euler = rng.uniform(-170, 170, (300, 3))
    q = quat_from_euler(euler + 0.5, order)  # every rotation differs from the reference a little
    back = quat_to_euler(q, order, reference=euler)
    assert np.max(quat_angle(quat_from_euler(back, order), q)) < 1e-9
    assert np.max(np.abs(back - euler)) < 5.0


def test_to_euler_without_reference_is_continuous_through_gimbal_lock():
    # Middle angle sweeps from 60 to 120 degrees: the canonical solution would jump by 180.
    frames = 241
    euler = np.stack([np.linspace(10, 70, frames), np.linspace(60, 120, frames), np.linspace(-20, 200, frames)], 1)
    q = quat_from_euler(euler, "ZXY")
    back = quat_to_euler(q, "ZXY")
    assert np.max(quat_angle(quat_from_euler(back, "ZXY"), q)) < 1e-6
    assert np.max(np.abs(np.diff(back, axis=0))) < 5.0


def _spinning_through_locks(frames: int, joints: int, order: str, seed: int) -> np.ndarray:
    """Rotations that spin past whole turns, switch Euler solution, and sit at gimbal lock,
    some from the first frame on (their angle comes from a later frame)."""
    rng = np.random.default_rng(seed)
    euler = np.cumsum(rng.normal(scale=40.0, size=(frames, joints, 3)), axis=0)
    locked = rng.random((frames, joints)) < 0.3
    locked[: frames // 3, 0] = True  # joint 0 starts locked for a third of the clip
    locked[:, -1] = True  # the last joint is locked throughout (its third angle is 0)
    euler[..., 1] = np.where(locked, 90.0 * rng.choice([-1.0, 1.0], size=(frames, joints)), euler[..., 1])
    return quat_from_euler(euler, order)


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("block", [1, 3, 64])
def test_euler_blocks_are_the_whole_clips_angles_bit_for_bit(order, block):
    # What a frame's choice depends on (the previous pick, the flips and turns so far, the last
    # angle off gimbal lock, or the first one after) is carried from block to block.
    q = _spinning_through_locks(200, 4, order, seed=705)
    whole = quat_to_euler(q, order)
    assert np.max(np.abs(np.diff(whole, axis=0))) > 90.0 or np.ptp(whole) > 360.0  # the case is not trivial
    blocks = np.concatenate(list(euler_blocks(q, order, block=block)))
    assert blocks.view(np.int64).tolist() == whole.view(np.int64).tolist()
    # Some joints only, taken block by block: the same as those joints converted alone.
    picked = np.concatenate(list(euler_blocks(q, order, block=block, columns=[3, 0])))
    assert np.array_equal(picked, quat_to_euler(q[:, [3, 0]], order))
    reference = quat_to_euler(q, order) + 360.0
    with_reference = np.concatenate(list(euler_blocks(q, order, reference, block=block)))
    assert np.array_equal(with_reference, quat_to_euler(q, order, reference=reference))
    # As the BVH writer calls it: some joints, and every joint's reference (each block takes its columns').
    both = np.concatenate(list(euler_blocks(q, order, reference, block=block, columns=[3, 0])))
    assert np.array_equal(both, quat_to_euler(q[:, [3, 0]], order, reference=reference[:, [3, 0]]))
    # A joint locked throughout: its third angle is 0, its first carries the whole turn.
    assert np.all(whole[:, -1, 2] == 0.0)
    assert np.max(quat_angle(quat_from_euler(whole, order), q)) < 1e-6
    # The choice of solution and whole turns made frame after frame in core/_kernels.c: NumPy's bits,
    # whole clips and blocks, all joints and some.
    if rotations._kernels is not None:
        numpy_whole = np.concatenate(list(euler_blocks(q, order, block=len(q), compiled=False)))
        assert numpy_whole.view(np.int64).tolist() == whole.view(np.int64).tolist()
        numpy_picked = np.concatenate(list(euler_blocks(q, order, block=block, columns=[3, 0], compiled=False)))
        assert numpy_picked.view(np.int64).tolist() == picked.view(np.int64).tolist()


def test_unroll_makes_neighbours_same_hemisphere():
    q = Rotation.from_euler("z", np.linspace(0, 720, 100)[:, None], degrees=True).as_quat()
    q[::3] *= -1
    out = quat_unroll(q)
    assert np.all(np.sum(out[1:] * out[:-1], axis=-1) > 0)
    assert np.allclose(np.abs(np.sum(out * q, axis=-1)), 1.0)


@pytest.mark.parametrize("order", ORDERS)
def test_euler_from_quaternions_reads_the_matrix_entries_bit_for_bit(order):
    # The writer makes only the five matrix entries the angles read, each by quat_to_matrix's own expression.
    from mocap_exaggerate.core.rotations import _euler_from_quat, quat_normalize, quat_to_matrix

    q = quat_normalize(np.random.default_rng(706).normal(size=(2000, 3, 4)))
    q[:10] = quat_from_euler(np.array([30.0, 90.0, -20.0]), order)  # gimbal lock
    m = quat_to_matrix(q)  # the whole matrix, and the angles read from it
    i, j, k = ("XYZ".index(a) for a in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    b = np.arctan2(s * m[..., i, k], np.hypot(m[..., i, i], m[..., i, j]))
    a = np.arctan2(-s * m[..., j, k], m[..., k, k])
    c = np.arctan2(-s * m[..., i, j], m[..., i, i])
    expected = np.degrees(np.stack([a, b, c], axis=-1))
    assert _euler_from_quat(q, order).tobytes() == expected.tobytes()  # (the compiled entries, where built)
    assert _euler_from_quat(np.repeat(q, 2, axis=1)[:, ::2], order).tobytes() == expected.tobytes()  # strided
    with pytest.MonkeyPatch.context() as patch:  # and NumPy's, as an install without a compiler runs it
        patch.setattr(rotations, "_kernels", None)
        assert _euler_from_quat(q, order).tobytes() == expected.tobytes()
    # A known answer: 30 degrees about the first axis alone.
    assert np.allclose(_euler_from_quat(quat_from_euler(np.array([[30.0, 0.0, 0.0]]), order), order), [[30.0, 0, 0]])


def test_sum_of_three_is_numpys_sum_bit_for_bit():
    from mocap_exaggerate.core.rotations import sum_last as _sum3  # (the one sum over a short last axis)

    values = np.abs(np.random.default_rng(707).normal(size=(4000, 3)) * np.logspace(-8, 8, 4000)[:, None])
    assert _sum3(values).tobytes() == np.sum(values, axis=-1).tobytes()


@pytest.mark.parametrize("length", [1, 2, 3, 4, 7, 8])
def test_sum_over_the_last_axis_is_numpys_sum_bit_for_bit(length):
    # Dot products across the stages: NumPy's bits, the sign of a zero too (NumPy adds to +0.0, so a sum of
    # -0.0 alone is +0.0), on any layout, with infinities that cancel.
    from mocap_exaggerate.core.rotations import sum_last

    rng = np.random.default_rng(709)
    values = rng.normal(size=(3000, length)) * 10.0 ** rng.integers(-20, 20, size=(3000, length))
    values[::7] = -0.0
    values[1::7, : max(length - 1, 1)] = -0.0
    values[2::7, 0] = -values[2::7, -1]
    values[4::11, 0], values[5::11, -1] = np.inf, -np.inf
    for laid in (values, np.asfortranarray(values), values[::2], np.repeat(values, 2, axis=1)[:, ::2]):
        ours, theirs = sum_last(laid), np.sum(laid, axis=-1)
        assert np.array_equal(ours, theirs, equal_nan=True) and np.array_equal(np.signbit(ours), np.signbit(theirs))
    stacked = values.reshape(100, 30, length).transpose(1, 0, 2)
    assert sum_last(stacked, keepdims=True).tobytes() == np.sum(stacked, axis=-1, keepdims=True).tobytes()
    for other in (values.astype(np.float32), np.arange(3 * length).reshape(3, length)):  # NumPy's own, as it is
        assert sum_last(other).tobytes() == np.sum(other, axis=-1).tobytes()
    assert sum_last(np.float64(2.5)) == 2.5


@pytest.mark.parametrize("length", [1, 2, 3, 4, 7, 8])
def test_vector_norm_is_numpys_norm_bit_for_bit(length):
    # Every stage measures lengths with it: NumPy's own bits, on any layout (and whole blocks in the cache).
    from mocap_exaggerate.core.rotations import vector_norm

    rng = np.random.default_rng(708)
    base = rng.normal(size=(300, 120, length)) * np.exp(5.0 * rng.normal(size=(300, 120, length)))
    for v in (base, base[::3], np.swapaxes(base, 0, 1), np.asfortranarray(base), base[0], base[0, 0]):
        assert vector_norm(v).tobytes() == np.linalg.norm(v, axis=-1).tobytes()
        assert vector_norm(v, keepdims=True).shape == np.linalg.norm(v, axis=-1, keepdims=True).shape
    assert vector_norm(np.array([[3, 4]])).tolist() == [5.0]  # integers: NumPy's norm


def test_a_unit_track_is_unrolled_and_normalised_with_numpys_bits():
    """The GLB's rotation tracks: the compiled pass gives `quat_unroll` and `vector_norm`'s division bit for
    bit (unit and scaled quaternions, signs flipped at random, a track of one frame, a track whose
    neighbours are at right angles: a dot of exactly zero does not flip)."""
    from mocap_exaggerate.core.rotations import quat_unroll, unit_track, vector_norm

    rng = np.random.default_rng(77)
    q = rng.normal(size=(5000, 4)) * rng.uniform(0.5, 2.0, (5000, 1))
    q[rng.random(5000) < 0.3] *= -1.0
    square = np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0]])
    for track in (q, q[:1], square, q[:, [2, 0, 3, 1]].T.copy().T):
        expected = quat_unroll(track, axis=0)
        expected = (expected / vector_norm(expected, keepdims=True)).tobytes()  # (bit for bit: the sign of zero too)
        assert rotations.unit_track(track).tobytes() == expected
        assert unit_track(track, compiled=False).tobytes() == expected
    joints = q[:4998].reshape(1666, 3, 4)  # a joint's track read where it lies in a clip's (F, J, 4)
    for joint in range(3):
        assert unit_track(joints, joint).tobytes() == unit_track(joints[:, joint].copy(), compiled=False).tobytes()
        assert unit_track(joints, joint, compiled=False).tobytes() == unit_track(joints[:, joint].copy()).tobytes()
    for joint in (-1, 3):
        with pytest.raises(ValueError, match="joint"):
            unit_track(joints, joint)
    ours = unit_track(q)
    assert np.all(np.sum(ours[1:] * ours[:-1], axis=-1) >= 0)  # one hemisphere
    assert np.allclose(vector_norm(ours), 1.0, atol=1e-15)
