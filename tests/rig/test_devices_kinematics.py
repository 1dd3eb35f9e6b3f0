"""Joint kinematics (forward / closed-form inverse of a joint's 1-3 servos) and limb kinematics
(the joints of a limb in order over one tick vector)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as Q
from rig.devices.config import load_rig_config
from rig.devices.kinematics import (
    EXACT_TOLERANCE_DEG,
    NEAREST_TOLERANCE_DEG,
    RAD_PER_TICK,
    JointKinematics,
    LimbKinematics,
    ServoAxis,
    default_tolerance_deg,
)
from rig.errors import RigConfigError, UnreachableError

ZYX = [(0, 0, 1), (0, 1, 0), (1, 0, 0)]


def joint(axes, lo=-8192, hi=8192, **kw):
    return JointKinematics([ServoAxis(i + 1, a, min_ticks=lo, max_ticks=hi)
                            for i, a in enumerate(axes)], **kw)


def angle_deg(p, q):
    return float(np.degrees(Q.angle(Q.multiply(p, Q.conjugate(q)))))


def test_forward_is_the_product_of_axis_angle_rotations():
    kin = joint(ZYX)
    ticks = np.array([2048 + 512, 2048 - 256, 2048 + 1024])  # +45°, -22.5°, +90°
    expected = Q.multiply(Q.multiply(Q.from_axis_angle(np.array([0.0, 0, 1]), math.pi / 4),
                                     Q.from_axis_angle(np.array([0.0, 1, 0]), -math.pi / 8)),
                          Q.from_axis_angle(np.array([1.0, 0, 0]), math.pi / 2))
    assert angle_deg(kin.forward(ticks), expected) < 1e-9
    assert kin.forward([2048, 2048, 2048]) == pytest.approx([1, 0, 0, 0])
    batch = kin.forward_batch(np.array([ticks, [2048, 2048, 2048]]))
    assert np.allclose(batch[0], kin.forward(ticks))


def test_the_compiled_forward_equals_the_batched_one():
    """``forward``/``forward_one`` (compiled, the loop's per-cycle path) and ``forward_batch``
    (numpy) give the same orientations, for integer and float ticks alike."""
    rng = np.random.default_rng(3)
    for axes in ([(0, 0, 1), (0, 1, 0), (1, 0, 0)], [(1, 0, 0), (0, 0.6, 0.8)], [(0, 1, 0)]):
        kin = JointKinematics([ServoAxis(i + 1, a, zero_ticks=2000 + 10 * i, direction=(-1) ** i)
                               for i, a in enumerate(axes)])
        ticks = rng.integers(0, 4096, size=(200, kin.n))
        batch = kin.forward_batch(ticks)
        for t, b in zip(ticks, batch, strict=True):
            np.testing.assert_allclose(kin.forward(t), b, rtol=0, atol=1e-15)
            assert kin.forward_one(t.astype(float)) == tuple(kin.forward(t))


def test_direction_and_zero_offset():
    kin = JointKinematics([ServoAxis(7, (0, 0, 1), zero_ticks=1000, direction=-1,
                                      min_ticks=0, max_ticks=4095)])
    q = kin.forward([1000 + 1024])  # -90° about Z
    assert angle_deg(q, Q.from_axis_angle(np.array([0.0, 0, 1]), -math.pi / 2)) < 1e-9


@pytest.mark.parametrize("axes", [ZYX, [(0, 0, 1), (0.3, 1, 0.2), (1, 0.1, 0)],
                                  [(0, 1, 0), (1, 0, 0), (0, 1, 0)]])
def test_inverse_inverts_forward_and_picks_the_solution_near_the_present(axes):
    kin = joint(axes)
    rng = np.random.default_rng(3)
    for _ in range(300):
        ticks = rng.uniform(0, 4095, 3)
        q = kin.forward(ticks)
        near = ticks + rng.normal(0, 30, 3)
        sol = kin.inverse_float(q, near)
        assert angle_deg(kin.forward(sol), q) < 1e-6
        # no farther from the present position than the solution we started from
        assert np.sum((sol - near) ** 2) <= np.sum((ticks - near) ** 2) + 1e-6
        assert np.abs(kin.inverse_float(q, ticks) - ticks).max() < 1e-6


def test_inverse_branch_follows_near_ticks_by_whole_turns():
    kin = joint(ZYX)
    q = kin.forward([2048, 2048, 2048 + 100])
    assert kin.inverse(q, [2048, 2048, 2048 + 4096])[2] == 2048 + 100 + 4096


def test_gimbal_lock_keeps_the_first_joint_where_it_is():
    kin = joint(ZYX)
    # elevation -90°: limb along +Z, first and third axes aligned
    q = kin.forward([2048 + 300, 2048 - 1024, 2048 + 100])
    sol = kin.inverse_float(q, [2048 + 250, 2048 - 1000, 2048])
    assert angle_deg(kin.forward(sol), q) < 1e-6
    assert sol[0] == pytest.approx(2048 + 250)


def test_out_of_tick_range_is_unreachable_never_clipped():
    kin = joint(ZYX, lo=1024, hi=3072)
    q = kin.forward([2048, 2048, 2048 + 1500])  # axial rotation beyond the +90° stop
    with pytest.raises(UnreachableError, match="ID 3"):
        kin.inverse(q, [2048, 2048, 2048])


def test_a_joint_of_two_servos_reaches_only_its_surface():
    kin = joint([(0, 0, 1), (0, 1, 0)])
    q = kin.forward([2300, 1900])
    assert kin.inverse(q, [2048, 2048]).tolist() == [2300, 1900]
    twisted = Q.multiply(q, Q.from_axis_angle(np.array([1.0, 0, 0]), math.radians(10)))
    with pytest.raises(UnreachableError, match="from the nearest orientation"):
        kin.inverse(twisted, [2048, 2048])


def test_non_unit_target_is_refused():
    with pytest.raises(UnreachableError, match="unit quaternion"):
        joint(ZYX).inverse([0, 0, 0, 0], [2048] * 3)
    with pytest.raises(UnreachableError):
        joint(ZYX).inverse([math.nan, 0, 0, 1], [2048] * 3)


@pytest.mark.parametrize(("servos", "match"), [
    ([ServoAxis(1, (0, 0, 1)), ServoAxis(1, (0, 1, 0))], "duplicate ID 1"),
    ([ServoAxis(1, (0, 0, 1)), ServoAxis(2, (0, 0, 2))], "parallel"),
    ([ServoAxis(1, (0, 0, 0))], "non-zero"),
    ([], "1 to 3"),
    ([ServoAxis(i, (0, 0, 1) if i % 2 else (0, 1, 0)) for i in range(4)], "1 to 3"),
])
def test_bad_joints(servos, match):
    with pytest.raises(RigConfigError, match=match):
        JointKinematics(servos)


# -- limb kinematics --------------------------------------------------------------------------
def _arm() -> LimbKinematics:
    """The servo arm's layout: shoulder 3, elbow 1, forearm 1, wrist 2 servos (IDs 1..7)."""
    def servos(ids, axes):
        return [ServoAxis(i, a, min_ticks=-8192, max_ticks=8192) for i, a in zip(ids, axes,
                                                                                 strict=True)]
    return LimbKinematics([JointKinematics(servos([1, 2, 3], ZYX)),
                           JointKinematics(servos([4], [(0, 0, 1)])),
                           JointKinematics(servos([5], [(1, 0, 0)])),
                           JointKinematics(servos([6, 7], [(0, 0, 1), (0, 1, 0)]))],
                          ["shoulder", "elbow", "forearm", "wrist"])


def test_limb_kinematics_is_each_joints_kinematics_on_its_slice_of_the_tick_vector():
    limb = _arm()
    assert limb.ids == (1, 2, 3, 4, 5, 6, 7) and limb.n == 7 and len(limb) == 4
    assert [(s.start, s.stop) for s in limb.slices] == [(0, 3), (3, 4), (4, 5), (5, 7)]
    rng = np.random.default_rng(0)
    ticks = rng.integers(1024, 3072, size=(50, 7))
    q = limb.forward_batch(ticks)
    assert q.shape == (50, 4, 4)
    for row, qs in zip(ticks, q, strict=True):
        one = limb.forward(row)
        np.testing.assert_array_equal(one, np.stack(
            [j.forward(part) for j, part in zip(limb.joints, limb.split(row), strict=True)]))
        np.testing.assert_allclose(one, qs, atol=1e-12)
    # inverse: each joint's solution nearest its part of the present ticks
    back = limb.inverse(limb.forward(ticks[0]), ticks[0])
    np.testing.assert_array_equal(back, ticks[0])
    assert limb.joint("wrist") is limb.joints[3]


def test_a_one_joint_limb_is_its_joint_bit_for_bit():
    kin = joint(ZYX)
    limb = LimbKinematics([kin], ["shoulder"])
    ticks = np.array([2100, 1990, 2300])
    np.testing.assert_array_equal(limb.forward(ticks)[0], kin.forward(ticks))
    q = kin.forward(ticks)
    np.testing.assert_array_equal(limb.inverse(q[None], ticks), kin.inverse(q, ticks))


def test_limb_limits_are_replaced_per_joint_and_validated():
    limb = _arm()
    lo, hi = limb.min_ticks + 100, limb.max_ticks - 100
    narrower = limb.with_limits(lo, hi)
    np.testing.assert_array_equal(narrower.min_ticks, lo)
    np.testing.assert_array_equal(narrower.joint("elbow").max_ticks, hi[3:4])
    with pytest.raises(ValueError, match="need 7 min and max ticks"):
        limb.with_limits(lo[:3], hi[:3])
    with pytest.raises(RigConfigError, match="zero_ticks outside"):
        limb.with_limits(np.full(7, 2100), np.full(7, 3000))


@pytest.mark.parametrize(("names", "match"), [(["a", "a"], "one distinct name"),
                                               (["a"], "one distinct name")])
def test_bad_limbs(names, match):
    with pytest.raises(RigConfigError, match=match):
        LimbKinematics([joint([(0, 0, 1)]), JointKinematics([ServoAxis(2, (0, 0, 1))])], names)
    with pytest.raises(RigConfigError, match="servo ID 1 in two joints"):
        LimbKinematics([joint([(0, 0, 1)]), joint([(0, 1, 0)])])
    with pytest.raises(RigConfigError, match="at least one joint"):
        LimbKinematics([])


@pytest.mark.parametrize("axes", [[(0, 0, 1), (1, 0, 0)], [(1, 0, 0), (0, 0.6, 0.8)],
                                  [(0, 1, 0)]])
def test_a_joint_of_fewer_servos_goes_to_the_nearest_orientation_it_reaches(axes):
    """With the nearest tolerance, IK of any target gives the orientation its axes reach that is
    nearest the target (no point of a fine grid of the servos' angles is nearer); a target it
    reaches is solved exactly as with the exact tolerance."""
    kin = joint(axes, tolerance_deg=NEAREST_TOLERANCE_DEG)
    exact = joint(axes)
    th = np.linspace(-np.pi, np.pi, 361)
    grids = np.meshgrid(*([th] * kin.n), indexing="ij")
    grid = np.tile([1.0, 0, 0, 0], (grids[0].size, 1))
    for k in range(kin.n):
        grid = Q.multiply(grid, Q.from_axis_angle(kin.axes[k], grids[k].ravel()))
    rng = np.random.default_rng(5)
    qs = rng.standard_normal((60, 4))
    for q in qs / np.linalg.norm(qs, axis=1, keepdims=True):
        reached = kin.forward(kin.inverse_float(q, [2048] * kin.n))
        best = 2 * np.degrees(np.arccos(min(1.0, np.abs(grid @ q).max())))
        assert angle_deg(reached, q) <= best + 1e-6
    for t in rng.integers(1024, 3072, size=(20, kin.n)):
        q = kin.forward(t)
        assert np.array_equal(kin.inverse(q, t + 30), exact.inverse(q, t + 30))


def test_rig_joints_of_fewer_than_three_servos_take_the_nearest_by_default():
    assert default_tolerance_deg(3) == EXACT_TOLERANCE_DEG
    assert default_tolerance_deg(2) == default_tolerance_deg(1) == NEAREST_TOLERANCE_DEG
    arm = load_rig_config("sim-servo-arm").servos
    assert arm.ik_tolerance_deg is None
    assert [j.tolerance_deg for j in arm.limb_kinematics().joints] == [
        EXACT_TOLERANCE_DEG, NEAREST_TOLERANCE_DEG, NEAREST_TOLERANCE_DEG]
    assert load_rig_config("sim-shoulder").servos.kinematics().tolerance_deg == 0.1


def test_less_than_half_a_tick_beyond_a_limit_is_the_limit():
    """An angle a fraction of a tick beyond a tick limit is the tick it rounds to (the limit);
    more than half a tick beyond stays unreachable."""
    kin = joint([(0, 0, 1)], lo=1000, hi=3000)
    for off, ok in ((0.3, True), (0.7, False)):
        q = Q.from_axis_angle(np.array([0.0, 0, 1]), (1000 - off - 2048) * RAD_PER_TICK)
        if ok:
            assert kin.inverse(q, [1100]).tolist() == [1000]
        else:
            with pytest.raises(UnreachableError, match="outside its limits"):
                kin.inverse(q, [1100])
