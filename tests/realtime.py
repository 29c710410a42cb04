"""What the tests expect of gcs.io.scheduling on this machine: whether a thread may run under a
real-time policy here (root, CAP_SYS_NICE or an RLIMIT_RTPRIO), and the policy a raised
thread then has."""

from __future__ import annotations

import os
import threading

from gcs.io.scheduling import FLIGHT_PRIORITY


def _allowed() -> bool:
    result: list[bool] = []

    def attempt() -> None:  # in a thread of its own: the caller's policy stays
        try:
            os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(1))
        except PermissionError:
            result.append(False)
        else:
            result.append(True)

    thread = threading.Thread(target=attempt)
    thread.start()
    thread.join()
    return result[0]


ALLOWED = _allowed()
#: policy and priority of a thread after raise_thread() on this machine
RAISED = (os.SCHED_RR, FLIGHT_PRIORITY) if ALLOWED else (os.SCHED_OTHER, 0)
