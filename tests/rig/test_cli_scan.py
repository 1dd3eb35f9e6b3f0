"""``rig scan PORT [--baud B]``: what answers, at which rate; mistakes in one line, exit 2."""

from __future__ import annotations

import pytest


def test_scan_finds_servos_at_their_baud_rate(rig_cli):
    code, out, err = rig_cli(["scan", "sim://dynamixel?ids=1,3&baud=57600&model=XL430-W250",
                              "--ids", "0-3", "--latency-ms", "50", "--protocol", "2"])
    assert code == 0, err
    rows = [line.split() for line in out.splitlines()[1:]]
    assert out.splitlines()[0].split() == ["ID", "model", "firmware", "baud", "protocol",
                                           "homing", "direction"]
    assert rows == [["1", "XL430-W250", "48", "57600", "2.0", "0", "normal"],
                    ["3", "XL430-W250", "48", "57600", "2.0", "0", "normal"]]


def test_scan_finds_both_protocols_on_one_bus(rig_cli):
    code, out, err = rig_cli(["scan", "sim://dynamixel?ids=1:AX-12A,2:MX-28:1,3:XM430-W350:1,"
                              "4:XM430-W350&wire_time=off", "--baud", "1000000", "--ids", "1-4",
                              "--latency-ms", "50"])
    assert code == 0, err
    rows = sorted(line.split() for line in out.splitlines()[1:])
    assert [(r[0], r[1], r[4]) for r in rows] == [
        ("1", "AX-12A", "1.0"), ("2", "MX-28", "1.0"), ("3", "XM430-W350", "1.0"),
        ("4", "XM430-W350", "2.0")]


def test_scan_one_baud(rig_cli):
    code, out, _ = rig_cli(["scan", "sim://dynamixel?ids=2", "--baud", "1000000", "--ids", "1-2"])
    assert code == 0 and out.splitlines()[1].split()[:2] == ["2", "XM430-W350"]


@pytest.mark.parametrize(("args", "match"), [
    (["scan", "/dev/ttyUSB9"], "/dev/ttyUSB9: no such port"),
    (["scan", "/dev/null"], "not a serial port"),
    (["scan", "sim://dynamixel?ids=5&baud=57600", "--baud", "1000000", "--ids", "4-5"],
     "no servo answered"),
    (["scan", "sim://dynamixel", "--baud", "12345"], "--baud 12345"),
    (["scan", "sim://dynamixel", "--ids", "1-x"], "--ids"),
    (["scan", "sim://dynamixel?idz=1"], "unknown key 'idz'"),
])
def test_scan_mistakes_are_one_line(args, match, rig_cli):
    code, _, err = rig_cli(args)
    assert code == 2
    assert err.startswith("rig: error: ") and err.count("\n") == 1 and match in err
