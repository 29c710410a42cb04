"""tools/px4_sitl_table.py: the figures of each real-firmware test as docs/px4-sitl.md shows them
(records made up here, in the shapes the tests of tests/px4/ write)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

TOOL = Path(__file__).resolve().parents[1] / "tools" / "px4_sitl_table.py"
_spec = importlib.util.spec_from_file_location("px4_sitl_table", TOOL)
table = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(table)


def test_a_lab_flight_shows_its_pre_arm_wait_and_gcs_hover_line() -> None:
    text = table.figures_text(
        "test_lab",
        {
            "e_pos_m": [0.5, 0.25],
            "prearm_wait": "vehicle ready to arm (after 5.0 s)",
            "hover": "hover at the start point: 0.24 m off on average (95 % within 0.26 m, "
            "at most 0.26 m), 1.7 cm fast noise, speed 0.11 m/s median",
        },
    )
    assert text == (
        "e_pos per trial j = 0: 0.500, j = 1: 0.250 m (last 50 % of the first); "
        "pre-arm: vehicle ready to arm (after 5.0 s); "
        "hover 0.24 m off on average (95 % within 0.26 m, at most 0.26 m)"
    )


def test_mocap_lost_and_a_refusal_show_their_times_and_the_message_without_the_path() -> None:
    lost = table.figures_text(
        "t",
        {"gcs_stopped_after_s": 1.25, "landed_after_s": 9.0, "disarmed_after_s": 10.5,
         "reason": "mocap stream stale"},
    )  # fmt: skip
    assert lost == (
        "after the mocap stopped: gcs stopped 1.2 s, landed 9.0 s, disarmed 10.5 s; "
        "gcs: mocap stream stale"
    )
    refused = table.figures_text(
        "t",
        {"exit_code": 2, "refused": "error: /tmp/x y/p.yaml: field 'mocap.right_handed'",
         "armed": False},
    )  # fmt: skip
    assert refused == "exit 2: field 'mocap.right_handed'; armed: False"


def test_a_gps_hover_record_and_a_table_cell_pipe() -> None:
    text = table.figures_text(
        "t", {"hover": {"stats": {"offset_m": 0.3, "distance_p95_m": 0.6}}, "settle": "a|b"}
    )
    assert text == "hover 0.30 m off (95 % within 0.60 m); settle a\\|b"


def test_the_frame_check_line_shows_without_its_prefix() -> None:
    text = table.figures_text(
        "t", {"check": "mocap check: 1.00 m moves; wander 0.2 m", "reason": "r"}
    )
    assert text == "frame check 1.00 m moves; wander 0.2 m; gcs: r"


def test_a_pause_shows_its_length_the_late_setpoint_and_the_modes_after_it() -> None:
    events = [[16.4, "mode AUTO.LAND"], [16.7, "landing"], [23.4, "disarmed"]]
    text = table.figures_text("t", {"pause": {"pause_s": 0.6, "late_ms": 567, "events": events}})
    assert text == "paused 0.6 s: the next setpoint 567 ms late; PX4's modes after it: AUTO.LAND"
