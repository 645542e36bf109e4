"""The paper's controller in the fast fidelity at low wind: how many flights leave the reduced-order wing's envelope,
with the force loop (Eq. 19 and its integral) on, and off.

At 4.5 m/s with turbulence 0.1 the fast kite flown by the paper's controller leaves its envelope in about half of
the 120 s flights, while the full model completed each of them it flew (seeds 50000-50007); the reduced-order wing
answers a change of the common steering-line length (the force loop's depower actuation) several times more
strongly than the wing with inertia (``analyses/steering_response.py --input depower``), so the loop that holds the
force ratio drives a pitch swing instead. ``--force-loop off`` holds the common length at its start value
(``control.k3_m = k3i_per_s = 0``): a diagnosis only. The force loop's gains are part of the model's record, so the
shipped wing refuses that config; this script accepts that one mismatch on purpose and says so in its output
(docs/fast_fidelity.md, "Where it falls short").

    .venv/bin/python analyses/low_wind_exits.py [--winds 4.5,5.5] [--episodes 20] [--seed 50000]
        [--duration 120] [--force-loop on|off] [--set SECTION.KEY=VALUE ...]

Prints one line per wind: flights that left the envelope (and their seeds), mean traction +- standard error,
RMS tracking error.
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def fly(wind_mps: float, seed: int, duration_s: float, force_loop: bool, overrides=()) -> dict:
    """One flight of the controller in the fast fidelity (wind ``wind_mps``, turbulence 0.1, realisation and reset
    ``seed``): its end, mean traction [N] and RMS distance to the figure [deg]."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.policies.baseline import BaselineAgent

    over = [f"wind.speed_mps={wind_mps}", "wind.turbulence_intensity=0.1", f"wind.seed={seed}",
            f"env.max_episode_s={duration_s}", *overrides]
    if not force_loop:
        over += ["control.k3_m=0", "control.k3i_per_s=0"]
    env = KiteFigureEightEnv(overrides=over, fidelity="surrogate")
    agent = BaselineAgent(env.cfg)
    obs, _ = env.reset(seed=seed)
    start, force, dist = True, [], []
    while True:
        a, _ = agent.predict(obs, episode_start=start)
        start = False
        obs, _, term, trunc, info = env.step(a)
        force.append(info["tether_force_N"])
        dist.append(info["path_distance_rad"])
        if term or trunc:
            break
    env.close()
    return {"end": info["termination_reason"], "t": info["t"], "traction_N": float(np.mean(force)),
            "tracking_deg": math.degrees(math.sqrt(float(np.mean(np.square(dist)))))}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--winds", default="4.5,5.5", help="wind speeds [m/s], comma-separated")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--seed", type=int, default=50000, help="first seed (the held-out seeds of docs/agents.md)")
    p.add_argument("--duration", type=float, default=120.0)
    p.add_argument("--force-loop", choices=("on", "off"), default="on")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="config override, e.g. sim.surrogate_path=runs/fast/rhino16.npz (another reduced-order wing)")
    args = p.parse_args()
    loop = args.force_loop == "on"
    if not loop:
        import dataclasses

        import kite_env.config

        check, default = kite_env.config.check_model, kite_env.config.load_config(None, []).control

        def check_but_force_loop(record, cfg, what):  # the one mismatch this diagnosis makes on purpose
            ctl = dataclasses.replace(cfg.control, k3_m=default.k3_m, k3i_per_s=default.k3i_per_s)
            return check(record, dataclasses.replace(cfg, control=ctl), what)

        kite_env.config.check_model = check_but_force_loop
        print("force loop off (control.k3_m = control.k3i_per_s = 0): the shipped wing's model record differs in "
              "these two keys only, accepted for this diagnosis")
    for w in (float(x) for x in args.winds.split(",")):
        rows = [fly(w, s, args.duration, loop, args.set) for s in range(args.seed, args.seed + args.episodes)]
        left = [(args.seed + i, round(r["t"], 1)) for i, r in enumerate(rows) if r["end"] != "time limit"]
        F = np.array([r["traction_N"] for r in rows])
        print(f"{w:g} m/s, force loop {args.force_loop}: {len(left)} of {len(rows)} flights left the envelope "
              f"{left}; traction {F.mean():,.0f} +- {F.std(ddof=1) / math.sqrt(len(F)):,.0f} N; tracking "
              f"{np.mean([r['tracking_deg'] for r in rows]):.2f} deg", flush=True)


if __name__ == "__main__":
    main()
