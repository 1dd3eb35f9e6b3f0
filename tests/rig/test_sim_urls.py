"""``sim://`` port strings: the one table of simulators, the one query parser, the URL editor."""

from __future__ import annotations

import urllib.parse

import pytest

from rig.errors import RigConfigError
from rig.sim.urls import SIM_DEVICES, SimUrl, query_keys, sim_device_of, with_keys


def test_every_host_names_one_simulator():
    assert {h: d.name for h, d in SIM_DEVICES.items()} == {
        "dynamixel": "dynamixel", "dxl": "dynamixel", "bno055": "bno055",
        "imu-stream": "imu-stream", "stream": "imu-stream"}
    assert sim_device_of("sim://stream?sensors=2").kind == "sim-imu-stream"
    assert sim_device_of("sim://dxl").kind == "sim-dynamixel"
    for url in ("sim://toaster", "tcp://dynamixel", "/dev/ttyUSB0"):
        with pytest.raises(RigConfigError, match="names no simulator") as err:
            sim_device_of(url)
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("query", [
    "a=1&b=x%2Fy&c=&d", "a=1+2&b=%41", "&&a=1&&", "a==1&b=c=d", "", "p=/tmp/a%20b.yaml",
])
def test_query_decoding_is_parse_qsl_with_blank_values(query):
    pairs = urllib.parse.parse_qsl(query, keep_blank_values=True)
    keys = {k for k, _ in pairs}
    q = SimUrl(f"sim://bno055?{query}", ("bno055",), keys, "sim://bno055")
    for k, v in pairs:
        assert q.text(k) == v
    assert query_keys(f"sim://bno055?{query}") == keys


def test_an_empty_key_is_an_unknown_key():
    with pytest.raises(RigConfigError, match="unknown key ''"):
        SimUrl("sim://bno055?=x", ("bno055",), ("rate",), "sim://bno055")


def test_unknown_and_repeated_keys_are_named():
    with pytest.raises(RigConfigError, match=r"^sim://bno055\?rate=1&colour=red: unknown key "
                                             r"'colour'; known keys: .*rate"):
        SimUrl("sim://bno055?rate=1&colour=red", ("bno055",), ("rate",), "sim://bno055")
    with pytest.raises(RigConfigError, match="key 'rate' given twice"):
        SimUrl("sim://bno055?rate=1&rate=2", ("bno055",), ("rate",), "sim://bno055")


def test_with_keys_replaces_in_place_and_appends():
    url = "sim://imu-stream?sensors=2&rate=200&patient=original&seed=1&flow=on"
    got = with_keys(url, patient="/tmp/demo dir/p.yaml", seed=7, time_scale="20")
    assert got == ("sim://imu-stream?sensors=2&rate=200&patient=/tmp/demo%20dir/p.yaml&seed=7"
                   "&flow=on&time_scale=20")
    q = SimUrl(got, ("imu-stream",), ("sensors", "rate", "patient", "seed", "flow"), url)
    assert q.text("patient") == "/tmp/demo dir/p.yaml" and q.integer("seed", 0) == 7
    assert with_keys("sim://dynamixel", ids="1,2") == "sim://dynamixel?ids=1%2C2"
    assert with_keys("sim://dynamixel?ids=1,2,3&&", seed=2) == "sim://dynamixel?ids=1,2,3&seed=2"
    assert with_keys(url) == url
