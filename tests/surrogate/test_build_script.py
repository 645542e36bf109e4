"""scripts/build_surrogate.py's stage runner: independent stages (sampling runs, fits) at most --jobs at a time."""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import pytest


@pytest.fixture(scope="module")
def build(load_script):
    return load_script("build_surrogate")


def _sleeper(text: str, seconds: float) -> list[str]:
    return [sys.executable, "-c", f"import time; time.sleep({seconds}); print({text!r})"]


def test_stages_run_in_parallel_each_to_its_log(build, tmp_path):
    jobs = [(_sleeper(f"stage {i}", 1.0), tmp_path / f"s{i}.log") for i in range(4)]
    t0 = time.perf_counter()
    wall = build._run_parallel(jobs, 4)
    assert wall < 3.5  # four 1-s stages at once, not one after another
    assert time.perf_counter() - t0 >= 1.0
    assert [(tmp_path / f"s{i}.log").read_text() for i in range(4)] == [f"stage {i}\n" for i in range(4)]


def test_a_failed_stage_is_named_with_its_log_after_the_others_finish(build, tmp_path):
    bad = [sys.executable, "-c", "import sys; print('boom'); sys.exit(3)"]
    jobs = [(bad, tmp_path / "bad.log"), (_sleeper("ok", 0.5), tmp_path / "ok.log")]
    with pytest.raises(SystemExit, match=r"stage failed: .*\(3, log: .*bad\.log\)"):
        build._run_parallel(jobs, 2)
    assert (tmp_path / "ok.log").read_text() == "ok\n" and (tmp_path / "bad.log").read_text() == "boom\n"


def test_jobs_below_one_is_refused(build, capsys):
    with pytest.raises(SystemExit) as e:
        build.main(["--out-dir", "unused", "--jobs", "0"])
    assert e.value.code == 2 and "--jobs must be at least 1" in capsys.readouterr().err


def test_reuse_samples_keeps_a_matching_run_and_refuses_a_different_one(build, tmp_path):
    from kite_env.surrogate.samples import WingSamples

    args = argparse.Namespace(
        policies="baseline,constant:0", winds="4,6.5", every=2, perturb=1, perturb_every=10, duration=6.0,
        set=["env.start_curvature_max=1.0"])
    meta = {"policies": ["baseline", "constant:0"], "winds_mps": [4.0, 6.5], "every": 2, "perturb": 1,
            "perturb_every": 10, "duration_s": 6.0, "seed": 3, "overrides": ["env.start_curvature_max=1.0"]}
    path = tmp_path / "samples_seed3.npz"
    assert not build.reusable(path, args, 3)  # nothing there yet: sample it
    WingSamples(np.zeros((2, 30)), np.zeros((2, 17)), np.zeros(2, int), np.zeros(2, int), meta).save(path)
    assert build.reusable(path, args, 3)
    with pytest.raises(SystemExit, match=r"sampled with seed = 3, this command samples 4"):
        build.reusable(path, args, 4)
    args.winds = "4,7"
    with pytest.raises(SystemExit, match=r"winds_mps = \[4.0, 6.5\], this command samples \[4.0, 7.0\]"):
        build.reusable(path, args, 3)
