"""Real PX4 firmware (SIH quadrotor on GPS, the default airframe) flown by the real gcs CLI."""

from __future__ import annotations

import re
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.signal
import yaml
from synthetic import SHORT
from test_fly_e2e import wait_for_line

from gcs.app.fly import record_drift
from gcs.core.model import dc_gain
from gcs.core.pbsid import natural_frequency_damping
from gcs.io.config import load_profile
from gcs.io.rundir import RunDir
from px4.flying import IN_AIR, ON_GROUND, finish, first, gcs, report_rows, since, sitl_profile

pytestmark = pytest.mark.px4
EXPERIMENT_S = 30.0  # each identification experiment


def session_figures(run: Path, out: str) -> dict:
    """The figures of a flown session: hover, settle, clock rate per trial, e_pos per trial."""
    rd = RunDir.open(run)
    sessions = rd.sessions()
    hover = sessions[0]["hovers"][0]
    figures = {
        "hover": {k: v for k, v in hover.items() if k != "verdict"},
        "e_pos_m": [round(r["epos_m"], 4) for r in report_rows(run)],
        "clock_rate": [
            round(rd.read_status(j).extra["vehicle_time_rate"], 3) for j in rd.complete_trials()
        ],
    }
    settle = re.search(r"settle tolerances: (.*)", out)
    figures["settle"] = settle.group(1).strip() if settle else None
    return figures


@pytest.mark.flight_s(149)
def test_fly_two_trials_then_ctrl_c_lands_and_resume_completes_on_the_same_vehicle(
    px4_booting, px4_figures, tmp_path: Path
) -> None:
    """The README's `gcs fly --connect ...` with the shipped profile and eight: take-off,
    hover, two trials; e_pos falls from j = 0 to j = 1. Then Ctrl-C (SIGINT) as trial 2 starts:
    gcs lands and disarms and exits 130, trials 0 and 1 stay complete and trial 2 is marked
    interrupted; `gcs fly --resume` then flies trial 2 on the same vehicle, lands and disarms."""
    px4, run = px4_booting, tmp_path / "run"
    with px4.monitor() as mon:
        proc = gcs("fly", "--connect", px4.url, "--iter", 3, "--run", run, "--profile",
                   sitl_profile(tmp_path))  # fmt: skip
        seen = wait_for_line(proc, "trial 2 started")
        mon.wait("in the air", lambda s: s.landed_state == IN_AIR and s.armed, 10)
        proc.send_signal(signal.SIGINT)
        t_int = time.monotonic()
        code, out = finish(proc, seen)
        t_exit = time.monotonic()
        mon.wait("disarmed", lambda s: s.armed is False and s.landed_state == ON_GROUND, 10)
        events = mon.events_since(t_int)
        assert code == 130, out
        for line in ("hover at the start point: ", "trial 0 flown", "trial 1 flown"):
            assert line in out, out
        assert "landed and disarmed" in out, out
        rd = RunDir.open(run)
        assert rd.complete_trials() == [0, 1]
        status = rd.read_status(2)
        assert not status.complete and "interrupt" in status.reason, status
        fault = {
            "gcs_exit_s": since(t_int, t_exit),
            "on_ground_s": first(events, "on ground"),
            "disarmed_s": first(events, "disarmed"),
            "events": events,
        }

        code, resumed = finish(gcs("fly", "--connect", px4.url, "--resume", run, "--iter", 1))
        assert code == 0, resumed
        assert "trial 2 flown" in resumed and "landed and disarmed" in resumed, resumed
        mon.wait("disarmed after the resumed run", lambda s: s.armed is False, 10)
    assert RunDir.open(run).complete_trials() == [0, 1, 2]
    # What a failed test prints for CI, read here from a flight that passed: the console's
    # events and the landing's last seconds in PX4's own log.
    digest = px4.digest()
    assert "Disarmed by external command" in digest, digest
    assert re.search(r"^ +[\d.]+ LAND +True +False ", digest, re.MULTILINE), digest
    figures = session_figures(run, out)
    px4_figures.update(figures, fault=fault)
    e0, e1, _ = figures["e_pos_m"]
    # GPS-aided EKF2 wanders: identical setpoints flown twice differ by 0.36-0.68 m RMS, about
    # 40 % of e_pos,0 here, so one learning step can only be asked to make e_pos fall.
    assert e1 < e0, figures


@pytest.mark.flight_s(184)
def test_identify_with_short_experiments(px4_booting, px4_figures, tmp_path: Path) -> None:
    """`gcs identify` with two 30 s PRBS experiments (60 s shipped): the profile it writes
    loads; per axis the model is stable and a position loop (steady-state gain within a factor
    of 2 of 1), or gcs names the axis. How well each axis explains the validation experiment
    (trial 1) against the profile's model it was identified beside (antx) is simulated here with
    scipy: where the identified one explains it less, gcs says so in a warning naming the axis,
    with the same two VAFs; where it explains it better, no warning. Short experiments on a GPS
    hover that wanders 0.1-0.7 m support no more: in three runs the east axis's VAF was 40-62 %
    and in four the gains 1.1-1.8 (north: VAF 91 %), where the shipped 60 s gave 80-90 %; east
    once came out at 0.01 % (antx's -19 %) and once at 1.37 % (antx's 19.55 %), so the VAFs are
    figures. On a machine at load 14-21 the hover wandered 0.89 m (95 %) and neither model
    explained the validation experiment (VAF x -147 %, antx's -305 %; gains 3.0 and 3.2): an
    axis explained less than by its mean may have any gain, but gcs must name it. Nor does a
    positive VAF pin the gain (east once 2.09 at 57.6 %, antx's 54.9 %, at load 11-20): a gain
    beyond a factor of 2 of 1 is named too.

    Then the README's next step on the same vehicle, not rebooted: one trial of ``gcs fly`` with
    the identified profile. On the identification's disarm PX4 returned to OFFBOARD (the last
    mode it was put in that allows arming), where it cannot arm without a setpoint stream; gcs
    switches it to Hold first (before, it waited out the pre-arm checks: "No offboard
    signal")."""
    profile_path = sitl_profile(tmp_path, identification={"duration_s": EXPERIMENT_S})
    out_path = tmp_path / "identified.yaml"
    px4 = px4_booting
    code, out = finish(
        gcs("identify", "--connect", px4.url, "--profile", profile_path, "--run",
            tmp_path / "ident", "--out", out_path)
    )  # fmt: skip
    assert code == 0, out
    assert "landed and disarmed" in out and f"wrote profile {out_path}" in out, out
    tiny = tmp_path / "tiny.yaml"
    tiny.write_text(yaml.safe_dump(SHORT))
    code, flown = finish(
        gcs("fly", "--connect", px4.url, "--profile", out_path, "--iter", 1, "--run",
            tmp_path / "fly", "--trajectory", tiny)
    )  # fmt: skip
    assert code == 0, flown
    for line in ("switched to Hold", "trial 0 flown", "landed and disarmed"):
        assert line in flown, flown
    profile = load_profile(out_path)
    description = yaml.safe_load(out_path.read_text())["description"]
    vafs = dict(re.findall(r"([xy]): order \d+, delay \d+, VAF ([-\d.]+) %", description))
    models = {}
    for axis, model in zip("xy", profile.models(), strict=True):
        wn, zeta = natural_frequency_damping(model)
        models[axis] = {
            "order": int(model.A.shape[0]),
            "delay_s": round(model.delay_samples * model.dt_s, 3),
            "dc_gain": round(dc_gain(model), 3),
            "wn_rad_s": round(wn, 3),
            "zeta": round(zeta, 3),
            "max_pole_abs": round(float(np.max(np.abs(np.linalg.eigvals(model.A)))), 4),
            "vaf_pct": float(vafs[axis]),
        }
    # the validation trial, as identification measures it (relative to the hover point)
    run = RunDir.open(tmp_path / "ident")
    center = np.asarray(run.manifest["trajectory"]["center_ned_m"], dtype=float)
    validation = run.measured_trial(1)
    prior = load_profile(profile_path).models()
    for c, (axis, model) in enumerate(zip("xy", profile.models(), strict=True)):
        u = validation.sp_ned_m[:, c] - center[c]
        y = validation.pos_ned_m[:, c] - center[c]
        identified, shipped = (free_run_vaf(m, u, y) for m in (model, prior[c]))
        models[axis] |= {"vaf_here_pct": round(identified, 2), "vaf_antx_pct": round(shipped, 2)}
    px4_figures.update({"models": models, "experiment_s": EXPERIMENT_S})
    said = " ".join(out.split())  # the terminal may wrap a long line
    warned = {
        axis: (float(here), float(antx))
        for axis, here, antx in re.findall(
            r"warning: ([xy]): the identified model explains the validation experiment less "
            r"than [\w-]+'s \(VAF ([-\d.]+) % against ([-\d.]+) %\)",
            said,
        )
    }
    unexplained = set(re.findall(
        r"warning: ([xy]): the identified model explains the validation experiment less than "
        r"its mean does", said))  # fmt: skip
    implausible = set(re.findall(r"warning: ([xy]): the identified model's steady-state gain",
                                 said))  # fmt: skip
    for axis, m in models.items():
        assert m["max_pole_abs"] < 1.0, (axis, m)  # stable
        if m["vaf_here_pct"] < 0.0:  # the experiment showed nothing of this axis: gcs says so
            assert axis in unexplained or axis in warned, (axis, m, out)
        elif not 0.5 < m["dc_gain"] < 2.0:  # its slow response unknown: gcs says so
            assert axis in implausible or axis in warned, (axis, m, out)
        else:
            assert axis not in implausible, (axis, m, out)
        weaker = m["vaf_here_pct"] < m["vaf_antx_pct"]
        if abs(m["vaf_here_pct"] - m["vaf_antx_pct"]) > 0.05:  # not a tie within rounding
            assert (axis in warned) == weaker, (axis, m, warned, out)
        if axis in warned:  # gcs's own figures are those computed here
            assert warned[axis] == pytest.approx(
                (m["vaf_here_pct"], m["vaf_antx_pct"]), abs=0.02
            ), (axis, m, warned)


def free_run_vaf(model, u: np.ndarray, y: np.ndarray) -> float:  # type: ignore[no-untyped-def]
    """VAF [%] of ``model`` simulated from rest on the setpoints ``u`` (delayed by its input
    delay) against the positions ``y``, both relative to the hover point (scipy's dlsim)."""
    d = model.delay_samples
    delayed = np.concatenate([np.zeros(d), u[: u.size - d]])
    system = (model.A, model.B, model.C, np.zeros((1, 1)), model.dt_s)
    _, y_hat, _ = scipy.signal.dlsim(system, delayed)
    error = y - y_hat[:, 0]
    return float(100.0 * (1.0 - np.var(error) / np.var(y)))


@pytest.mark.flight_s(126)
def test_until_converged_reaches_a_verdict(px4_booting, px4_figures, tmp_path: Path) -> None:
    """`gcs fly --profile antx-adaptive --until-converged --iter 5` on eight-short: trial 0
    and its two repeats (the profile's default) measure the floor, its scatter between the
    three flights too; learning runs until it says it has converged, has left the floor it
    reached (two learned trials above it), or the bound is reached (and says which), and the
    run ends landed and disarmed in every case."""
    px4, run = px4_booting, tmp_path / "run"
    code, out = finish(
        gcs("fly", "--connect", px4.url, "--profile", sitl_profile(tmp_path, "antx-adaptive"),
            "--trajectory", "eight-short", "--iter", 5, "--until-converged", "--run", run)
    )  # fmt: skip
    assert code == 0, out
    assert "landed and disarmed" in out, out
    rd = RunDir.open(run)
    flown = rd.complete_trials()
    floor = rd.read_floor()  # three flights of trial 0's setpoints: the between-flight scatter
    assert floor["trials"] == [0, 1, 2] and floor["scatter_between_m"] is not None, floor
    assert floor["scatter_m"] == max(floor["scatter_within_m"], floor["scatter_between_m"])
    records = {j: rd.read_learn_record(j) for j in flown if (run / f"learn-{j:03d}.json").exists()}
    converged = [j for j, r in records.items() if r["decision"]["converged"]]
    drift = record_drift(records.get(flown[-1]))
    rows = report_rows(run)
    px4_figures.update(
        {
            "e_pos_m": [round(r["epos_m"], 4) for r in rows],
            "iteration": [r["iteration"] for r in rows],
            "floor_m": rows[0].get("floor_m"),
            "floor_scatter_within_between_m": [
                round(floor["scatter_within_m"], 4),
                round(floor["scatter_between_m"], 4),
            ],
            "trials_flown": flown,
            "verdict": "converged" if converged else "drifted up" if drift else "bound reached",
        }
    )
    if converged:  # landed after the first trial that converged, and said so
        assert flown[-1] == converged[0], (flown, converged)
        assert f"no further trial after trial {converged[0]}: learning has converged" in out
    elif drift is not None:  # landed after two learned trials above the floor, and said so
        assert flown[-1] == drift.above[-1] and len(drift.above) == 2, (flown, drift)
        assert all(t > 2 for t in drift.above), drift  # 1 and 2 repeat trial 0: never "above"
        assert "--until-converged: landed, learning left the floor" in out, out
        assert f"--again {drift.best_trial}" in out, out
    else:
        assert flown == [0, 1, 2, 3, 4], out
        assert "learning has not converged within --iter 5" in out, out
