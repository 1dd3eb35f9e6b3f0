"""Limb files and the exact limb oracle (issue 20, parts 2-3): chains of joints, couplings given
at keyframes of a hinge's angle and interpolated between them, and the hierarchical correction
(the source joint corrected first, the dependant judged at the corrected angle)."""

from __future__ import annotations

import math
import os
import stat

import numpy as np
import pytest
import yaml

from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import ConstraintError, QuaternionError
from models.geometry import SphericalPolygon, nearest_on_polygons
from models.limb import dump_limb, load_limb, loads_limb
from models.oracle import ConstraintOracle

Z = np.array([0.0, 0.0, 1.0])


def _ring(centre, radius_deg, n, wobble=0.0, phase=0.0):
    """A star-shaped (concave when wobble > 0) polygon of n vertices about centre."""
    c = np.asarray(centre, dtype=float)
    c /= np.linalg.norm(c)
    e1, e2 = Q.tangent_basis(c)
    out = []
    for k in range(n):
        a = 2 * math.pi * k / n + phase
        r = math.radians(radius_deg) * (1 + wobble * math.cos(3 * a))
        out.append((math.cos(r) * c + math.sin(r) * (math.cos(a) * e1 + math.sin(a) * e2)).tolist())
    return out


def _poly(centre, radius_deg, n, wobble=0.0, twist=None, reverse=False):
    v = _ring(centre, radius_deg, n, wobble)
    body = {"swing": {"polygon": {"vertices": v[::-1] if reverse else v,
                                  "interior": list(centre)}}}
    if twist is not None:
        body["twist"] = {"min_deg": twist[0], "max_deg": twist[1]}
    return body


def _knee(lo=0, hi=135):
    return {"kind": "hinge", "hinge": {"axis": [0, 0, 1], "min_deg": lo, "max_deg": hi}}


def leg_doc(knee=(0, 135), twist=True):
    """A leg: the hip's swing (concave polygons of 7, 12 and 5 vertices, one listed clockwise)
    and twist at knee 0°, 60°, 120°; a hinge knee; a two-axis ankle."""
    tw = [(-30, 40), (-35, 45), (-40, 50)] if twist else [None] * 3
    return {
        "name": "test-leg", "limb": "leg", "side": "right", "patient": "P-001",
        "joints": [
            {"name": "hip", "parent": "pelvis", "child": "thigh", "coupled": {
                "by": "knee", "keyframes": [
                    {"at_deg": 0, "constraint": _poly([1, 0, 0], 40, 7, 0.3, tw[0])},
                    {"at_deg": 60, "constraint": _poly([0.8, 0.6, 0], 55, 12, 0.25, tw[1],
                                                       reverse=True)},
                    {"at_deg": 120, "constraint": _poly([0.6, 0.8, 0], 65, 5, 0.1, tw[2])},
                ]}},
            {"name": "knee", "parent": "thigh", "child": "shank", "constraint": _knee(*knee)},
            {"name": "ankle", "parent": "shank", "child": "foot", "constraint": {
                "kind": "two-axis", "swing": {"cone": {"centre": [0, -1, 0.2],
                                                        "radius_deg": 30}},
                "twist": {"min_deg": -5, "max_deg": 5}}},
        ]}


def _load(doc, source="leg.yaml"):
    return loads_limb(yaml.safe_dump(doc), source=source)


def _postures(n, seed=0, joints=3):
    return Q.random_quaternions(n * joints, np.random.default_rng(seed)).reshape(n, joints, 4)


def _with_knee(q, deg):
    q = q.copy()
    q[:, 1] = Q.from_axis_angle(Z, np.full(len(q), math.radians(deg)))
    return q


# --------------------------------------------------------------------------- the file
def test_a_leg_file_reads_and_writes_back(tmp_path):
    limb = _load(leg_doc())
    assert limb.joint_names == ("hip", "knee", "ankle")
    assert [j.kind for j in limb.joints] == ["ball", "hinge", "two-axis"]
    assert limb.coupled == (0,) and limb.joints[0].coupling.by == "knee"
    assert limb.order == (1, 0, 2)  # the knee is corrected before the hip that depends on it
    path = tmp_path / "leg.yaml"
    dump_limb(limb, path)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    again = load_limb(path)
    assert again.content_hash() == limb.content_hash()
    assert again.to_dict() == limb.to_dict()
    assert "coupled to knee at 0, 60, 120 deg" in limb.summary()


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(jionts=[]), "jionts: unknown key 'jionts' (did you mean 'joints'?)"),
    (lambda d: d["joints"][1].update(chlid="x"),
     "joints[1].chlid: unknown key 'chlid' (did you mean 'child'?)"),
    (lambda d: d["joints"][0]["coupled"]["keyframes"][1].update(at=3),
     "joints[0].coupled.keyframes[1].at: unknown key 'at'"),
    (lambda d: d["joints"][0]["coupled"]["keyframes"][0]["constraint"].update(twsit={}),
     "joints[0].coupled.keyframes[0].constraint.twsit: unknown key 'twsit'"),
    (lambda d: d["joints"][2]["constraint"]["swing"]["cone"].update(radius_deg=-3),
     "joints[2].constraint.swing.cone.radius_deg"),
    (lambda d: d["joints"][2].update(parent="calf"),
     "joints[2].parent: the chain is broken: joint 'ankle' hangs from segment 'calf'"),
    (lambda d: d["joints"][0]["coupled"].update(by="kne"),
     "joints[0].coupled.by: no joint named 'kne' (did you mean 'knee'?)"),
    (lambda d: d["joints"][0]["coupled"].update(by="ankle"),
     "a coupling follows a hinge's angle or a forearm's flexion; 'ankle' is a two-axis joint"),
    (lambda d: d["joints"][0]["coupled"].update(by="hip"),
     "a joint's limits cannot depend on its own angle"),
    (lambda d: d["joints"][0]["coupled"]["keyframes"].__delitem__(slice(1, None)),
     "joints[0].coupled.keyframes: expected a list of at least 2 keyframes"),
    (lambda d: d["joints"][0]["coupled"]["keyframes"][2].update(at_deg=50),
     "joints[0].coupled.keyframes[2].at_deg: keyframes go in increasing angle: 50 after 60"),
    (lambda d: d["joints"][0]["coupled"]["keyframes"][1].update(constraint=_knee()),
     "every keyframe of a coupling is one kind of joint"),
    (lambda d: d["joints"][0]["coupled"]["keyframes"][1]["constraint"].update(
        swing={"cone": {"centre": [1, 0, 0], "radius_deg": 40}}),
     "every keyframe of a coupling has the same swing shape"),
    (lambda d: d["joints"][0]["coupled"]["keyframes"][1]["constraint"].update(
        twist={"min_deg": -9, "max_deg": 9, "by_swing": {"bandwidth_deg": 20, "points": [
            {"direction": [1, 0, 0], "min_deg": -5, "max_deg": 5}]}}),
     "by_swing tables are not interpolated"),
    (lambda d: d["joints"][1]["constraint"].update(side="left"),
     "joints[1].constraint.side: 'side' is given by the limb"),
    (lambda d: d["joints"][1].update(coupled={}), "give either 'constraint'"),
    (lambda d: d["joints"][2].update(name="hip"), "joint name 'hip' used twice"),
    # issue 37: the joints a limb file holds are that limb's, in order, on its segments
    (lambda d: d.update(limb="arm"),
     "joints[0].name: 'hip' is not a joint of the arm (its joints: shoulder, elbow, wrist)"),
    (lambda d: d["joints"][2].update(name="wrist"), "'wrist' is not a joint of the leg"),
    (lambda d: d["joints"][2].update(child="toes"),
     "joints[2]: the leg's ankle joins shank to foot, not shank to toes"),
    (lambda d: [j.update(name=n) for j, n in zip(d["joints"], ("knee", "hip", "ankle"),
                                                             strict=True)],
     "joints[0]: the leg's knee joins thigh to shank, not pelvis to thigh"),
])
def test_a_mistake_in_a_limb_file_is_one_line_naming_the_field(mutate, message):
    doc = leg_doc()
    mutate(doc)
    with pytest.raises(ConstraintError) as err:
        _load(doc)
    text = str(err.value)
    assert message in text and text.startswith("leg.yaml: ") and "\n" not in text


def test_a_cycle_of_couplings_is_refused():
    doc = {"joints": [
        {"name": "a", "parent": "p", "child": "c", "coupled": {"by": "b", "keyframes": [
            {"at_deg": 0, "constraint": _knee(0, 90)}, {"at_deg": 90,
                                                         "constraint": _knee(0, 100)}]}},
        {"name": "b", "parent": "c", "child": "d", "coupled": {"by": "a", "keyframes": [
            {"at_deg": 0, "constraint": _knee(0, 90)}, {"at_deg": 90,
                                                         "constraint": _knee(10, 90)}]}}]}
    with pytest.raises(ConstraintError, match=r"the couplings form a cycle \(a -> b -> a\)"):
        _load(doc)


def _c_shape(open_deg):
    c = np.array([1.0, 0, 0])
    e1, e2 = Q.tangent_basis(c)

    def pt(r, a):
        r, a = math.radians(r), math.radians(a)
        return (math.cos(r) * c + math.sin(r) * (math.cos(a) * e1 + math.sin(a) * e2)).tolist()
    outer = [pt(40, open_deg + 30 + k * 30) for k in range(11)]
    inner = [pt(20, open_deg + 330 - k * 30) for k in range(11)]
    return outer + inner, pt(30, open_deg + 180)


def test_keyframes_whose_interpolation_crosses_itself_are_refused():
    (a, ia), (b, ib) = _c_shape(0), _c_shape(180)
    doc = {"joints": [
        {"name": "hip", "parent": "p", "child": "c", "coupled": {"by": "knee", "keyframes": [
            {"at_deg": 0, "constraint": {"swing": {"polygon": {"vertices": a, "interior": ia}}}},
            {"at_deg": 90, "constraint": {"swing": {"polygon": {"vertices": b,
                                                                "interior": ib}}}}]}},
        {"name": "knee", "parent": "c", "child": "d", "constraint": _knee(0, 90)}]}
    with pytest.raises(ConstraintError, match=r"keyframes 0 and 1: the boundary interpolated "
                                              r"at knee [\d.]+ deg is not a simple polygon"):
        _load(doc)


# --------------------------------------------------------------------------- the oracle
def test_uncoupled_joints_get_the_single_joint_oracles_answers():
    limb = _load(leg_doc())
    q = _postures(3000, seed=1)
    res = ConstraintOracle(limb).evaluate(q)
    for j in (1, 2):
        ref = ConstraintOracle(limb.joints[j].constraint).evaluate(q[:, j])
        assert np.array_equal(res.valid[:, j], ref.valid)
        # the same computation (the limb renormalises its input once more: a last-bit change)
        np.testing.assert_allclose(res.correction[:, j], ref.correction, atol=1e-15)
        np.testing.assert_allclose(res.distance[:, j], ref.distance, atol=1e-15)
    assert np.isnan(res.coupling_angle[:, 1:]).all()


@pytest.mark.parametrize("index", [0, 1, 2])
def test_at_a_keyframe_the_coupled_joint_is_exactly_that_keyframe(index):
    limb = _load(leg_doc())
    hip = limb.joints[0].coupling
    q = _with_knee(_postures(4000, seed=2), hip.at_deg[index])
    res = ConstraintOracle(limb).evaluate(q)
    ref = ConstraintOracle(hip.keyframes[index]).evaluate(q[:, 0])
    assert 0.01 < ref.valid.mean() < 0.99
    assert np.array_equal(res.valid[:, 0], ref.valid)
    np.testing.assert_allclose(res.distance[:, 0], ref.distance, atol=1e-12)
    np.testing.assert_allclose(res.correction[:, 0], ref.correction, atol=1e-12)
    np.testing.assert_allclose(res.coupling_angle[:, 0], math.radians(hip.at_deg[index]),
                               atol=1e-12)


def test_coupled_cones_and_hinges_match_their_keyframes_and_interpolate_linearly():
    doc = {"joints": [
        {"name": "elbow", "parent": "upper-arm", "child": "forearm", "constraint": _knee(0, 145)},
        {"name": "wrist", "parent": "forearm", "child": "hand", "coupled": {
            "by": "elbow", "keyframes": [
                {"at_deg": 0, "constraint": {"kind": "two-axis", "swing": {"cone": {
                    "centre": [1, 0, 0], "radius_deg": 30}}, "twist": {"min_deg": -4,
                                                                       "max_deg": 4}}},
                {"at_deg": 100, "constraint": {"kind": "two-axis", "swing": {"cone": {
                    "centre": [1, 1, 0], "radius_deg": 50}}, "twist": {"min_deg": -8,
                                                                       "max_deg": 12}}}]}},
        {"name": "finger", "parent": "hand", "child": "finger", "coupled": {
            "by": "elbow", "keyframes": [
                {"at_deg": 0, "constraint": _knee(0, 60)},
                {"at_deg": 100, "constraint": _knee(20, 100)}]}}]}
    limb = _load(doc)
    oracle = ConstraintOracle(limb)
    q = _postures(3000, seed=3)
    for at in (0, 100):
        qa = q.copy()
        qa[:, 0] = Q.from_axis_angle(Z, np.full(len(q), math.radians(at)))
        res = oracle.evaluate(qa)
        for j in (1, 2):
            ref = ConstraintOracle(limb.joints[j].coupling.at(at)).evaluate(qa[:, j])
            assert np.array_equal(res.valid[:, j], ref.valid)
            np.testing.assert_allclose(res.correction[:, j], ref.correction, atol=1e-12)
    # half-way: the cone and the intervals are the linear mix (the constraint at() builds)
    qh = q.copy()
    qh[:, 0] = Q.from_axis_angle(Z, np.full(len(q), math.radians(50)))
    mid = limb.joints[1].coupling.at(50)
    assert mid.swing.radius_deg == pytest.approx(40) and mid.twist.min_deg == pytest.approx(-6)
    assert limb.joints[2].coupling.at(50).hinge.min_deg == pytest.approx(10)
    res = oracle.evaluate(qh)
    for j in (1, 2):
        ref = ConstraintOracle(limb.joints[j].coupling.at(50)).evaluate(qh[:, j])
        assert np.array_equal(res.valid[:, j], ref.valid)
        np.testing.assert_allclose(res.correction[:, j], ref.correction, atol=1e-9)


def test_the_interpolated_boundary_is_its_polygons_brute_force_answer():
    """Between keyframes the nearest boundary point is the exact one of the interpolated
    polygon: the kernel equals SphericalPolygon's brute force, and no point of the boundary
    (sampled every 0.01°) is nearer."""
    limb = _load(leg_doc(twist=False))
    lim = limb.joints[0].coupling.limits
    rng = np.random.default_rng(4)
    d = Q.random_unit_vectors(500, rng)
    for k, t in ((0, 0.37), (1, 0.81)):
        v = lim.polygon_at(k, t)
        dist, near = nearest_on_polygons(np.broadcast_to(v, (len(d), *v.shape)), d)
        inner = limb.joints[0].coupling.at(math.degrees(
            (1 - t) * lim.at[k] + t * lim.at[k + 1])).swing.interior
        ref_d, ref_p = SphericalPolygon(v, inner).brute_nearest(d, need_point=True)
        np.testing.assert_array_equal(dist, ref_d)
        np.testing.assert_array_equal(near, ref_p)
        # dense boundary samples are never nearer than the answer
        nxt = np.roll(v, -1, axis=0)
        s = np.linspace(0, 1, 200)[:, None, None]
        dense = (1 - s) * v[None] + s * nxt[None]
        dense = (dense / np.linalg.norm(dense, axis=2, keepdims=True)).reshape(-1, 3)
        best = np.arccos(np.clip(d @ dense.T, -1, 1)).min(axis=1)
        assert (np.abs(dist) <= best + 1e-9).all()
        assert (best - np.abs(dist) < 2e-3).all()  # the samples come close to the answer


def test_the_limits_change_continuously_with_the_coupling_angle():
    """The signed distance of a fixed posture moves by no more than the boundary does (a
    vertex's displacement) as the knee turns in steps of 0.05°, across the keyframes."""
    limb = _load(leg_doc(twist=False))
    oracle = ConstraintOracle(limb)
    lim = limb.joints[0].coupling.limits
    q0 = _postures(200, seed=5)
    angles = np.arange(-10.0, 130.0, 0.05)
    # 100 knee angles to one evaluation (the same distances as one call per angle, bit for
    # bit; a third less time)
    dist = np.concatenate([
        oracle.evaluate(np.concatenate([_with_knee(q0, a) for a in angles[k:k + 100]]))
        .distance[:, 0].reshape(-1, len(q0)) for k in range(0, len(angles), 100)])
    # a vertex moving from a to b (angle θ apart) by normalised linear interpolation moves at
    # most 2 tan(θ/2) per unit of t (its speed at the midpoint); t moves 0.05/60 per step
    theta = max(float(np.max(Q.angle_between(a, b))) for a, b in lim.polygons)
    step = 2.0 * math.tan(theta / 2.0) * 0.05 / 60.0
    jumps = np.abs(np.diff(dist, axis=0))
    assert jumps.max() <= step * 1.001 + 1e-12
    assert jumps.max() > 0.2 * step  # the limits did move


def test_the_source_joint_is_corrected_first_and_the_dependant_judged_at_its_corrected_angle():
    """The knee's range starts at 10°; a knee at −60° is corrected to 10° and the hip judged
    at 10° (part of the way from keyframe 0° to 60°), not at the clamped 0°."""
    limb = _load(leg_doc(knee=(10, 135), twist=False))
    oracle = ConstraintOracle(limb)
    q = _postures(20000, seed=6)
    at10 = oracle.evaluate(_with_knee(q, 10)).valid[:, 0]
    at0 = ConstraintOracle(limb.joints[0].coupling.keyframes[0]).is_valid(q[:, 0])
    differ = at10 != at0
    assert differ.sum() > 50
    bent = _with_knee(q, -60)
    res = oracle.evaluate(bent)
    assert not res.valid[:, 1].any()  # the knee is outside its range
    np.testing.assert_allclose(res.coupling_angle[:, 0], math.radians(10), atol=1e-9)
    assert np.array_equal(res.valid[:, 0], at10)
    # one joint's verdict alone (with its source's correction, not the others') is the same
    for j in range(3):
        np.testing.assert_array_equal(oracle.joint_is_valid(bent, j), res.valid[:, j])
    assert oracle.joint_is_valid(bent[0], 1) == res.valid[0, 1]


def test_the_corrected_limb_is_valid_and_a_valid_limb_is_left_alone():
    limb = _load(leg_doc())
    oracle = ConstraintOracle(limb)
    q = _postures(20000, seed=7)
    res = oracle.evaluate(q)
    fixed = Q.multiply(res.correction.reshape(-1, 4), q.reshape(-1, 4)).reshape(q.shape)
    np.testing.assert_allclose(fixed, res.projected, atol=1e-12)
    again = oracle.evaluate(fixed)
    assert again.valid.all()
    np.testing.assert_allclose(again.correction[..., 0], 1.0, atol=1e-12)
    # a valid limb: identity corrections, distance <= 0
    assert (again.distance <= 1e-9).all()


def test_one_posture_is_a_batch_of_one_and_bad_shapes_are_refused():
    limb = _load(leg_doc())
    oracle = ConstraintOracle(limb)
    q = _postures(5, seed=8)
    batch = oracle.evaluate(q)
    for i in range(5):
        one = oracle.evaluate(q[i])
        assert one.valid.shape == (3,) and one.correction.shape == (3, 4)
        np.testing.assert_array_equal(one.correction, batch.correction[i])
    with pytest.raises(QuaternionError, match=r"expected shape \(N, 3, 4\) or \(3, 4\)"):
        oracle.evaluate(q[:, :2])
    bad = q.copy()
    bad[2, 1, 0] = np.nan
    with pytest.raises(QuaternionError, match="postures"):
        oracle.evaluate(bad)


def test_end_points_with_unit_segments():
    limb = _load(leg_doc())
    oracle = ConstraintOracle(limb)
    straight = np.tile(Q.IDENTITY, (3, 1))
    np.testing.assert_allclose(oracle.end_points(straight), [3, 0, 0], atol=1e-12)
    bent = straight.copy()
    bent[1] = Q.from_axis_angle(Z, math.radians(90))  # knee bent 90° about z
    np.testing.assert_allclose(oracle.end_points(bent), [1, 2, 0], atol=1e-12)
    bent[0] = Q.from_axis_angle(Z, math.radians(90))  # and the hip: everything turns
    np.testing.assert_allclose(oracle.end_points(bent), [-2, 1, 0], atol=1e-12)


def test_a_coupling_at_an_angle_is_a_constraint_of_its_own():
    limb = _load(leg_doc())
    hip = limb.joints[0].coupling
    assert hip.at(60) is hip.keyframes[1]
    assert hip.at(-20) is hip.keyframes[0] and hip.at(170) is hip.keyframes[2]
    mid = hip.at(30)
    assert isinstance(mid, JointConstraint) and mid.twist.max_deg == pytest.approx(42.5)
    # its interior point is inside, and it has the vertices of both keyframes (7 + 12 - shared)
    assert len(mid.swing.vertices) >= 12


# --------------------------------------------------------------------------- the command line
def test_rig_constraint_check_describes_a_limb_file_and_names_a_mistake(tmp_path, rig_cli):
    good = tmp_path / "leg.yaml"
    good.write_text(yaml.safe_dump(leg_doc()))
    code, out, err = rig_cli(["constraint", "check", str(good), "--samples", "20000"])
    assert code == 0, err
    assert "limb 'test-leg' (leg)" in out and "coupled to knee at 0, 60, 120 deg" in out
    assert "knee hinge 0..135 deg" in out
    hip = float(out.split("valid")[1].split("hip ")[1].split("%")[0])
    assert 1.0 < hip < 20.0
    doc = leg_doc()
    doc["joints"][0]["coupled"]["by"] = "kneee"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(doc))
    code, out, err = rig_cli(["constraint", "check", str(bad)])
    assert code == 2 and "Traceback" not in err
    assert err.strip() == (f"rig: error: {bad}: joints[0].coupled.by: no joint named 'kneee' "
                           f"(did you mean 'knee'?) in this limb; joints: hip, knee, ankle")
