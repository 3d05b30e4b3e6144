import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocap_exaggerate.core.rotations import (
    quat_angle,
    quat_from_euler,
    quat_inv,
    quat_mul,
    quat_rotate,
    quat_to_euler,
    quat_unroll,
)

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]


@pytest.mark.parametrize("order", ORDERS)
def test_from_euler_matches_scipy_intrinsic(order):
    rng = np.random.default_rng(701)
    euler = rng.uniform(-180, 180, (500, 3))
    ours = quat_from_euler(euler, order)
    theirs = Rotation.from_euler(order, euler, degrees=True).as_quat()
    assert np.max(quat_angle(ours, theirs)) < 1e-12


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


def test_unroll_makes_neighbours_same_hemisphere():
    q = Rotation.from_euler("z", np.linspace(0, 720, 100)[:, None], degrees=True).as_quat()
    q[::3] *= -1
    out = quat_unroll(q)
    assert np.all(np.sum(out[1:] * out[:-1], axis=-1) > 0)
    assert np.allclose(np.abs(np.sum(out * q, axis=-1)), 1.0)
