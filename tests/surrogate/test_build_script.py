"""scripts/build_surrogate.py's stage runner: independent stages (sampling runs, fits) at most --jobs at a time."""

from __future__ import annotations

import sys
import time

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
