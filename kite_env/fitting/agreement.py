"""Agreement of the fast fidelity with the full model over whole flights (``kite-fit agreement``).

Whole flights, not single steps, are what an agent is trained on: a reduced-order wing whose one-step error is small
can still drift, turn at another rate or leave its envelope. Two sets of flights are flown in both fidelities:

* :data:`FLIGHTS`: the paper's controller from the crossing of the figure-eight, 300 s at the paper's 5 m/s and 120 s at
  4, 7 and 10 m/s with turbulence intensity 0.1 (the same turbulence realisation in both); compared by mean traction
  (within :data:`TRACTION_REL`), tracking error (within :data:`TRACKING_DEG`) and the number of figure-eights;
* random steering: episodes of 30 s in the conditions the fast wing was fitted in (wind 4-10 m/s, turbulence up to 0.1,
  starts on the straight parts at 4.0-4.8 times the wind), seed ``seed + i``; compared by how many episodes end for
  each reason (within :data:`END_REASON_EPISODES`).

The full model's results depend only on the model; they are kept per case in ``fe/`` of the output folder (with the
model's fingerprint, refused for another model) so that a refitted fast wing is compared without flying them again.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

#: the acceptance of one flight (mean traction relative, tracking error absolute)
TRACTION_REL, TRACKING_DEG, END_REASON_EPISODES = 0.03, 1.0, 5
#: the conditions of the random-steering episodes (those of the sampling plan and of the training recipes)
RANDOM_CONDITIONS = ("env.wind_speed_min_mps=4", "env.wind_speed_max_mps=10", "env.turbulence_intensity_max=0.1",
                     "env.random_start=true", "env.start_curvature_max=1.0", "env.initial_speed_per_wind_min=4.0",
                     "env.initial_speed_per_wind_max=4.8")


@dataclass(frozen=True)
class Flight:
    name: str
    wind_mps: float
    turbulence: float
    duration_s: float

    def overrides(self) -> list[str]:
        return [f"wind.speed_mps={self.wind_mps}", f"wind.turbulence_intensity={self.turbulence}", "wind.seed=0"]


FLIGHTS = (Flight("5 m/s, 300 s", 5.0, 0.0, 300.0), Flight("4 m/s, turbulence 0.1, 120 s", 4.0, 0.1, 120.0),
           Flight("7 m/s, turbulence 0.1, 120 s", 7.0, 0.1, 120.0),
           Flight("10 m/s, turbulence 0.1, 120 s", 10.0, 0.1, 120.0))


def fly_case(args) -> dict:
    """One baseline flight (``(overrides, duration_s)``): its metrics that the comparison uses."""
    overrides, duration = args
    from kite_env.config import load_config
    from kite_env.flight import fly
    from kite_env.metrics import compute_metrics

    cfg = load_config(None, overrides)
    t0 = time.perf_counter()
    log = fly(cfg, duration_s=duration)
    m = compute_metrics(log, cfg)
    return {"traction_mean_N": m["tether_force_mean_N"], "tracking_rms_deg": m["tracking_error_rms_deg"],
            "figure_eights": m["figure_eights_completed"], "end": m["termination_reason"] or "completed",
            "flown_s": m["sim_time_s"], "wall_s": time.perf_counter() - t0}


def random_episode(args) -> dict:
    """One random-steering episode (``(overrides, seed, duration_s)``): how and when it ended."""
    overrides, seed, duration = args
    from kite_env.config import load_config
    from kite_env.dynamics.simulator import NumericalFailure
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.flight import run_episode
    from kite_env.policies import RandomAgent

    cfg = load_config(None, [*overrides, f"env.max_episode_s={duration}", "env.randomize=true"])
    env = KiteFigureEightEnv(config=cfg)
    try:
        _, info = run_episode(env, RandomAgent(seed), seed=seed, record=False)
    except NumericalFailure as exc:
        return {"seed": seed, "end": "numerical failure", "t": exc.t}
    env.close()
    return {"seed": seed, "end": info["termination_reason"] or "completed", "t": info["episode_steps"] * env.control_dt,
            "wind_mps": info["wind_speed_mps"]}


def _cached(folder: Path, name: str, model: dict, compute):
    """The full model's result ``name`` from ``folder`` (made for ``model``), else computed and kept."""
    from kite_env.config import check_model

    path = folder / f"{name}.json"
    if path.is_file():
        data = json.loads(path.read_text())
        check_model(data["model"], _config(model), f"full-model result '{path}'")
        return data["result"]
    result = compute()
    folder.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"model": model, "result": result}, indent=1))
    return result


def _config(model: dict):
    """The config of a model record (:func:`kite_env.config.fingerprint`: its keys hold the retired ones at their one
    value, which a config no longer takes)."""
    from kite_env.config import config_from_dict, without_retired

    data: dict = {}
    for key, value in model["keys"].items():
        s, k = key.split(".")
        data.setdefault(s, {})[k] = value
    return config_from_dict(without_retired(data))


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in text).strip("_")


def run_agreement(out: str | Path, surrogate_path: str | None = None, episodes: int = 50, seed: int = 300,
                  duration_s: float = 30.0, flights=FLIGHTS, jobs: int = 1, base=(), log=print) -> dict:
    """Fly :data:`FLIGHTS` and the random-steering episodes in both fidelities; returns the comparison (also written
    to ``out/agreement.json`` and ``out/agreement.md``)."""
    from kite_env.config import fingerprint, load_config

    out = Path(out)
    fast = [*base, "sim.fidelity=surrogate"] + ([f"sim.surrogate_path={surrogate_path}"] if surrogate_path else [])
    model = fingerprint(load_config(None, list(base)))
    pool = ProcessPoolExecutor(jobs) if jobs > 1 else None
    run = (lambda f, items: list(pool.map(f, items))) if pool else (lambda f, items: [f(i) for i in items])
    rows = []
    try:
        fe_flights = {}
        todo = [fl for fl in flights if not (out / "fe" / f"{_slug(fl.name)}.json").is_file()]
        done = dict(zip([fl.name for fl in todo], run(fly_case, [([*base, *fl.overrides()], fl.duration_s)
                                                                  for fl in todo])))
        for fl in flights:
            fe_flights[fl.name] = _cached(out / "fe", _slug(fl.name), model, lambda fl=fl: done[fl.name])
        fast_flights = dict(zip([fl.name for fl in flights],
                                run(fly_case, [([*fast, *fl.overrides()], fl.duration_s) for fl in flights])))
        for fl in flights:
            a, b = fe_flights[fl.name], fast_flights[fl.name]
            d_tr = b["traction_mean_N"] / a["traction_mean_N"] - 1.0
            d_tk = b["tracking_rms_deg"] - a["tracking_rms_deg"]
            ok = (abs(d_tr) <= TRACTION_REL and abs(d_tk) <= TRACKING_DEG and a["figure_eights"] == b["figure_eights"]
                  and a["end"] == b["end"])
            rows.append({"flight": fl.name, "fe": a, "fast": b, "traction_rel": d_tr, "tracking_deg": d_tk, "ok": ok})
            log(f"{fl.name}: traction {a['traction_mean_N']:.0f} / {b['traction_mean_N']:.0f} N ({100 * d_tr:+.1f} %), "
                f"tracking {a['tracking_rms_deg']:.2f} / {b['tracking_rms_deg']:.2f} deg, figure-eights "
                f"{a['figure_eights']} / {b['figure_eights']}, end {a['end']} / {b['end']}")
        seeds = list(range(seed, seed + episodes))
        ep_name = f"random_{episodes}x{duration_s:g}s_seed{seed}"
        fe_eps = _cached(out / "fe", ep_name, model, lambda: run(random_episode, [([*base, *RANDOM_CONDITIONS], s,
                                                                                  duration_s) for s in seeds]))
        fast_eps = run(random_episode, [([*fast, *RANDOM_CONDITIONS], s, duration_s) for s in seeds])
    finally:
        if pool:
            pool.shutdown()
    c_fe, c_fast = Counter(e["end"] for e in fe_eps), Counter(e["end"] for e in fast_eps)
    reasons = sorted(set(c_fe) | set(c_fast))
    ends = [{"end": r, "fe": c_fe.get(r, 0), "fast": c_fast.get(r, 0)} for r in reasons]
    ends_ok = all(abs(e["fe"] - e["fast"]) <= END_REASON_EPISODES for e in ends)
    result = {"model": model, "surrogate_path": surrogate_path, "flights": rows, "random": {
        "episodes": episodes, "seed": seed, "duration_s": duration_s, "ends": ends, "ok": ends_ok,
        "fe": fe_eps, "fast": fast_eps}}
    out.mkdir(parents=True, exist_ok=True)
    (out / "agreement.json").write_text(json.dumps(result, indent=1))
    (out / "agreement.md").write_text(agreement_table(result))
    return result


def agreement_table(result: dict) -> str:
    """The comparison as Markdown (the README's table)."""
    lines = ["| baseline flight | traction full / fast [kN] | difference | tracking full / fast [deg] | difference | "
             "figure-eights full / fast | end full / fast | within 3 %, 1 deg, same count |",
             "|---|---:|---:|---:|---:|---:|---|---|"]
    for r in result["flights"]:
        a, b = r["fe"], r["fast"]
        lines.append(f"| {r['flight']} | {a['traction_mean_N'] / 1e3:.2f} / {b['traction_mean_N'] / 1e3:.2f} | "
                     f"{100 * r['traction_rel']:+.1f} % | {a['tracking_rms_deg']:.2f} / {b['tracking_rms_deg']:.2f} | "
                     f"{r['tracking_deg']:+.2f} | {a['figure_eights']} / {b['figure_eights']} | "
                     f"{a['end']} / {b['end']} "
                     f"| {'yes' if r['ok'] else 'no'} |")
    rnd = result["random"]
    lines += ["", f"| random steering, {rnd['episodes']} episodes of {rnd['duration_s']:g} s (seeds {rnd['seed']}-"
              f"{rnd['seed'] + rnd['episodes'] - 1}): end | full model | fast | within {END_REASON_EPISODES} |",
              "|---|---:|---:|---|"]
    for e in rnd["ends"]:
        lines.append(f"| {e['end']} | {e['fe']} | {e['fast']} | "
                     f"{'yes' if abs(e['fe'] - e['fast']) <= END_REASON_EPISODES else 'no'} |")
    return "\n".join(lines) + "\n"


__all__ = ["END_REASON_EPISODES", "FLIGHTS", "Flight", "RANDOM_CONDITIONS", "TRACKING_DEG", "TRACTION_REL",
           "agreement_table", "fly_case", "random_episode", "run_agreement"]
