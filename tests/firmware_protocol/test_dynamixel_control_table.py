"""Control tables loaded from the dynamixel-sdk wheel's ``.model`` files."""

from __future__ import annotations

import pytest

from firmware_protocol.dynamixel import available_models, load_control_table
from firmware_protocol.dynamixel.control_table import model_key, model_numbers


@pytest.mark.parametrize(("name", "number"), [
    ("XL430-W250", 1060), ("XM430-W350", 1020), ("XC330-M288", 1240)])
def test_model_numbers_come_from_the_sdk_list(name, number):
    table = load_control_table(name)
    assert table.model_number == number
    assert load_control_table(number).model == table.model
    assert table.display_name == name
    assert table.source is not None and table.source.name == f"{model_key(name)}.model"
    assert table.default_memory()[0] | table.default_memory()[1] << 8 == number


def test_xm430_layout_matches_the_e_manual():
    t = load_control_table("XM430-W350")
    expect = {"ID": (7, 1), "Baud Rate": (8, 1), "Return Delay Time": (9, 1),
              "Operating Mode": (11, 1), "Max Position Limit": (48, 4),
              "Min Position Limit": (52, 4), "Shutdown": (63, 1), "Torque Enable": (64, 1),
              "Status Return Level": (68, 1), "Hardware Error Status": (70, 1),
              "Profile Acceleration": (108, 4), "Profile Velocity": (112, 4),
              "Goal Position": (116, 4), "Present Position": (132, 4),
              "Present Temperature": (146, 1)}
    for name, (address, size) in expect.items():
        assert (t[name].address, t[name].size) == (address, size), name
    assert t["ID"].eeprom and not t["Torque Enable"].eeprom
    assert not t["Present Position"].writable and t["Goal Position"].writable
    assert t["Present Velocity"].signed and not t["Profile Velocity"].signed
    assert t.size == 662  # ends with Indirect Data 56 at 661
    assert t.item_covering(118) is t["Goal Position"]
    assert t.item_covering(14) is None  # reserved
    assert t.item_at(116) is t["Goal Position"]


def test_model_differences_are_kept():
    xl, xm = load_control_table("XL430-W250"), load_control_table("XM430-W350")
    assert "Current Limit" in xm and "Current Limit" not in xl
    assert "Present Load" in xl and "Present Current" in xm
    assert "PWM Slope" in load_control_table("XC330-M288")


def test_item_codec():
    item = load_control_table("XM430-W350")["Goal Velocity"]
    assert item.encode(-1) == b"\xff\xff\xff\xff"
    assert item.decode(b"\xff\xff\xff\xff") == -1


def test_names_and_errors():
    assert model_key(" XM430-W350 ") == model_key("xm430_w350.model") == "xm430_w350"
    assert "XM430-W350" in available_models()
    assert len(model_numbers()) > 50
    with pytest.raises(ValueError, match="unknown Dynamixel model 'XQ1'"):
        load_control_table("XQ1")
    with pytest.raises(ValueError, match="model number 4242"):
        load_control_table(4242)
