import numpy as np
import pytest

from mocap_exaggerate.errors import ConfigError
from mocap_exaggerate.io.bvh import read_bvh
from mocap_exaggerate.stages.extrapolate import ExtrapolateConfig, extrapolate, gaussian_average, parse_duration


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
