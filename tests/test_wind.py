import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad

from kite_env.compiled import NUMBA_AVAILABLE
from kite_env.wind import WindConfig, WindField, von_karman_spectra

POS = np.array([[0.0, 0.0, 10.0], [30.0, -12.0, 45.0], [70.0, 25.0, 40.0], [-5.0, 3.0, 0.05]])


def test_uniform_wind_everywhere_and_shapes():
    wind = WindField(WindConfig(speed_mps=7.5))
    v = wind.velocity(3.0, POS)
    assert v.shape == POS.shape
    np.testing.assert_array_equal(v, np.tile([7.5, 0.0, 0.0], (len(POS), 1)))
    v1 = wind.velocity(3.0, POS[1])
    assert v1.shape == (3,)
    np.testing.assert_array_equal(v1, [7.5, 0.0, 0.0])
    np.testing.assert_array_equal(wind(3.0, POS), v)  # __call__ alias (PyFlyt-style wind(t, pos))
    for bad in (np.zeros(4), np.zeros((2, 3, 3)), np.zeros((5, 2))):
        with pytest.raises(ValueError, match="shape"):
            wind.velocity(0.0, bad)


def test_log_profile_against_hand_formula():
    cfg = WindConfig(speed_mps=6.0, profile="log", ref_height_m=10.0, roughness_m=0.0002)
    wind = WindField(cfg)
    z = np.array([10.0, 50.0, 100.0, 1.0])
    expected = 6.0 * np.array([math.log(zz / 0.0002) / math.log(10.0 / 0.0002) for zz in z])
    np.testing.assert_allclose(wind.mean_speed(z), expected, rtol=1e-14)
    assert abs(wind.mean_speed(10.0) - 6.0) < 1e-14
    # hand numbers: ln(250000)/ln(50000) = 12.4292/10.8198
    assert wind.mean_speed(50.0) == pytest.approx(6.0 * 12.429216196844383 / 10.819778284410283, rel=1e-12)
    # at and below z0 (and below ground): zero, never NaN or negative
    low = wind.mean_speed(np.array([0.0002, 1e-5, 0.0, -3.0]))
    np.testing.assert_array_equal(low, 0.0)
    pos = np.column_stack([np.zeros(4), np.zeros(4), z])
    np.testing.assert_allclose(wind.velocity(0.0, pos)[:, 0], expected, rtol=1e-14)
    np.testing.assert_array_equal(wind.velocity(0.0, pos)[:, 1:], 0.0)


def test_power_profile_against_hand_formula():
    wind = WindField(WindConfig(speed_mps=5.0, profile="power", ref_height_m=10.0, shear_exponent=0.14))
    assert wind.mean_speed(40.0) == pytest.approx(5.0 * 4.0**0.14, rel=1e-14)
    assert wind.mean_speed(40.0) == pytest.approx(6.070974, rel=1e-6)  # 4^0.14 = 1.2141949
    assert wind.mean_speed(10.0) == pytest.approx(5.0, rel=1e-14)
    assert wind.mean_speed(2.5) == pytest.approx(5.0 * 0.25**0.14, rel=1e-14)
    np.testing.assert_array_equal(wind.mean_speed(np.array([0.0, -1.0])), 0.0)
    assert np.all(np.isfinite(wind.velocity(0.0, np.array([[0.0, 0.0, -2.0], [1.0, 1.0, 0.0]]))))


def test_spectra_are_normalised_von_karman():
    length = 80.0
    for comp in (0, 1):
        total = quad(lambda k, comp=comp: von_karman_spectra(np.array([k]), length)[comp][0], 0.0, np.inf, limit=200)[0]
        assert total == pytest.approx(1.0, abs=1e-4)
    f_u, f_t = von_karman_spectra(np.array([0.0]), length)
    # integral length scale L = pi F_u(0) / (2 sigma^2); transverse scale is half of it (isotropy)
    assert math.pi * f_u[0] / 2.0 == pytest.approx(length, rel=1e-14)
    assert math.pi * f_t[0] / 2.0 == pytest.approx(length / 2.0, rel=1e-14)
    # inertial range: F ~ k^(-5/3), F_t / F_u -> 4/3
    k = np.array([1e3, 2e3]) / length
    f_u, f_t = von_karman_spectra(k, length)
    assert math.log(f_u[1] / f_u[0]) / math.log(2.0) == pytest.approx(-5.0 / 3.0, abs=1e-3)
    assert f_t[1] / f_u[1] == pytest.approx(4.0 / 3.0, rel=1e-3)


def test_same_seed_identical_different_seed_different():
    cfg = WindConfig(turbulence_intensity=0.15, seed=3)
    v_a = WindField(cfg).velocity(12.3, POS)
    v_b = WindField(cfg).velocity(12.3, POS)
    assert np.array_equal(v_a, v_b)
    v_9 = WindField(cfg, seed=9).velocity(12.3, POS)
    assert np.array_equal(v_9, WindField(replace(cfg, seed=9)).velocity(12.3, POS))
    v_c = WindField(cfg, seed=4).velocity(12.3, POS)
    sigma = 0.15 * 5.0
    assert np.max(np.abs(v_c - v_a)) > 0.1 * sigma


def test_turbulence_statistics_at_one_point():
    """Frozen field advected past a fixed point: std of each component = TI * U, zero mean."""
    speed, ti = 5.0, 0.1
    wind = WindField(WindConfig(speed_mps=speed, turbulence_intensity=ti, turbulence_length_m=100.0))
    sigma = ti * speed
    t = np.random.default_rng(100).uniform(0.0, 40000.0, 20000)  # 2000 integral time scales L/U
    pos = np.tile([30.0, 5.0, 40.0], (t.size, 1))
    fluct = wind.velocity(t, pos) - [speed, 0.0, 0.0]
    np.testing.assert_allclose(fluct.std(axis=0), sigma, rtol=0.05)
    assert np.all(np.abs(fluct.mean(axis=0)) < 0.05 * sigma)
    # one time per position gives the same as separate scalar calls
    for i in (0, 777, 19999):
        np.testing.assert_allclose(fluct[i] + [speed, 0, 0], wind.velocity(t[i], pos[i]), atol=1e-9 * sigma)
    # longitudinal autocorrelation at a lag of one integral length, vs the von Karman correlation computed
    # independently from the spectrum: rho(xi) = int F_u(k) cos(k xi) dk
    xi = 100.0
    fluct_lag = wind.velocity(t + xi / speed, pos) - [speed, 0.0, 0.0]
    rho_sample = np.mean(fluct[:, 0] * fluct_lag[:, 0]) / np.mean(fluct[:, 0] ** 2)
    rho_vk = quad(lambda k: von_karman_spectra(np.array([k]), 100.0)[0][0], 0.0, np.inf, weight="cos", wvar=xi)[0]
    assert rho_vk == pytest.approx(0.347, abs=0.002)
    assert abs(rho_sample - rho_vk) < 0.06


def test_taylor_frozen_field():
    """u(t + tau, r + U tau e_x) = u(t, r) for the turbulence (uniform profile, no gust)."""
    wind = WindField(WindConfig(speed_mps=8.0, turbulence_intensity=0.2), seed=1)
    tau = 3.7
    np.testing.assert_allclose(wind.velocity(2.0 + tau, POS + [8.0 * tau, 0.0, 0.0]), wind.velocity(2.0, POS),
                               atol=1e-11)
    assert np.max(np.abs(wind.velocity(2.0 + tau, POS) - wind.velocity(2.0, POS))) > 1e-3  # it does change


def test_gust_shape():
    cfg = WindConfig(speed_mps=5.0, gust_speed_mps=3.0, gust_start_s=10.0, gust_duration_s=4.0)
    wind = WindField(cfg)
    g = wind.gust(np.array([0.0, 9.999, 10.0, 11.0, 12.0, 13.0, 14.0, 14.001, 50.0]))
    np.testing.assert_allclose(g, [0.0, 0.0, 0.0, 1.5, 3.0, 1.5, 0.0, 0.0, 0.0], atol=1e-14)
    assert wind.gust(12.0) == pytest.approx(3.0, rel=1e-15)  # peak at mid-duration
    v = wind.velocity(12.0, POS)
    np.testing.assert_allclose(v[:, 0], 8.0, rtol=1e-15)  # added uniformly along x_w
    np.testing.assert_array_equal(v[:, 1:], 0.0)
    lull = WindField(replace(cfg, gust_speed_mps=-2.0))
    assert lull.velocity(12.0, POS[0])[0] == pytest.approx(3.0)


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("speed_mps", -1.0, "wind.speed_mps must be >= 0"),
        ("profile", "cubic", "wind.profile must be one of uniform, log, power"),
        ("ref_height_m", 0.0, "wind.ref_height_m must be positive"),
        ("roughness_m", 0.0, r"wind.roughness_m must lie in \(0, ref_height_m\)"),
        ("roughness_m", 20.0, r"wind.roughness_m must lie in \(0, ref_height_m\)"),
        ("shear_exponent", -0.1, r"wind.shear_exponent must lie in \[0, 1\)"),
        ("turbulence_intensity", -0.05, "wind.turbulence_intensity must be >= 0"),
        ("turbulence_length_m", 0.0, "wind.turbulence_length_m must be positive"),
        ("turbulence_modes", 0, "wind.turbulence_modes must be >= 1"),
        ("gust_duration_s", -1.0, "wind.gust_duration_s must be >= 0"),
        ("gust_speed_mps", 2.0, "wind.gust_duration_s must be positive when wind.gust_speed_mps is not 0"),
        ("speed_mps", math.nan, "wind.speed_mps must be finite"),
        ("seed", -1, "wind.seed must be >= 0"),
    ],
)
def test_config_validation(field, value, match):
    with pytest.raises(ValueError, match=match):
        WindConfig(**{field: value})


def test_field_argument_validation():
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        WindField(WindConfig(), seed=-2)
    with pytest.raises(ValueError, match="backend must be one of"):
        WindField(WindConfig(), backend="cuda")


def test_auto_backend_is_the_packages_choice(monkeypatch):
    """The wind's ``"auto"`` backend follows the one rule of the package (kite_env.compiled.resolve_backend)."""
    monkeypatch.setenv("KITE_ENV_ELEMENT_BACKEND", "numpy")
    assert WindField(WindConfig()).backend == "numpy"
    monkeypatch.delenv("KITE_ENV_ELEMENT_BACKEND")
    assert WindField(WindConfig()).backend == ("numba" if NUMBA_AVAILABLE else "numpy")


def test_numba_and_numpy_backends_agree():
    cfg = WindConfig(speed_mps=6.0, profile="log", turbulence_intensity=0.12, gust_speed_mps=1.0,
                     gust_start_s=0.0, gust_duration_s=10.0)
    ref = WindField(cfg, backend="numpy")
    if not NUMBA_AVAILABLE:
        with pytest.raises(ImportError, match="numba"):
            WindField(cfg, backend="numba")
        return
    fast = WindField(cfg, backend="numba")
    assert fast.backend == "numba" and ref.backend == "numpy"
    for t in (0.0, 4.2, 1234.5):
        np.testing.assert_allclose(fast.velocity(t, POS), ref.velocity(t, POS), rtol=0, atol=1e-10)
    t_arr = np.array([0.0, 1.0, 2.0, 3.0])
    np.testing.assert_allclose(fast.velocity(t_arr, POS), ref.velocity(t_arr, POS), rtol=0, atol=1e-10)
