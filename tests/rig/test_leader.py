"""The leader arm as a target source (issue 41, ``--targets leader:RIG|PORT``): joints mapped by
name, left ↔ right mirroring, the leader's own calibration, a failed leader read holding the
follower within two cycles (the simulator's fault injection, manual clock), one-line errors
before anything moves, and a short ``rig enforce`` on the simulated leader."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from models.limb import dump_limb
from models.limb_model import export_limb_model
from models.oracle import ConstraintOracle
from rig.demo.stages import shipped_config
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port
from rig.errors import RigConfigError
from rig.loop import EnforcementLoop, Intervention, LoopConfig, SupervisorConfig
from rig.loop.leader import (
    LEADER_COLUMNS,
    LEADER_STALE_PERIODS,
    LeaderTargets,
    leader_mapping,
    mirror_posture,
    open_leader,
)
from rig.loop.runner import prepare_servo_limb
from rig.loop.targets import valid_targets
from rig.loop.telemetry import Telemetry, telemetry_columns
from rig.sim.patients import anatomical_limb
from rig.sim.urls import with_keys
from rig.store import open_store
from tests.rig.rigs import LOADED_HOST_MS

NAMES = ("shoulder", "elbow", "wrist")
MANUAL = {"clock": "manual", "process": "off", "wire_time": "off"}


@pytest.fixture(scope="module")
def arm():
    """The follower's limits: sim-servo-arm's patient (a right arm, forearm elbow)."""
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    return limb, ConstraintOracle(limb)


def _manual_leader_rig(tmp_path, **keys):
    """sim-leader-arm served in this process on a manual clock (fault injection reachable)."""
    cfg = shipped_config("sim-leader-arm")
    cfg["servos"]["port"] = with_keys(cfg["servos"]["port"], **MANUAL, **keys)
    path = tmp_path / "leader.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def _qangle_deg(a, b):
    dot = np.abs(np.einsum("...i,...i->...", a, b))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


# --------------------------------------------------------------------------- mapping
def test_joints_are_mapped_by_name_in_the_followers_order():
    assert leader_mapping(NAMES, ("wrist", "shoulder", "elbow")) == [1, 2, 0]
    assert leader_mapping(("elbow",), NAMES) == [1]
    with pytest.raises(RigConfigError) as err:
        leader_mapping(NAMES, ("shoulder", "elbow"), what="the leader")
    msg = str(err.value)
    assert "\n" not in msg and "has no joint wrist" in msg and "(its joints: shoulder, elbow" \
        in msg


def test_a_mirrored_posture_is_the_other_sides_and_mirroring_twice_is_identity():
    """A right arm's posture and its mirror image hold the same place in the right and the
    left arm's limits (the left limb is the right one reflected), and mapping twice returns
    the posture. (The hinge elbow: ``anatomical_limb``'s left forearm elbow keeps the right
    one's pronation interval instead of negating it, so it is no mirror image.)"""
    right = anatomical_limb(3, "arm")
    left = anatomical_limb(3, "arm", "left")
    o_r, o_l = ConstraintOracle(right), ConstraintOracle(left)
    rng = np.random.default_rng(41)
    q = rng.normal(size=(400, 3, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[:100] = o_r.project(q[:100])  # some inside, the rest anywhere
    m = mirror_posture(q)
    np.testing.assert_array_equal(mirror_posture(m), q)
    d_r, d_l = o_r.signed_distance(q), o_l.signed_distance(m)
    # the same place in the limits: equal up to the swing polygon's own discretisation (the
    # reflected polygon runs the other way round), well under the loop's 1° tolerance
    np.testing.assert_allclose(d_l, d_r, atol=math.radians(0.75))
    clear = (np.abs(d_r) > math.radians(1.0)).all(axis=1)
    np.testing.assert_array_equal(o_l.is_valid(m[clear]), o_r.is_valid(q[clear]))
    assert clear.sum() > 200
    # a rotation about the sagittal normal (+Z: flexion of the elbow) is its own mirror image
    flex = np.array([math.cos(0.4), 0.0, 0.0, math.sin(0.4)])
    np.testing.assert_array_equal(mirror_posture(flex), flex)


# --------------------------------------------------------------------------- the leader's own
def test_the_leaders_own_calibration_gives_the_same_joints_as_the_followers(tmp_path, arm):
    """The same seeded therapist back-driving the XL330 leader (two servos mounted the other way
    round) and a twin of the XM430 follower: other ticks, the same joint orientations."""
    _, oracle = arm
    follower = load_rig_config("sim-servo-arm")
    lrig = _manual_leader_rig(tmp_path)
    twin_url = with_keys(load_rig_config(lrig).servos.port, chain="sim-servo-arm",
                         model="XM430-W350")
    who = {"names": oracle.limb.joint_names, "side": oracle.limb.side, "rig": follower,
           "separate_process": False}
    with open_leader(f"leader:{lrig}", **who) as lead, \
            open_leader(f"leader:{twin_url}", **who) as twin:
        assert lead.description.startswith("leader sim-leader-arm (7 servos")
        assert twin.description.startswith("twin of sim-servo-arm")
        for src in (lead, twin):  # a loaded host's reply may wait for the patient's motion
            src.bus.set_latency(LOADED_HOST_MS)
        worst = 0.0
        diff_ticks = False
        for k in range(1, 6):
            for src in (lead, twin):
                src.port.simulator.clock.advance(0.25)
            ta, qa = lead.latest(k * 0.25)
            tb, qb = twin.latest(k * 0.25)
            assert ta == tb == k * 0.25 and qa.shape == (3, 4)
            worst = max(worst, float(_qangle_deg(qa, qb).max()))
            ticks_a = np.asarray(lead.bus.read_ticks())
            ticks_b = np.asarray(twin.bus.read_ticks())
            diff_ticks |= bool(abs(ticks_a[3] - ticks_b[3]) > 100)
        assert worst < 0.5, worst  # the encoders' quantum, the IK's nearest solution
        assert diff_ticks  # the elbow servo turns the other way on the leader
        assert lead.failures == 0 and lead.reads == 5


# --------------------------------------------------------------------------- the loop
FAULTS = {  # what the leader's simulator does from the cut on (on the wire, rig.sim faults)
    "unplugged": lambda sim: sim.unplug(),  # the bus cable: nobody answers
    "garbage": lambda sim: sim.set_fault_rates(corrupt=1.0),  # every reply's CRC wrong
    "stalled": lambda sim: sim.delay_responses(10.0, 1000),  # replies 10 s late
}


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_a_leader_that_fails_holds_the_follower_within_two_cycles(tmp_path, arm, fault):
    """Cycle 20 the leader stops answering, answers garbage or stalls: that cycle still steers
    to the last posture read (one period old), the next holds in every joint (HOLD_STALE, the
    goal unchanged from then on); every failure is counted."""
    _, oracle = arm
    follower = load_rig_config("sim-servo-arm")
    rate = 200.0
    period = 1.0 / rate
    cut, cycles = 20, 30
    url = "sim://dynamixel?ids=1-7&model=XM430-W350&return_delay_us=0&" \
          "clock=manual&wire_time=off"
    lead = open_leader(f"leader:{_manual_leader_rig(tmp_path)}",
                       names=oracle.limb.joint_names, side=oracle.limb.side, rig=follower,
                       separate_process=False)
    lsim = lead.port.simulator
    lead.bus.set_latency(LOADED_HOST_MS)  # no timeout of a loaded host's before the cut

    def on_cycle(loop, k):
        lsim.clock.advance(period)
        if k == cut:
            FAULTS[fault](lsim)
            lead.bus.set_latency(1.0)  # each failed read costs its packet timeout

    cfg = LoopConfig(rate_hz=rate, watchdog_ms=1000, supervisor=SupervisorConfig(
        stale_target_s=1.5 * period, stale_present_s=1.0))
    with lead, open_port(url, baud=1_000_000) as port:
        clk = port.simulator.clock
        limb = prepare_servo_limb(port, follower.servos, oracle)
        tel = Telemetry(keep=True, columns=telemetry_columns(NAMES) + LEADER_COLUMNS,
                        extra=lead.telemetry_values)
        try:
            loop = EnforcementLoop(limb, None, oracle, lead, cfg, clock=clk, sleep=clk.sleep,
                                   telemetry=tel, on_cycle=on_cycle)
            loop.setup()
            summary = loop.run(max_cycles=cycles)
        finally:
            limb.close()
    t = tel.table()
    stale = [all(int(t[f"{n}_intervention"][k]) & Intervention.HOLD_STALE for n in NAMES)
             for k in range(cycles)]
    assert not any(stale[:cut + 1]), stale
    assert all(stale[cut + 1:]), stale
    cmd = np.stack([np.stack([t[f"{n}_commanded_{c}"] for c in "wxyz"], -1) for n in NAMES], 1)
    np.testing.assert_array_equal(cmd[cut + 1:], np.broadcast_to(cmd[cut], cmd[cut:].shape)[1:])
    assert lead.failures == cycles - cut and lead.reads == cycles
    assert summary["safe_state_entries"] == 0
    # the target's age on the loop clock (the column adds the cycle's own work time)
    age = t["target_age_ms"] - t["cycle_ms"]
    want = 1e3 * period * np.maximum(0, np.arange(cycles) - cut + 1)
    np.testing.assert_allclose(age, want, atol=1e-6)
    assert np.isfinite(t["leader_ms"]).all()
    fig = lead.summary(t, oracle, valid_targets)
    assert fig["reads"] == cycles and fig["failures"] == cycles - cut
    assert fig["latency_ms"]["p50"] is not None


# --------------------------------------------------------------------------- the CLI
@pytest.fixture(scope="module")
def model(tmp_path_factory, arm):
    d = tmp_path_factory.mktemp("leader")
    limb, _ = arm
    dump_limb(limb, d / "arm.yaml")
    export_limb_model(limb, d / "arm.onnx")  # the exact geometric graph: no training
    return d / "arm.onnx"


@pytest.mark.parametrize(("targets", "message"), [
    ("leader:no-such-rig", "--targets leader:no-such-rig: 'no-such-rig': no such shipped rig "
                           "config"),
    ("leader:sim-arm", "rig 'sim-arm' has no servos to read a leader arm from"),
    ("leader:sim-shoulder", "the leader (leader sim-shoulder) has no joints elbow, wrist"),
    ("leader:", "expected leader:RIG"),
    ("SAME-PORT", "the leader's port is the follower's"),
])
def test_a_wrong_leader_is_one_line_before_anything_moves(model, targets, message, rig_cli):
    if targets == "SAME-PORT":
        targets = "leader:" + load_rig_config("sim-servo-arm").servos.port
    code, out, err = rig_cli(["enforce", "--rig", "sim-servo-arm", "--model", model,
                              "--targets", targets, "--duration", "1"])
    assert code == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("rig: error: "), err
    assert message in lines[0], lines[0]
    assert "enforcing" not in out and "backstop" not in out, out


def test_a_leader_unplugged_mid_run_holds_resumes_by_a_ramp_and_the_session_keeps_it_all(
        model, tmp_path, rig_cli):
    """``rig enforce`` follows the simulated leader (summary, telemetry columns); the leader's
    bus cable pulled mid-run by the simulator's own fault injection (``unplug_after=`` /
    ``unplug_for=``, in its own process: ~300 cycles in) during a CLI run into a store: every
    cycle whose target is older than 1.5 periods holds (from the second failed read), the
    follower's commanded posture does not move while held, it resumes under the velocity
    limit, every cycle is stored, and the session's report shows the leader's figures."""
    cfg = shipped_config("sim-leader-arm")
    cfg["servos"]["port"] = with_keys(cfg["servos"]["port"], unplug_after=300, unplug_for=0.5)
    lrig = tmp_path / "leader.yaml"
    lrig.write_text(yaml.safe_dump(cfg, sort_keys=False))
    db, tel, summ = tmp_path / "lead.db", tmp_path / "t.csv", tmp_path / "s.json"
    code, out, err = rig_cli(["enforce", "--rig", "sim-servo-arm", "--model", model,
                              "--targets", f"leader:{lrig}", "--duration", "3.5",
                              "--stale-servo-ms", "1000", "--watchdog-ms", "1000",
                              "--db", db, "--patient", "P-LEAD-01",
                              "--summary-json", summ, "--telemetry", tel])
    assert code == 0, (err, out[-1500:])
    assert f"targets leader {lrig.stem}" in out or "targets leader" in out, out
    s = json.loads(summ.read_text())
    assert s["safe_state_entries"] == 0, s["safe_state_reason"]
    lead = s["leader"]
    assert lead["reads"] == s["cycles"] and lead["failures"] < lead["reads"]
    assert lead["latency_ms"]["p50"] > 0 and not lead["mirrored"]
    header = tel.read_text().splitlines()[0].split(",")
    assert header[-3:] == list(LEADER_COLUMNS) and "wrist_target_w" in header
    rows = np.genfromtxt(tel, delimiter=",", names=True)
    period = 1.0 / s["rate_hz"]
    names = ("shoulder", "elbow", "wrist")
    # the target's age at the cycle's start (the row's age is at its goal's write): 0 when
    # this cycle's read came, the last good read's when it failed
    age = rows["target_age_ms"] - rows["cycle_ms"]
    failed = rows["leader_read"] == 0
    assert (np.abs(age[~failed]) < 1e-3).all()
    assert lead["stale_cycles"] == failed.sum()  # a failed read is not a latency figure
    assert s["leader"]["failures"] >= failed.sum()
    # held: a target older than 1.5 periods at the cycle's start
    stale = failed & (age > 1e3 * LEADER_STALE_PERIODS * period + 1e-3)
    # the cut: the longest run of failed reads (a loaded host may time out a read elsewhere)
    edges = np.flatnonzero(np.diff(np.r_[0, failed.astype(np.int8), 0]))
    first, end = max(zip(edges[::2], edges[1::2], strict=True), key=lambda e: e[1] - e[0])
    span = rows["t_s"][end - 1] - rows["t_s"][first]
    assert 0.4 <= span <= 0.7, span  # the 0.5 s cut, whatever the cycles took
    # held from the cut's second cycle (its third when the loop caught up on a late cycle,
    # two starts within 1.5 periods of the last good read), to its end
    t = rows["t_s"]
    held_from = first + 1 if t[first + 1] - t[first - 1] > LEADER_STALE_PERIODS * period \
        else first + 2
    assert stale[held_from:end].all(), np.flatnonzero(~stale[held_from:end])[:5] + held_from
    for j in names:
        bits = rows[f"{j}_intervention"].astype(np.int64)
        assert (bits[stale] & int(Intervention.HOLD_STALE)).all(), j
        c = np.stack([rows[f"{j}_commanded_{a}"] for a in "wxyz"], axis=1)
        step = np.degrees(2 * np.arccos(np.clip(np.abs(np.sum(c[1:] * c[:-1], axis=1)), 0, 1)))
        # not a tick while held (a tick is 0.088°; the CSV's 9 digits: components to 1e-8)
        moved = np.abs(np.diff(c, axis=0)).max(axis=1)
        held = np.flatnonzero(stale[1:]) + 1
        assert moved[held - 1].max() < 1e-8, (j, held[moved[held - 1] >= 1e-8][:5])
        dt = np.diff(rows["t_s"])  # the cycle's own step time (a late cycle: a longer step)
        vmax = s["joints"][j].get("max_velocity_deg_s", 120.0)
        assert (step <= vmax * np.maximum(dt, period) * 1.05 + 1e-9).all(), j
    assert end < len(rows) - 50  # resumed: the leader read again
    with open_store(db, create=False) as store:
        (sess,) = [x for x in store.sessions.list() if x["kind"] == "enforce"]
        (run,) = store.runs.list(sess["id"])
        assert run["status"] == "completed"
        stored = store.runs.telemetry(run["id"])
        assert len(stored["cycle"]) == s["cycles"] == len(rows)
        np.testing.assert_array_equal(stored["cycle"], rows["cycle"].astype(np.int64))
        assert run["summary"]["leader"]["failures"] == s["leader"]["failures"]
    # the session's report: the leader's figures and each joint's limit activity, in the
    # limb's order
    page = tmp_path / "r.html"
    code, _, err = rig_cli(["report", "--db", db, "--session", sess["id"], "--out", page])
    assert code == 0, err
    text = page.read_text()
    assert "Live enforcement report — shoulder, elbow, wrist (right)" in text
    assert "<h3>Leader arm</h3>" in text and "<h3>Per joint</h3>" in text
    assert f"<th>failed reads (an older target; held from the second in a row)</th><td>" \
           f"{s['leader']['failures']:,}</td>" in text
    assert "leader → follower latency p50 / p99 (ms)" in text


def test_a_leader_source_is_a_target_source():
    from rig.loop.targets import TargetSource

    assert issubclass(LeaderTargets, TargetSource)
