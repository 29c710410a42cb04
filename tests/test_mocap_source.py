"""The --mocap URL and what the library is given for each system."""

from __future__ import annotations

import pytest

from gcs.errors import ProfileError
from gcs.io.mocap_source import MocapSource, parse_mocap_url


def test_optitrack_url_with_defaults_and_interface() -> None:
    src = parse_mocap_url("optitrack://192.168.1.10/drone?interface=192.168.1.20")
    assert src == MocapSource("optitrack", "192.168.1.10", 1510, "drone", "192.168.1.20")
    assert src.library_config() == {
        "hostname": "192.168.1.10",
        "port_command": "1510",
        "interface_ip": "192.168.1.20",
    }
    assert parse_mocap_url(src.url()) == src


@pytest.mark.parametrize(
    ("url", "config"),
    [
        ("vicon://10.0.0.5/cf1", {"hostname": "10.0.0.5:801"}),
        ("qualisys://qtm.lab:22223/cf1", {"hostname": "qtm.lab", "port": "22223"}),
        ("vrpn://motive.lab/cf1", {"hostname": "motive.lab:3883"}),
    ],
)
def test_other_systems(url: str, config: dict) -> None:
    src = parse_mocap_url(url)
    assert src.library_config() == config
    assert parse_mocap_url(src.url()) == src


@pytest.mark.parametrize(
    ("url", "match"),
    [
        ("natnet://127.0.0.1/drone", "scheme must be one of"),
        ("optitrack://127.0.0.1", "rigid body name is missing"),
        ("optitrack://127.0.0.1:99999/drone", "bad port"),
        ("optitrack://motive.lab/drone", "host must be an IPv4 address"),
        ("optitrack://127.0.0.1/drone?iface=1.2.3.4", "unknown option"),
        ("optitrack://127.0.0.1/drone?interface=eth0", "interface must be an IPv4"),
    ],
)
def test_bad_urls_name_the_problem(url: str, match: str) -> None:
    with pytest.raises(ProfileError, match=match):
        parse_mocap_url(url)


def test_a_multicast_failure_names_the_interface_option() -> None:
    from gcs.flight.mocap.client import connect_hint

    source = parse_mocap_url("optitrack://10.0.0.5/drone")
    hint = connect_hint(source, "optitrack connect failed: set_option: No such device")
    assert "?interface=IP" in hint
    assert "?interface=" in connect_hint(source, "no answer from optitrack server within 5 s")
    with_if = parse_mocap_url("optitrack://10.0.0.5/drone?interface=10.0.0.2")
    assert connect_hint(with_if, "no answer from optitrack server within 5 s") == ""
    assert connect_hint(parse_mocap_url("vicon://10.0.0.5/cf1"), "No such device") == ""
