"""Flight metrics on a hand-made flight log with known answers (kite_env.metrics) and the time-series export."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from kite_env.config import load_config
from kite_env.flight import FlightLog
from kite_env.metrics import (
    MIN_FIT_SAMPLES,
    compute_metrics,
    heading_rate,
    heading_rate_mean,
    read_timeseries,
    write_timeseries,
    yaw_steering_fit,
)

DT = 0.01  # [s]
N_SEC = 5
DESIGN_TIP = 5.8  # [m]
WARMUP = 1.0  # [s]
ELEV0_DEG = 30.0  # trajectory.elevation_deg of the config below
PERIOD = 2.0  # period of the force / speed oscillation [s]
SLOPE = 2.0  # yaw rate = SLOPE * steering + 0.05 [rad/s per m] in the upper half
PSI_RATE = -0.7  # [rad/s]
FIG_RATE = 2 * math.pi / 4.0  # one figure-eight every 4 s [rad/s]


def cfg_for(warmup=WARMUP):
    return load_config(None, [f"sim.warmup_s={warmup}", f"trajectory.elevation_deg={ELEV0_DEG}"])


def synthetic_log(duration=9.0, warmup=WARMUP, rows=None) -> FlightLog:
    """A flight log with analytic series; the warm-up part carries absurd values that must not show up."""
    n = rows if rows is not None else int(round(duration / DT)) + 1
    t = np.arange(n) * DT
    w = 2 * np.pi / PERIOD
    ph = w * (t - warmup)  # phase 0 at the end of the warm-up
    warm = t < warmup
    steer = 0.1 * np.sin(1.3 * t)
    upper = np.sin(2 * np.pi * t / 4.0) > 0  # upper half of the figure: elevation above the crossing
    elev = np.radians(ELEV0_DEG + np.where(upper, 8.0, -8.0) * np.abs(np.sin(2 * np.pi * t / 4.0)) +
                      np.where(upper, 0.5, -0.5))
    yaw = np.where(upper, SLOPE * steer + 0.05, np.cos(7.1 * t))  # unrelated in the lower half
    alpha = np.zeros((n, N_SEC))
    alpha[:, N_SEC // 2] = np.radians(7.5)
    alpha[:, -1] = np.radians(2.0 + 4.0 * np.sin(ph))  # left tip: min -2 deg
    alpha[:, 0] = np.radians(3.0 - 5.0 * np.sin(ph))  # right tip: min -2 deg
    omega_k = np.zeros((n, 3))
    omega_k[:, 2] = yaw
    r = np.zeros((n, 5, 3))
    r[:, 4] = 100.0 * np.stack([np.cos(elev), np.zeros(n), np.sin(elev)], axis=1)
    pd = np.where(np.arange(n) % 2 == 0, np.radians(1.0), np.radians(3.0))  # RMS sqrt(5) deg
    series = {
        "t": t, "r": r, "omega_k": omega_k,
        "speed": 23.0 + 5.0 * np.cos(ph),
        "tether_force": 4500.0 + 1500.0 * np.sin(ph),
        "lift_to_drag": 8.25 + 0.75 * np.sin(ph),
        "mu": 0.30 + 0.04 * np.sin(ph),
        "alpha": alpha,
        "steering_input": steer,
        "elevation": elev, "azimuth": np.radians(20.0) * np.sin(2 * np.pi * t / 4.0),
        "psi": (PSI_RATE * t + np.pi) % (2 * np.pi) - np.pi,  # wrapped
        "path_s": 3.0 + FIG_RATE * t,
        "path_distance": pd,
        "tip_distance": DESIGN_TIP - 1.0 + 0.15 * np.sin(ph),
        "tip_disp_left": 0.5 + 0.1 * np.sin(ph), "tip_disp_right": 0.45 - 0.2 * np.sin(ph),
        # y_k of A, B, C, D (Fig. 18): A and C at half the tip distance, B and D moving by 0.25 and 0.35 m in total
        "bridle_y": np.stack([0.5 * (DESIGN_TIP - 1.0 + 0.15 * np.sin(ph)), 2.4 + 0.125 * np.sin(ph),
                              -0.5 * (DESIGN_TIP - 1.0 + 0.15 * np.sin(ph)), -2.4 + 0.175 * np.cos(ph)], axis=1),
        "newton_iters": np.where(np.arange(n) % 2 == 0, 3.0, 5.0),
        "wall_time": np.full(n, 0.012),
        "constraint_drift": np.outer(np.sin(t), [1e-9, -4e-9, 2e-9]),
        "line_tension": np.outer(np.ones(n), [1500.0, 400.0, 1500.0, 400.0]),
        "line_length": np.outer(np.ones(n), [25.0, 25.2, 25.0, 25.2]),
        "delta_l": 0.9 * steer, "delta_l_star": steer,
        "section_lift": np.ones((n, N_SEC)) * 100.0, "section_drag": np.ones((n, N_SEC)) * 12.0,
    }
    for key in ("tether_force", "speed", "lift_to_drag", "mu", "tip_distance", "tip_disp_left", "tip_disp_right",
                "path_distance", "newton_iters", "bridle_y"):
        series[key] = np.where(warm.reshape((-1,) + (1,) * (series[key].ndim - 1)), 1e6, series[key])
    series["alpha"][warm] = 3.0
    series["wall_time"][0] = 0.0
    snaps = {"design": np.zeros((12, 3)), "initial": np.ones((12, 3))}
    meta = {"crashed": False, "termination_reason": "completed", "sim_time_s": float(t[-1]),
            "wall_time_s": 2.5 * float(t[-1]), "design_tip_distance_m": DESIGN_TIP, "warmup_s": warmup,
            "n_sections": N_SEC, "pair_stiffness_N_per_m": [1.0, 2.0],
            "design_bridle_y_m": [DESIGN_TIP / 2, 2.6, -DESIGN_TIP / 2, -2.6]}
    return FlightLog(series=series, meta=meta, snapshots=snaps)


@pytest.fixture(scope="module")
def metrics():
    return compute_metrics(synthetic_log(), cfg_for())


def test_whole_flight_and_window_keys(metrics):
    assert metrics["sim_time_s"] == pytest.approx(9.0)
    assert metrics["wall_time_s"] == pytest.approx(22.5)
    assert metrics["real_time_factor"] == pytest.approx(2.5)
    assert metrics["crashed"] is False and metrics["termination_reason"] == "completed"
    assert "after the warm-up" in metrics["metrics_window"]
    assert metrics["metrics_window_start_s"] == pytest.approx(WARMUP)
    assert metrics["metrics_window_samples"] == 801


def test_force_speed_aero_values_exclude_warmup(metrics):
    # window = 4 full periods of the oscillations, sampled at their extremes
    assert metrics["tether_force_mean_N"] == pytest.approx(4500.0, rel=1e-9)
    assert metrics["tether_force_min_N"] == pytest.approx(3000.0, rel=1e-9)
    assert metrics["tether_force_max_N"] == pytest.approx(6000.0, rel=1e-9)
    assert metrics["kite_speed_min_mps"] == pytest.approx(18.0)
    assert metrics["kite_speed_max_mps"] == pytest.approx(28.0)
    assert metrics["kite_speed_mean_mps"] == pytest.approx(23.0 + 5.0 / 801)  # one extra sample at cos = 1
    assert metrics["lift_to_drag_min"] == pytest.approx(7.5)
    assert metrics["lift_to_drag_max"] == pytest.approx(9.0)
    assert metrics["lift_to_drag_mean"] == pytest.approx(8.25, abs=1e-9)
    assert metrics["force_ratio_mu_min"] == pytest.approx(0.26)
    assert metrics["force_ratio_mu_max"] == pytest.approx(0.34)
    assert metrics["alpha_mid_mean_deg"] == pytest.approx(7.5)
    assert metrics["alpha_mid_min_deg"] == pytest.approx(7.5) and metrics["alpha_mid_max_deg"] == pytest.approx(7.5)
    assert metrics["alpha_left_min_deg"] == pytest.approx(-2.0)
    assert metrics["alpha_left_max_deg"] == pytest.approx(6.0)
    assert metrics["alpha_right_min_deg"] == pytest.approx(-2.0)
    assert metrics["alpha_right_max_deg"] == pytest.approx(8.0)


def test_path_and_heading(metrics):
    # window: path_s grows by FIG_RATE * 8 s = 2 figures exactly -> floor(2 - round-off) must still be 2
    assert metrics["figure_eights_completed"] == 2
    assert metrics["figure_period_s"] == pytest.approx(4.0)
    assert metrics["tracking_error_rms_deg"] == pytest.approx(math.sqrt(5.0), rel=1e-3)
    assert metrics["heading_rate_mean_deg_s"] == pytest.approx(math.degrees(abs(PSI_RATE)), rel=1e-9)


def test_steering_and_yaw_fit(metrics):
    t = np.arange(801) * DT + WARMUP
    assert metrics["steering_input_max_m"] == pytest.approx(np.max(np.abs(0.1 * np.sin(1.3 * t))))
    assert metrics["yaw_rate_steering_corr"] == pytest.approx(1.0, abs=1e-12)
    assert metrics["yaw_rate_steering_slope_deg_s_per_m"] == pytest.approx(math.degrees(SLOPE), rel=1e-9)
    upper = np.sin(2 * np.pi * t / 4.0) > 0
    assert metrics["yaw_rate_steering_samples"] == int(upper.sum())


def test_deformation_and_numerics(metrics):
    assert metrics["tip_distance_reduction_mean_m"] == pytest.approx(1.0, abs=1e-9)
    assert metrics["tip_distance_variation_m"] == pytest.approx(0.3)
    assert metrics["tip_displacement_left_mean_m"] == pytest.approx(0.5, abs=1e-9)
    assert metrics["tip_displacement_right_mean_m"] == pytest.approx(0.45, abs=1e-9)
    assert metrics["tip_displacement_left_variation_m"] == pytest.approx(0.2)
    assert metrics["tip_displacement_right_variation_m"] == pytest.approx(0.4)
    # Fig. 18's bridle points: each point's total variation, a tip's the larger of its two points'
    assert metrics["bridle_A_y_variation_m"] == pytest.approx(0.15)
    assert metrics["bridle_C_y_variation_m"] == pytest.approx(0.15)
    assert metrics["bridle_B_y_variation_m"] == pytest.approx(0.25)
    assert metrics["bridle_D_y_variation_m"] == pytest.approx(0.35)
    assert metrics["tip_right_bridle_y_variation_m"] == pytest.approx(0.25)
    assert metrics["tip_left_bridle_y_variation_m"] == pytest.approx(0.35)
    assert metrics["newton_iters_mean"] == pytest.approx(4.0, abs=1.0 / 801)
    assert metrics["wall_time_per_step_ms_median"] == pytest.approx(12.0)
    t = np.arange(801) * DT + WARMUP
    assert metrics["constraint_drift_max_m"] == pytest.approx(4e-9 * np.abs(np.sin(t)).max())


def test_paper_comparison(metrics):
    rows = {r["quantity"]: r for r in metrics["paper_comparison"]}
    assert len(rows) == 9
    for r in rows.values():
        assert set(r) == {"quantity", "model", "paper", "unit", "source"}
    force = rows["traction (tether) force range"]
    assert force["unit"] == "kN" and force["paper"] == [3.0, 6.0]
    assert force["model"] == pytest.approx([3.0, 6.0])
    assert rows["mid-wing angle of attack (mean)"]["model"] == pytest.approx(7.5)
    assert rows["force ratio mu range"]["paper"] == [0.26, 0.34]
    assert rows["tip distance reduction (mean)"]["model"] == pytest.approx(1.0)
    assert rows["transverse displacement variation, right tip (A, B)"]["model"] == pytest.approx(0.25)
    assert rows["transverse displacement variation, left tip (C, D)"]["model"] == pytest.approx(0.35)
    fig16 = rows["heading rate per steering input, upper half"]
    assert fig16["paper"] == 5.0 and fig16["unit"] == "rad/s/m"
    slope = metrics["heading_rate_steering_slope_deg_s_per_m"]
    assert slope is not None and fig16["model"] == pytest.approx(np.deg2rad(slope))


def test_json_serialisable_with_nan_and_inf():
    log = synthetic_log()
    log.series["lift_to_drag"][:] = np.nan  # no finite sample at all -> None
    log.series["speed"][200] = np.nan  # one bad sample: ignored
    log.series["tether_force"][300] = np.inf
    m = compute_metrics(log, cfg_for())
    text = json.dumps(m, allow_nan=False)  # raises on NaN / inf
    assert json.loads(text) == m
    assert m["lift_to_drag_min"] is None and m["lift_to_drag_mean"] is None
    assert m["kite_speed_max_mps"] == pytest.approx(28.0)
    assert m["tether_force_max_N"] == pytest.approx(6000.0)
    rows = {r["quantity"]: r for r in m["paper_comparison"]}
    assert rows["lift-to-drag ratio range"]["model"] == [None, None]
    for v in m.values():
        assert v is None or isinstance(v, (bool, int, float, str, list))


def test_flight_shorter_than_warmup_uses_everything():
    log = synthetic_log(duration=0.5, warmup=1.0)  # everything is "warm-up" (values 1e6)
    m = compute_metrics(log, cfg_for(1.0))
    assert m["metrics_window"].startswith("whole flight")
    assert m["metrics_window_samples"] == 51
    assert m["tether_force_mean_N"] == pytest.approx(1e6)
    assert m["figure_eights_completed"] == 0 and m["figure_period_s"] is None
    json.dumps(m, allow_nan=False)


def test_crash_meta_and_zero_length_series():
    log = synthetic_log(duration=2.0)
    log.meta.update(crashed=True, termination_reason="ground")
    m = compute_metrics(log, cfg_for())
    assert m["crashed"] is True and m["termination_reason"] == "ground"
    one = synthetic_log(rows=1)
    m1 = compute_metrics(one, cfg_for(0.0))
    assert m1["sim_time_s"] == 0.0 and m1["real_time_factor"] is None
    assert m1["heading_rate_mean_deg_s"] is None and m1["yaw_rate_steering_corr"] is None
    assert m1["wall_time_per_step_ms_median"] is None  # row 0 is no step


def test_yaw_fit_edge_cases():
    x = np.linspace(-0.2, 0.2, 40)
    up = np.ones(40, dtype=bool)
    few = up.copy()
    few[MIN_FIT_SAMPLES - 1:] = False
    assert yaw_steering_fit(x, 3.0 * x, few)[0] is None  # 9 samples
    corr, slope, icpt, n = yaw_steering_fit(x, -3.0 * x + 1.0, up)
    assert corr == pytest.approx(-1.0) and slope == pytest.approx(math.degrees(-3.0))
    assert icpt == pytest.approx(math.degrees(1.0)) and n == 40
    # constant steering: no fit; constant yaw rate: slope 0, no correlation
    assert yaw_steering_fit(np.full(40, 0.1), x, up)[:3] == (None, None, None)
    corr, slope, _, _ = yaw_steering_fit(x, np.full(40, 0.3), up)
    assert corr is None and slope == pytest.approx(0.0, abs=1e-9)
    # NaN samples are dropped; an independent check against numpy
    rng = np.random.default_rng(1)
    xr, yr = rng.normal(size=200), rng.normal(size=200)
    xr[5] = np.nan
    ok = np.isfinite(xr)
    corr, slope, _, n = yaw_steering_fit(xr, yr, np.ones(200, dtype=bool))
    assert n == 199 and corr == pytest.approx(np.corrcoef(xr[ok], yr[ok])[0, 1])
    assert slope == pytest.approx(math.degrees(np.polyfit(xr[ok], yr[ok], 1)[0]))


def test_heading_rate_unwraps_across_pi():
    t = np.linspace(0.0, 10.0, 1001)
    psi = (2.0 * t + np.pi) % (2 * np.pi) - np.pi
    assert heading_rate_mean(t, psi) == pytest.approx(2.0)
    assert heading_rate_mean(t[:1], psi[:1]) is None
    assert np.allclose(heading_rate(t, psi), 2.0)
    psi_q = 0.3 * t ** 2  # second-order differences: exact for a quadratic inside, first order at the ends
    assert np.allclose(heading_rate(t, psi_q)[1:-1], 0.6 * t[1:-1])
    psi_q[5] = np.nan
    assert np.isnan(heading_rate(t, psi_q)[5]) and np.isfinite(heading_rate(t, psi_q)[4])
    assert np.isnan(heading_rate(t[:1], psi[:1])).all()


def test_the_heading_rate_against_the_steering_input_is_fitted_like_the_yaw_rate():
    """Fig. 16's fit with the heading's rate (the paper's yaw angle): here the heading turns at a constant rate while
    the input varies, so the slope is zero and the correlation undefined."""
    m = compute_metrics(synthetic_log(), cfg_for())
    assert m["heading_rate_steering_slope_deg_s_per_m"] == pytest.approx(0.0, abs=1e-6)
    assert m["heading_rate_steering_corr"] is None


def test_write_timeseries_round_trip(tmp_path):
    log = synthetic_log(duration=1.5)
    log.series["speed"][3] = np.nan
    npz, csv_path = write_timeseries(log, tmp_path)
    assert npz == tmp_path / "timeseries.npz" and csv_path == tmp_path / "timeseries.csv"
    back = read_timeseries(npz)
    assert set(back.series) == set(log.series)
    for k, v in log.series.items():
        np.testing.assert_array_equal(back.series[k], v)
    assert back.meta == log.meta
    for k, v in log.snapshots.items():
        np.testing.assert_array_equal(back.snapshots[k], v)
    with open(csv_path) as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    assert len(rows) == 1 + log.series["t"].size
    scalar = [k for k, v in log.series.items() if v.ndim == 1]
    assert header[:len(scalar)] == scalar
    for extra in ("alpha_mid", "alpha_left", "alpha_right", "line_tension_A", "line_tension_D", "kcu_x", "kcu_z"):
        assert extra in header
    col = {name: i for i, name in enumerate(header)}
    data = np.array([[float(x) for x in r] for r in rows[1:]])
    np.testing.assert_allclose(data[:, col["tether_force"]], log.series["tether_force"], rtol=1e-9)
    np.testing.assert_allclose(data[:, col["alpha_left"]], log.series["alpha"][:, -1], rtol=1e-8)
    np.testing.assert_allclose(data[:, col["kcu_z"]], log.series["r"][:, 4, 2], rtol=1e-8)
    assert np.isnan(data[3, col["speed"]])
