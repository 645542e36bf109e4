"""The wing's response to fast steering, in both fidelities: the paper's controller flies the figure-eight with a
small sinusoid added to its action, and a lock-in (projection on the sinusoid's sine and cosine over whole periods)
gives the gain and phase of the yaw rate and of the tether force per metre of the steering-line difference actually
applied (``info["delta_l_m"]``, after the actuator), at each frequency.

A policy whose action changes every few control steps (PPO: 0.05 per 20 ms step) excites the wing at 1-5 Hz; where
the reduced-order wing answers there otherwise than the wing with inertia, what such a policy learns in the fast
fidelity does not carry over (docs/fast_fidelity.md, "Where it falls short").

    .venv/bin/python analyses/steering_response.py [--freqs 0.5,1,2,3,5] [--amplitude 0.05] [--wind 6.3]
        [--periods-s 16] [--fidelity fe --fidelity surrogate] [--set SECTION.KEY=VALUE ...]

``--input depower`` adds the sinusoid (``--amplitude`` in metres) to the force loop's common increment of both
steering lines instead (Eq. 16-17's L3, the depower actuation) and gives the force ratio's response
(mu, Eq. 18) per metre of the common rest length actually applied; with ``K3`` (``control.k3_m``) it gives the force
loop's gain at each frequency, ``K3 |mu / c|``: where it reaches 1 with the loop's phase, the loop cannot hold the
force ratio and drives the wing's pitch (docs/fast_fidelity.md, "Why the fast kite pulls less at low wind").

    .venv/bin/python analyses/steering_response.py --input depower --amplitude 0.01 --wind 4.5 --freqs 0.5,1,1.5,2,3

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
             settle_s: float = 4.0, depower: bool = False, overrides=()) -> dict:
    """Fly the controller plus ``amplitude * sin(2 pi f t)`` (normalised action) and return the gains of yaw rate
    [rad/s per m] and tether force [N per m] on the applied steering difference at ``f_hz``, with phases [deg].
    With ``depower`` the sinusoid [m] goes into the force loop's common increment L3 instead, and the gains are on
    the applied common rest length ``(L_B + L_D) / 2``, with the force ratio's (``mu`` per m) added."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.policies.baseline import BaselineAgent

    n_periods = max(1, round(record_s * f_hz))
    duration = settle_s + n_periods / f_hz
    env = KiteFigureEightEnv(overrides=[f"wind.speed_mps={wind_mps}", "wind.turbulence_intensity=0.0",
                                        f"env.max_episode_s={duration + 1.0}", *overrides], fidelity=fidelity)
    agent = BaselineAgent(env.cfg)
    obs, _ = env.reset(seed=0)
    start, rows = True, []
    while True:
        a, _ = agent.predict(obs, episode_start=start)
        start = False
        t = env.steps * env.control_dt
        if depower:  # on top of the force loop's common increment (LineActuator.depower_offset_m)
            env.actuator.depower_offset_m = amplitude * math.sin(2.0 * math.pi * f_hz * t)
        else:
            a = np.clip(a + amplitude * math.sin(2.0 * math.pi * f_hz * t), -1.0, 1.0).astype(np.float32)
        obs, _, term, trunc, info = env.step(a)
        u_in = 0.5 * (info["L_B_m"] + info["L_D_m"]) if depower else info["delta_l_m"]
        rows.append((info["t"], u_in, info["yaw_rate_rad_s"], info["tether_force_N"], info["force_ratio_mu"]))
        if term or trunc or info["t"] >= duration - 1e-9:
            break
    env.close()
    t, dl, yaw, force, mu = (np.array(c) for c in zip(*rows))
    keep = t > t[-1] - n_periods / f_hz + 1e-9
    if term or keep.sum() < 10:
        return {"fidelity": fidelity, "f_hz": f_hz, "ended": info["termination_reason"]}
    u = lock_in(t[keep], dl[keep], f_hz)
    out = {"fidelity": fidelity, "f_hz": f_hz, "ended": None, "dl_amp_m": abs(u)}
    for name, y in (("yaw", yaw), ("force", force), ("mu", mu)):
        g = lock_in(t[keep], y[keep], f_hz) / u
        out[f"{name}_gain"], out[f"{name}_phase_deg"] = abs(g), math.degrees(math.atan2(g.imag, g.real))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--freqs", default="0.5,1,2,3,5", help="frequencies [Hz], comma-separated")
    p.add_argument("--input", choices=("steering", "depower"), default="steering",
                   help="where the sinusoid goes: the action (steering) or the force loop's common increment")
    p.add_argument("--amplitude", type=float, default=None,
                   help="sinusoid's amplitude: normalised action (steering, default 0.05) or m (depower, default 0.01)")
    p.add_argument("--wind", type=float, default=6.3, help="steady wind speed [m/s]")
    p.add_argument("--periods-s", type=float, default=16.0, help="recorded time per frequency [s] (whole periods)")
    p.add_argument("--fidelity", action="append", choices=("fe", "surrogate"), default=None)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="config override, e.g. sim.surrogate_path=runs/fast/rhino16.npz (another reduced-order wing)")
    args = p.parse_args()
    depower = args.input == "depower"
    amplitude = args.amplitude if args.amplitude is not None else (0.01 if depower else 0.05)
    if depower:
        from kite_env.config import load_config

        k3 = load_config(None, []).control.k3_m
        print(f"{'fidelity':<10} {'f [Hz]':>6} {'c amp [m]':>10} {'mu gain [1/m]':>14} {'phase [deg]':>11} "
              f"{'K3 x mu gain':>12} {'force gain [kN/m]':>18} {'phase [deg]':>11}")
    else:
        print(f"{'fidelity':<10} {'f [Hz]':>6} {'dl amp [m]':>10} {'yaw gain [rad/s/m]':>19} {'phase [deg]':>11} "
              f"{'force gain [kN/m]':>18} {'phase [deg]':>11}")
    for f in (float(x) for x in args.freqs.split(",")):
        for fid in args.fidelity or ["fe", "surrogate"]:
            r = response(fid, f, amplitude, args.wind, args.periods_s, depower=depower, overrides=args.set)
            if r["ended"]:
                print(f"{fid:<10} {f:>6g}  ended early: {r['ended']}")
                continue
            if depower:
                print(f"{fid:<10} {f:>6g} {r['dl_amp_m']:>10.4f} {r['mu_gain']:>14.3f} {r['mu_phase_deg']:>11.1f} "
                      f"{k3 * r['mu_gain']:>12.3f} {r['force_gain'] / 1e3:>18.2f} {r['force_phase_deg']:>11.1f}",
                      flush=True)
                continue
            print(f"{fid:<10} {f:>6g} {r['dl_amp_m']:>10.4f} {r['yaw_gain']:>19.3f} {r['yaw_phase_deg']:>11.1f} "
                  f"{r['force_gain'] / 1e3:>18.2f} {r['force_phase_deg']:>11.1f}", flush=True)


if __name__ == "__main__":
    main()
