"""The wing's response to fast steering, in both fidelities: the paper's controller flies the figure-eight with a
small sinusoid added to its action, and a lock-in (projection on the sinusoid's sine and cosine over whole periods)
gives the gain and phase of the yaw rate and of the tether force per metre of the steering-line difference actually
applied (``info["delta_l_m"]``, after the actuator), at each frequency.

A policy whose action changes every few control steps (PPO: 0.05 per 20 ms step) excites the wing at 1-5 Hz; where
the reduced-order wing answers there otherwise than the wing with inertia, what such a policy learns in the fast
fidelity does not carry over (docs/fast_fidelity.md, "Where it falls short").

    .venv/bin/python analyses/steering_response.py [--freqs 0.5,1,2,3,5] [--amplitude 0.05] [--wind 6.3]
        [--periods-s 16] [--fidelity fe --fidelity surrogate]

Prints one table row per fidelity and frequency.
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def lock_in(t: np.ndarray, y: np.ndarray, f_hz: float) -> complex:
    """Complex amplitude of ``y`` at ``f_hz`` (``y ~ Re(c exp(i w t))``) over the samples ``t`` (whole periods)."""
    w = 2.0 * math.pi * f_hz
    y = y - y.mean()
    return complex(2.0 * np.mean(y * np.cos(w * t)), -2.0 * np.mean(y * np.sin(w * t)))


def response(fidelity: str, f_hz: float, amplitude: float, wind_mps: float, record_s: float,
             settle_s: float = 4.0) -> dict:
    """Fly the controller plus ``amplitude * sin(2 pi f t)`` (normalised action) and return the gains of yaw rate
    [rad/s per m] and tether force [N per m] on the applied steering difference at ``f_hz``, with phases [deg]."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.policies.baseline import BaselineAgent

    n_periods = max(1, round(record_s * f_hz))
    duration = settle_s + n_periods / f_hz
    env = KiteFigureEightEnv(overrides=[f"wind.speed_mps={wind_mps}", "wind.turbulence_intensity=0.0",
                                        f"env.max_episode_s={duration + 1.0}"], fidelity=fidelity)
    agent = BaselineAgent(env.cfg)
    obs, _ = env.reset(seed=0)
    start, rows = True, []
    while True:
        a, _ = agent.predict(obs, episode_start=start)
        start = False
        t = env.steps * env.control_dt
        a = np.clip(a + amplitude * math.sin(2.0 * math.pi * f_hz * t), -1.0, 1.0).astype(np.float32)
        obs, _, term, trunc, info = env.step(a)
        rows.append((info["t"], info["delta_l_m"], info["yaw_rate_rad_s"], info["tether_force_N"]))
        if term or trunc or info["t"] >= duration - 1e-9:
            break
    env.close()
    t, dl, yaw, force = (np.array(c) for c in zip(*rows))
    keep = t > t[-1] - n_periods / f_hz + 1e-9
    if term or keep.sum() < 10:
        return {"fidelity": fidelity, "f_hz": f_hz, "ended": info["termination_reason"]}
    u = lock_in(t[keep], dl[keep], f_hz)
    out = {"fidelity": fidelity, "f_hz": f_hz, "ended": None, "dl_amp_m": abs(u)}
    for name, y in (("yaw", yaw), ("force", force)):
        g = lock_in(t[keep], y[keep], f_hz) / u
        out[f"{name}_gain"], out[f"{name}_phase_deg"] = abs(g), math.degrees(math.atan2(g.imag, g.real))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--freqs", default="0.5,1,2,3,5", help="frequencies [Hz], comma-separated")
    p.add_argument("--amplitude", type=float, default=0.05, help="sinusoid's amplitude in normalised action")
    p.add_argument("--wind", type=float, default=6.3, help="steady wind speed [m/s]")
    p.add_argument("--periods-s", type=float, default=16.0, help="recorded time per frequency [s] (whole periods)")
    p.add_argument("--fidelity", action="append", choices=("fe", "surrogate"), default=None)
    args = p.parse_args()
    print(f"{'fidelity':<10} {'f [Hz]':>6} {'dl amp [m]':>10} {'yaw gain [rad/s/m]':>19} {'phase [deg]':>11} "
          f"{'force gain [kN/m]':>18} {'phase [deg]':>11}")
    for f in (float(x) for x in args.freqs.split(",")):
        for fid in args.fidelity or ["fe", "surrogate"]:
            r = response(fid, f, args.amplitude, args.wind, args.periods_s)
            if r["ended"]:
                print(f"{fid:<10} {f:>6g}  ended early: {r['ended']}")
                continue
            print(f"{fid:<10} {f:>6g} {r['dl_amp_m']:>10.4f} {r['yaw_gain']:>19.3f} {r['yaw_phase_deg']:>11.1f} "
                  f"{r['force_gain'] / 1e3:>18.2f} {r['force_phase_deg']:>11.1f}", flush=True)


if __name__ == "__main__":
    main()
