"""gcs's MAVSDK link against the mock drone: closing it never strands a call MAVSDK still runs.

MAVSDK's asyncio calls run a blocking call in an executor thread; a timeout ends the await,
not the call. Destroying MAVSDK's objects under such a call left its thread blocked for good,
and ``asyncio.run`` (which joins the executor's threads) never returned: ``gcs fly --check``
hung on a loaded machine after a command had timed out. Here the vehicle stops answering (the
mock stopped with SIGSTOP, as an autopilot that froze or a link that died), a command and a
parameter read time out in gcs's hands while MAVSDK still waits for the answer, the link is
closed, and the process must then exit.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.e2e

# in a process of its own: with the fault, this process never exits (the test's timeout says so)
SCENARIO = """
import asyncio, json, os, signal, sys
from gcs.flight.mavsdk_link import MavsdkLink
from gcs.mock.process import MockProcess

async def main(mock):
    link = MavsdkLink()
    assert await link.connect(mock.url, 10.0)
    await link.set_landed_state_rate(5)  # answered: the vehicle is there
    os.kill(mock.pid, signal.SIGSTOP)  # the vehicle stops answering
    timed_out = []
    for name, call in (("command", lambda: link.set_landed_state_rate(5)),
                       ("parameter", lambda: link.get_param_int("NAV_DLL_ACT"))):
        try:
            async with asyncio.timeout(0.3):
                await call()
        except TimeoutError:
            timed_out.append(name)
    await link.close()
    os.kill(mock.pid, signal.SIGCONT)
    return timed_out

with MockProcess() as mock:
    with open(sys.argv[1], "w") as f:  # for the test to stop it if this process hangs
        f.write(str(mock.pid))
    timed_out = asyncio.run(main(mock))
print(json.dumps({"timed_out": timed_out}))
"""

#: a hang, not a slow exit: MAVSDK ends an unanswered command in about 1.5 s
EXIT_TIMEOUT_S = 120


def test_the_process_exits_after_closing_a_link_with_calls_still_running(tmp_path: Path) -> None:
    pid_file = tmp_path / "mock.pid"
    try:
        done = subprocess.run(
            [sys.executable, "-c", SCENARIO, str(pid_file)],
            capture_output=True, text=True, timeout=EXIT_TIMEOUT_S,
        )  # fmt: skip
    except subprocess.TimeoutExpired:
        # hung: its mock (a session of its own, maybe still stopped) would outlive it
        os.kill(int(pid_file.read_text()), signal.SIGKILL)
        raise
    assert done.returncode == 0, done.stdout + done.stderr
    found = json.loads(done.stdout.strip().splitlines()[-1])
    # both calls were still running in MAVSDK when the link was closed
    assert found["timed_out"] == ["command", "parameter"], done.stdout
