"""The launcher itself: two vehicles at once on their own instances, parameters at start-up and
over MAVLink, stopped by pid with their lock released."""

from __future__ import annotations

import pytest

from px4.sitl import Ports, Px4Sitl, _px4_lock_held, _udp_free

pytestmark = pytest.mark.px4


@pytest.mark.flight_s(9)
def test_two_vehicles_run_side_by_side_with_their_parameters(px4_factory, px4_figures) -> None:
    """Two vehicles at once (instance numbers probed), a parameter set at start-up and one over
    MAVLink, both stopped by pid with their instance freed."""
    a: Px4Sitl = px4_factory(params={"NAV_DLL_ACT": 0, "MPC_XY_P": 0.9})
    b: Px4Sitl = px4_factory()
    assert a.instance != b.instance and a.alive() and b.alive()
    assert "MPC_XY_P: curr: 0.9500 -> new: 0.9000" in a.output.text()
    px4_figures["ready_after_s"] = [round(a.ready_after_s, 1), round(b.ready_after_s, 1)]
    with b.monitor() as mon:
        mon.set_param("NAV_DLL_ACT", 3)  # PX4 echoes the new value (awaited)
        mon.wait("a heartbeat", lambda s: s.armed is False, 10)
        mon.wait("landed state", lambda s: s.landed_state == 1, 10)  # MAV_LANDED_STATE_ON_GROUND
    for vehicle in (a, b):
        n = vehicle.instance
        assert _px4_lock_held(n)
        assert vehicle.stop() == 0, vehicle.output.text()[-2000:]
        assert not _px4_lock_held(n) and all(_udp_free(p) for p in Ports(n).all())
    assert a.ulogs(), "PX4 wrote no ULog"
