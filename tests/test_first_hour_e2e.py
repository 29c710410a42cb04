"""End to end, a researcher's first hour: a vehicle that is not there.

The wait is said at once, and the final line says what to check. The printed ``Continue with:
...`` line that resumes an interrupted run is run as it stands on the virtual clock
(tests/test_first_hour_virtual.py); that no flight prints MAVSDK's harmless "Unexpected
component ID 0" is checked on the wire by tests/test_fly_e2e.py's Ctrl-C and resume.
"""

from __future__ import annotations

import pytest
from test_fly_adaptive_virtual import SHORT
from test_fly_e2e import finish, gcs, wait_for_line

pytestmark = pytest.mark.e2e


def test_no_vehicle_says_it_waits_at_once_and_what_to_check(tmp_path) -> None:
    import socket

    import yaml
    from synthetic import ci_profile

    data = yaml.safe_load(ci_profile(tmp_path).read_text())
    data["flight"]["connect_timeout_s"] = 1.0
    profile = tmp_path / "quick.yaml"
    profile.write_text(yaml.safe_dump(data))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # a port nobody sends to
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"udpin://127.0.0.1:{port}"
    proc = gcs(
        "fly", "--connect", url, "--iter", 1, "--trajectory", SHORT, "--profile", profile,
        "--run", tmp_path / "run",
    )  # fmt: skip
    seen = wait_for_line(proc, "waiting up to 1 s for a vehicle on")
    code, out = finish(proc)
    out = "".join(seen) + out
    assert code == 2, out
    assert not any("no autopilot" in line for line in seen), out  # said before the wait ends
    (last,) = [ln for ln in out.splitlines() if ln.startswith("error: ")]
    assert f"no autopilot answered on {url} within 1 s" in last, out
    assert f"nothing arrived on UDP port {port}: is PX4 SITL running" in last, out
    assert "no trial was flown; the run is set up in" in out, out
