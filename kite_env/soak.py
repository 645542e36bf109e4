"""Soak: many random-action episodes of an environment, checking that every step is finite and nothing raises.

    kite-bench soak --fidelity surrogate --episodes 10000 --jobs 2 --out runs/soak_fast
    kite-bench soak --fidelity fe --episodes 100 --jobs 2 --out runs/soak_fe
    kite-bench soak --fidelity batched --episodes 10000 --out runs/soak_batched

An episode flies random actions (uniform in [-1, 1], a new one every control step, seeded by the episode) in the
conditions the training recipes draw (:data:`kite_env.fitting.agreement.RANDOM_CONDITIONS`: wind 4-10 m/s,
turbulence up to 0.1, starts on the straight parts at 4.0-4.8 times the wind), episode ``i`` with seed
``seed + i``. Every observation and reward is checked for finite values; an exception (a ``NumericalFailure`` of the
full model included) is caught, counted and its message kept. The table counts the episodes by how they ended.

A long soak of the full model can run in parts (disjoint seeds, several processes or sessions) and be merged into
one table: ``kite-bench soak --merge runs/soak_fe_a runs/soak_fe_b --out runs/soak_fe``.

``batched`` flies the fast fidelity's vector env (:mod:`kite_env.envs.vector`, 64 kites in one compiled batch,
autoreset): the first episode of kite ``i`` starts from ``reset(seed=seed + i)``, later ones from the kite's own
draws, the actions of all kites from one generator seeded ``seed``; episodes are counted as they end, until
``episodes`` have ended. Per kite it is the single fast env, at several times its speed.
"""

from __future__ import annotations

import json
import time
import traceback
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np


def _episodes(args) -> list[dict]:
    fidelity, seeds, duration, overrides = args
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.fitting.agreement import RANDOM_CONDITIONS
    from kite_env.policies import RandomAgent

    env = KiteFigureEightEnv(overrides=[*RANDOM_CONDITIONS, f"env.max_episode_s={duration}", *overrides],
                             fidelity=fidelity)
    rows = []
    for seed in seeds:
        agent = RandomAgent(seed)
        row = {"seed": seed, "steps": 0, "non_finite": 0, "exception": None, "end": None}
        try:
            obs, info = env.reset(seed=seed)
            row["non_finite"] += int(not np.all(np.isfinite(obs)))
            done = False
            while not done:
                a, _ = agent.predict(obs)
                obs, reward, term, trunc, info = env.step(a)
                row["steps"] += 1
                row["non_finite"] += int(not (np.all(np.isfinite(obs)) and np.isfinite(reward)))
                done = term or trunc
            row["end"] = info.get("termination_reason") or "time limit"
        except Exception as exc:  # noqa: BLE001 - the soak counts every exception, whatever its type
            row["exception"] = f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
            row["traceback"] = traceback.format_exc(limit=6)
            row["end"] = "exception"
        rows.append(row)
    env.close()
    return rows


def _batched(episodes: int, seed: int, duration: float, overrides, n_kites: int = 64) -> list[dict]:
    """``episodes`` random-action episodes of the batched fast env (module docstring), one row per episode."""
    import gymnasium as gym

    import kite_env.envs  # noqa: F401  (registers the environments)
    from kite_env.envs import FAST_ENV_ID
    from kite_env.fitting.agreement import RANDOM_CONDITIONS

    ovr = [*RANDOM_CONDITIONS, f"env.max_episode_s={duration}", *overrides]
    rng = np.random.default_rng(seed)
    rows: list[dict] = []
    env = gym.make_vec(FAST_ENV_ID, num_envs=n_kites, vectorization_mode="vector_entry_point", overrides=ovr)
    steps = np.zeros(n_kites, dtype=int)
    bad = np.zeros(n_kites, dtype=int)
    try:
        obs, _ = env.reset(seed=seed)
        bad += ~np.all(np.isfinite(obs), axis=1)
        fresh = np.zeros(n_kites, dtype=bool)  # the kites this step resets (NEXT_STEP autoreset)
        while len(rows) < episodes:
            obs, reward, term, trunc, info = env.step(rng.uniform(-1.0, 1.0, (n_kites, 1)).astype(np.float32))
            bad += ~(np.all(np.isfinite(obs), axis=1) & np.isfinite(reward))
            steps += ~fresh
            for i in np.flatnonzero(term | trunc):
                end = info["termination_reason"][i] if term[i] else "time limit"
                rows.append({"seed": None, "steps": int(steps[i]), "non_finite": int(bad[i]), "exception": None,
                             "end": end or "time limit"})
                steps[i] = bad[i] = 0
            fresh = term | trunc
    except Exception as exc:  # noqa: BLE001 - the soak counts every exception, whatever its type
        rows.append({"seed": None, "steps": 0, "non_finite": 0, "end": "exception",
                     "exception": f"{type(exc).__name__}: {str(exc).splitlines()[0]}",
                     "traceback": traceback.format_exc(limit=6)})
    finally:
        env.close()
    return rows[:episodes] if rows[-1]["end"] != "exception" else rows


def soak(fidelity: str, episodes: int, seed: int = 0, duration_s: float = 30.0, jobs: int = 1, overrides=(),
         chunk: int = 50) -> dict:
    """Fly the episodes (module docstring); returns the counts, the exceptions and the wall time."""
    if fidelity == "batched":
        t0 = time.perf_counter()
        rows = _batched(episodes, seed, duration_s, list(overrides))
        return _summary(fidelity, rows, seed, episodes, duration_s, overrides, time.perf_counter() - t0)
    seeds = list(range(seed, seed + episodes))
    chunks = [(fidelity, seeds[i:i + chunk], duration_s, list(overrides)) for i in range(0, len(seeds), chunk)]
    t0 = time.perf_counter()
    if jobs > 1:
        with ProcessPoolExecutor(jobs) as pool:
            parts = list(pool.map(_episodes, chunks))
    else:
        parts = [_episodes(c) for c in chunks]
    rows = [r for p in parts for r in p]
    return _summary(fidelity, rows, seed, episodes, duration_s, overrides, time.perf_counter() - t0)


def _summary(fidelity, rows, seed, episodes, duration_s, overrides, wall_s) -> dict:
    ends = Counter(r["end"] for r in rows)
    return {"fidelity": fidelity, "episodes": len(rows), "seeds": [seed, seed + episodes - 1],
            "duration_s": duration_s, "steps": int(sum(r["steps"] for r in rows)),
            "non_finite_steps": int(sum(r["non_finite"] for r in rows)),
            "exceptions": [r for r in rows if r["exception"]], "ends": dict(ends),
            "wall_s": wall_s, "overrides": list(overrides)}


def merge(results: list[dict]) -> dict:
    """One result of several soaks of the same fidelity, episode length and overrides over disjoint seeds (a long
    soak of the full model run in parts); the wall time is the parts' sum. Raises ``ValueError`` otherwise."""
    if not results:
        raise ValueError("nothing to merge")
    first = results[0]
    for r in results[1:]:
        for k in ("fidelity", "duration_s", "overrides"):
            if r[k] != first[k]:
                raise ValueError(f"soaks differ in {k}: {first[k]!r} and {r[k]!r}")
    spans = sorted(tuple(r["seeds"]) for r in results)
    for (a0, a1), (b0, b1) in zip(spans, spans[1:]):
        if b0 <= a1:
            raise ValueError(f"seed ranges overlap: {a0}-{a1} and {b0}-{b1}")
    ends: Counter = Counter()
    for r in results:
        ends.update(r["ends"])
    return {"fidelity": first["fidelity"], "episodes": sum(r["episodes"] for r in results),
            "seeds": [spans[0][0], spans[-1][1]], "seed_ranges": [list(s) for s in spans],
            "duration_s": first["duration_s"], "steps": sum(r["steps"] for r in results),
            "non_finite_steps": sum(r["non_finite_steps"] for r in results),
            "exceptions": [e for r in results for e in r["exceptions"]], "ends": dict(ends),
            "wall_s": sum(r["wall_s"] for r in results), "overrides": first["overrides"]}


def soak_table(result: dict) -> str:
    n = result["episodes"]
    s0, s1 = result["seeds"]
    seeds = f", seeds {s0}-{s1}" if result["fidelity"] != "batched" else ""
    title = f"{result['fidelity']}: {n} random-action episodes of up to {result['duration_s']:g} s{seeds}"
    lines = [f"| {title} | episodes |",
             "|---|---:|"]
    for end, k in sorted(result["ends"].items(), key=lambda kv: -kv[1]):
        lines.append(f"| {end} | {k} |")
    lines += [f"| env steps | {result['steps']} |", f"| steps with a non-finite observation or reward | "
              f"{result['non_finite_steps']} |", f"| exceptions | {len(result['exceptions'])} |",
              f"| wall time [s] | {result['wall_s']:.0f} |"]
    return "\n".join(lines) + "\n"


def write(result: dict, out: str | Path) -> Path:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "soak.json").write_text(json.dumps(result, indent=1))
    (out / "soak.md").write_text(soak_table(result))
    return out


__all__ = ["merge", "soak", "soak_table", "write"]
