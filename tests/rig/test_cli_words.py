"""Words the CLI and the readers print (issue 37, item 11): a whole-limb session named by its
limb, an infinite ``--duration`` refused as such, a drift warning that fits any limb."""

from __future__ import annotations

import pytest

from rig.cli import main
from rig.commands.session import format_sessions
from rig.readback.data import RecordingFacts


def _row(**kw):
    row = {"id": 1, "pseudonym": "SIM-LEG-0000", "kind": "record", "side": "right",
           "joint": "hip", "meta": {"limb": "leg"}, "started_at": 1.7e9, "recording_s": 180.8,
           "samples_by_sensor": {"pelvis": 10}, "samples": 10, "runs": 0,
           "last_sample_at": 1.7e9 + 180.8, "dropped": 0, "status": "completed",
           "liveness": {"state": "ended"}}
    return {**row, **kw}


def test_session_list_names_a_whole_limb_session_by_its_limb():
    """A leg session was listed as "right hip" (its first joint)."""
    text = format_sessions([_row(), _row(id=2, joint="shoulder", meta={})])
    leg, shoulder = text.splitlines()[1:]
    assert "right leg" in leg and "hip" not in leg.split("SIM-LEG-0000")[1].split("  2")[0]
    assert "right shoulder" in shoulder


@pytest.mark.parametrize("command", [
    ["record", "--rig", "sim-imu", "--patient", "P-1", "--db", "{db}"],
    ["enforce", "--rig", "sim-shoulder", "--model", "{db}", "--targets", "script:slow"],
])
@pytest.mark.parametrize("value", ["inf", "nan"])
def test_an_infinite_duration_is_refused_as_such(command, value, tmp_path, capsys):
    """``--duration inf`` said "must be > 0" (record) or "expected a positive number"
    (enforce); it is positive, just not finite."""
    args = [a.format(db=tmp_path / "x.db") for a in command] + ["--duration", value]
    with pytest.raises(SystemExit) as info:
        main(args)
    err = capsys.readouterr().err
    assert info.value.code == 2 and err.count("\n") == 1
    assert "must be a finite number of seconds" in err and "> 0" not in err
    assert not (tmp_path / "x.db").exists()  # refused before anything is opened


def test_the_drift_warning_fits_any_limb():
    """The warning of a leg session spoke of "the arm raised"."""
    (w,) = RecordingFacts(unmeasured_drift=True).warnings()
    assert "arm" not in w and "away from the neutral pose" in w
