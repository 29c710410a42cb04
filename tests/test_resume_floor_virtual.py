"""A resumed mock session measures the floor as an uninterrupted run does (virtual clock).

Before each mock session drew a seed of its own, a session resumed with ``--mock`` replayed the
first session's gusts: the repeat of trial 0 matched it to the millimetre and the floor came out
ten times below that of uninterrupted runs (2.4 mm against 20.9 and 20.8 mm). Here the same
set-up is flown uninterrupted with five seeds, and once interrupted in its repeat and resumed
by the command gcs printed; the resumed run's floor must lie among theirs: within half the
smallest and twice the largest. A floor is measured here from one repeat (the profile of
tests/test_fly_adaptive_virtual.py: the resumed seed is tested, in one flight fewer than the
shipped two repeats take), so the gusts of the day move it: five seeds gave 11.5-38.4 mm when
this test was written, and the resumed run 18.3 mm; the replay was a factor of ten below.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import pytest
from test_fly_adaptive_virtual import SHORT, adaptive_ci_profile
from virtual import ctrl_c, on_trial, run_gcs, sim_mock

from gcs.io.rundir import RunDir

# whole flights, on the virtual clock: with the e2e set, out of `make test-fast`
pytestmark = pytest.mark.e2e


def floor_m(run_path: Path) -> float:
    floor = RunDir.open(run_path).read_floor()
    assert floor["trials"] == [0, 1], floor
    return float(floor["epos_m"])


def test_a_resumed_mock_run_measures_the_floor_of_uninterrupted_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sim_mock(monkeypatch)
    profile = adaptive_ci_profile(tmp_path)
    common = ("--trajectory", SHORT, "--profile", profile)
    floors = []
    for seed in range(5):
        run_path = tmp_path / f"whole-{seed}"
        code, out = run_gcs(
            "fly", "--mock", "--seed", seed, "--iter", 2, *common, "--run", run_path
        )
        assert code == 0, out
        floors.append(floor_m(run_path))

    run_path = tmp_path / "resumed"
    with monkeypatch.context() as m:
        on_trial(m, 1, ctrl_c)  # Ctrl-C in the repeat of trial 0
        code, out = run_gcs("fly", "--mock", "--seed", 0, "--iter", 2, *common, "--run", run_path)
    assert code == 130, out
    (line,) = [ln for ln in out.splitlines() if "Continue with: " in ln]
    argv = shlex.split(line.split("Continue with: ", 1)[1])
    assert argv[:2] == ["gcs", "fly"], argv
    code, out = run_gcs(*argv[1:])  # as printed
    assert code == 0, out
    resumed = floor_m(run_path)
    seeds = [s["mock_seed"] for s in RunDir.open(run_path).sessions()]
    assert seeds[0] == 0 and seeds[1] != 0, seeds
    print(f"floors uninterrupted {[round(1e3 * f, 1) for f in floors]} mm, resumed "
          f"{1e3 * resumed:.1f} mm")  # fmt: skip
    assert 0.5 * min(floors) <= resumed <= 2.0 * max(floors), (resumed, floors)
