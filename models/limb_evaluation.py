"""Held-out limbs, test postures and the metrics of a limb model (issue 20, part 5).

A *limb model* maps postures ``(N, J, 4)`` (joint orientations, child relative to parent,
scalar-first, in the limb file's joint order) to corrections ``(N, J, 4)``
(``corrected_j = correction_j ⊗ q_j``). :func:`models.evaluation.evaluate_model` scores one
against the exact limb oracle (:class:`models.oracle.ConstraintOracle`) on the postures drawn
here, with the limb metrics of :func:`models.metrics.evaluate`.

Held-out limbs (:func:`random_limb`)
-------------------------------------
Seeded legs (hip → knee → ankle) and arms (shoulder → elbow → wrist): the proximal ball
joint's swing is a concave star-shaped polygon (as :func:`models.evaluation.random_star_polygon`
draws them) with a twist interval, **coupled** to the hinge (knee or elbow) through 3 or 4
keyframes whose boundaries differ in vertex count and grow towards one side as the hinge bends
(the hamstrings' straight-leg limit, the biceps' long head); the hinge has a random interval;
the distal two-axis joint a smaller concave polygon and a narrow twist. No method is tuned on
seeds ≥ :data:`HELD_OUT_LIMB_SEED`. A family of its own (:func:`held_out_forearm_arms`, seeds
from :data:`HELD_OUT_FOREARM_SEED`): arms drawn the same way whose elbow is a **forearm**
joint (the hinge's flexion interval plus pronation–supination, 60-90° each way), the shoulder
coupled to its flexion — the 7-servo arm's chain.

Test postures (:func:`held_out_postures`)
-----------------------------------------
A third uniform (every swing joint's orientation uniform on SO(3), both signs); a third with
some swing joint within ``band_deg`` of its boundary (judged by the limb oracle, so a coupled
joint at its source's corrected angle); a third valid in every joint (where a live limb spends
its time: what a model must leave alone). Hinges: in the first two thirds, the angle uniform
over the interval widened by 40° on each side, half of them exactly on the axis (a servo
limb's hinge), half with up to 5° of out-of-axis rotation (a human joint, an IMU); in the last
third on the axis inside the interval. Forearm joints alike: flexion and rotation each uniform
over its interval widened by 40° (half on the joint's set ``F(θ) ⊗ R(φ)``, half up to 5° off
it), in the last third on the set inside both intervals.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint
from models.limb import LIMB_CHAINS, Limb
from models.limb import Limb as _Limb
from models.limits import ConeSwing
from models.oracle import ConstraintOracle

__all__ = [
    "HELD_OUT_FOREARM_SEED",
    "HELD_OUT_LIMB_SEED",
    "held_out_forearm_arms",
    "held_out_limbs",
    "held_out_postures",
    "random_limb",
    "uncoupled_model",
]

#: First seed of the held-out limbs (no method is tuned on seeds from here on).
HELD_OUT_LIMB_SEED = 9_100

#: First seed of the held-out arms with a forearm elbow (:func:`held_out_forearm_arms`).
HELD_OUT_FOREARM_SEED = 9_200



def _star(centre: np.ndarray, phi: np.ndarray, rho_deg: np.ndarray) -> list[list[float]]:
    e1 = Q.perpendicular(centre)
    e2 = Q.cross(centre, e1)
    rho = np.radians(rho_deg)
    v = (np.cos(rho)[:, None] * centre
         + np.sin(rho)[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2))
    return v.tolist()


def _radius_fn(rng: np.random.Generator, base: float):
    """A random radius function ρ(φ) (degrees): base, 2-3 lobes, 1-2 notches (as
    :func:`models.evaluation.random_star_polygon`)."""
    lobes = [(base * rng.uniform(0.05, 0.25), int(rng.integers(1, 5)), rng.uniform(0, 2 * np.pi))
             for _ in range(int(rng.integers(2, 4)))]
    notches = [(rng.uniform(0, 2 * np.pi), math.radians(rng.uniform(20, 50)),
                base * rng.uniform(0.25, 0.6)) for _ in range(int(rng.integers(1, 3)))]

    def rho(phi: np.ndarray) -> np.ndarray:
        r = np.full(len(phi), base)
        for amp, k, ph in lobes:
            r += amp * np.cos(k * phi + ph)
        for at, width, depth in notches:
            dphi = np.angle(np.exp(1j * (phi - at)))
            r -= depth * np.exp(-0.5 * (dphi / (0.5 * width)) ** 2)
        return r
    return rho


def _azimuths(rng: np.random.Generator, k: int) -> np.ndarray:
    return np.sort((np.arange(k) + rng.uniform(-0.3, 0.3, k)) * 2 * np.pi / k)


def random_limb(seed: int, kind: str = "leg", *, forearm: bool = False) -> Limb:
    """A seeded held-out leg or arm (see the module docstring); ``forearm``: an arm whose elbow
    is a forearm joint — the same draws, then its pronation–supination interval (the elbow's
    flexion interval is the hinge's; the shoulder is coupled to the flexion)."""

    if kind not in LIMB_CHAINS:
        raise ValueError(f"kind: expected 'leg' or 'arm', got {kind!r}")
    rng = np.random.default_rng(seed)
    (j0, s0, s1), (j1, _, s2), (j2, _, s3) = LIMB_CHAINS[kind]
    hinge_lo = float(rng.uniform(-10, 5))
    hinge_hi = float(rng.uniform(120, 150))
    n_kf = int(rng.integers(3, 5))
    at = np.linspace(hinge_lo, hinge_hi, n_kf).round(1)
    centre = Q.random_unit_vectors(1, rng)[0]
    base = rng.uniform(30, 55)
    rho = _radius_fn(rng, base)
    grow_at, grow_width = rng.uniform(0, 2 * np.pi), math.radians(rng.uniform(60, 120))
    grow = rng.uniform(0.25, 0.6) * base  # degrees gained on that side, fully bent
    tw_mid, tw_half = rng.uniform(-60, 60), rng.uniform(25, 70)
    tw_open = rng.uniform(5, 25)
    keyframes = []
    for i, a in enumerate(at):
        s = i / (n_kf - 1)
        phi = _azimuths(rng, int(rng.integers(10, 25)))
        dphi = np.angle(np.exp(1j * (phi - grow_at)))
        r = rho(phi) + s * grow * np.exp(-0.5 * (dphi / (0.5 * grow_width)) ** 2)
        r = np.clip(r, 8, 110)
        keyframes.append({"at_deg": float(a), "constraint": {
            "swing": {"polygon": {"vertices": _star(centre, phi, r),
                                  "interior": centre.tolist()}},
            "twist": {"min_deg": float(max(tw_mid - tw_half - s * tw_open, -180)),
                      "max_deg": float(min(tw_mid + tw_half + s * tw_open, 180))}}})
    hinge_axis = [0.0, 0.0, 1.0]
    dist_centre = Q.random_unit_vectors(1, rng)[0]
    dist_rho = _radius_fn(rng, rng.uniform(18, 35))
    phi = _azimuths(rng, int(rng.integers(8, 16)))
    tw = rng.uniform(2, 12)
    doc = {"name": f"{kind}-{seed}", "limb": kind, "joints": [
        {"name": j0, "parent": s0, "child": s1,
         "coupled": {"by": j1, "keyframes": keyframes}},
        {"name": j1, "parent": s1, "child": s2, "constraint": {
            "kind": "hinge", "hinge": {"axis": hinge_axis, "min_deg": hinge_lo,
                                       "max_deg": hinge_hi}}},
        {"name": j2, "parent": s2, "child": s3, "constraint": {
            "kind": "two-axis",
            "swing": {"polygon": {"vertices": _star(dist_centre, phi,
                                                    np.clip(dist_rho(phi), 6, 60)),
                                  "interior": dist_centre.tolist()}},
            "twist": {"min_deg": float(-tw), "max_deg": float(tw)}}}]}
    if forearm:
        if kind != "arm":
            raise ValueError(f"forearm: an arm's elbow, not a {kind}'s joint")
        pro, sup = rng.uniform(60, 90), rng.uniform(60, 90)  # pronation −φ, supination +φ
        doc["name"] = f"forearm-arm-{seed}"
        doc["joints"][1]["constraint"] = {"kind": "forearm", "forearm": {
            "flexion": {"axis": hinge_axis, "min_deg": hinge_lo, "max_deg": hinge_hi},
            "rotation": {"min_deg": float(-pro), "max_deg": float(sup)}}}
    return _Limb.from_dict(doc, source=f"held-out {kind} {seed}")


def held_out_limbs(n: int = 10, seed: int = HELD_OUT_LIMB_SEED) -> dict[str, Limb]:
    """``n`` held-out limbs, legs and arms alternating: name → Limb."""
    out = {}
    for i in range(n):
        kind = "leg" if i % 2 == 0 else "arm"
        limb = random_limb(seed + i, kind)
        out[limb.name] = limb
    return out


def held_out_forearm_arms(n: int = 3, seed: int = HELD_OUT_FOREARM_SEED) -> dict[str, Limb]:
    """``n`` held-out arms whose elbow is a forearm joint (flexion and pronation–supination,
    the shoulder coupled to the flexion): name → Limb. A family of its own beside
    :func:`held_out_limbs` (whose limbs and seeds are unchanged)."""
    out = {}
    for i in range(n):
        limb = random_limb(seed + i, "arm", forearm=True)
        out[limb.name] = limb
    return out


def held_out_postures(limb: Limb, n: int, rng: np.random.Generator | int, *,
                      band_deg: float = 20.0, oracle: ConstraintOracle | None = None) -> np.ndarray:
    """Test postures ``(n, J, 4)`` (see the module docstring)."""
    rng = np.random.default_rng(rng)
    oracle = oracle or ConstraintOracle(limb)
    jn = len(limb.joints)
    swing = [j for j, jt in enumerate(limb.joints) if jt.joint_kind.swing_twist]
    hinges = [j for j, jt in enumerate(limb.joints) if jt.joint_kind.single_axis]
    forearms = [j for j, jt in enumerate(limb.joints) if jt.joint_kind.flexion_rotation]
    band = math.radians(band_deg)

    def forearm(j: int, m: int, widen: float) -> np.ndarray:
        """Forearm ``j``'s ``F(θ) ⊗ R(φ)``, each angle uniform over its interval widened by
        ``widen`` degrees a side."""
        c = limb.joints[j].constraint
        f = c.limits
        th = rng.uniform(math.radians(f.flexion_min_deg - widen),
                         math.radians(f.flexion_max_deg + widen), m)
        ph = rng.uniform(math.radians(f.rotation_min_deg - widen),
                         math.radians(f.rotation_max_deg + widen), m)
        return Q.multiply(Q.from_axis_angle(np.asarray(f.axis), th),
                          Q.from_axis_angle(np.asarray(c.limb_axis), ph))

    def draw(m: int) -> np.ndarray:
        q = Q.random_quaternions(m * jn, rng).reshape(m, jn, 4)
        for j in hinges:
            joint = limb.joints[j]
            h = joint.loosest().hinge
            ang = rng.uniform(math.radians(h.min_deg - 40), math.radians(h.max_deg + 40), m)
            on = Q.from_axis_angle(np.asarray(h.axis), ang)
            off = Q.from_axis_angle(Q.random_unit_vectors(m, rng),
                                    np.radians(rng.uniform(0, 5, m)))
            bent = np.where((rng.random(m) < 0.5)[:, None], on, Q.multiply(off, on))
            q[:, j] = bent * np.where(rng.random(m) < 0.5, -1.0, 1.0)[:, None]
        for j in forearms:  # as hinges: half on the joint's set, half up to 5° off it
            on = forearm(j, m, 40.0)
            off = Q.from_axis_angle(Q.random_unit_vectors(m, rng),
                                    np.radians(rng.uniform(0, 5, m)))
            bent = np.where((rng.random(m) < 0.5)[:, None], on, Q.multiply(off, on))
            q[:, j] = bent * np.where(rng.random(m) < 0.5, -1.0, 1.0)[:, None]
        return q

    def valid(m: int) -> np.ndarray:
        q = Q.random_quaternions(m * jn, rng).reshape(m, jn, 4)
        for j in hinges:
            h = limb.joints[j].loosest().hinge
            q[:, j] = Q.from_axis_angle(np.asarray(h.axis), np.radians(
                rng.uniform(h.min_deg, h.max_deg, m)))
        for j in forearms:
            q[:, j] = forearm(j, m, 0.0)
        for j in (j for j in limb.order if j in swing):  # sources first
            centre, radius, lo, hi = _proposal(limb.joints[j])
            axis = np.asarray(limb.joints[j].limb_axis)
            todo = np.arange(m)
            for _ in range(1000):
                k = len(todo)
                cos_t = rng.uniform(math.cos(radius), 1.0, k)
                az = rng.uniform(0, 2 * np.pi, k)
                e1 = Q.perpendicular(centre)
                e2 = Q.cross(centre, e1)
                sin_t = np.sqrt(1.0 - cos_t**2)
                d = (cos_t[:, None] * centre + sin_t[:, None] * (
                    np.cos(az)[:, None] * e1 + np.sin(az)[:, None] * e2))
                tw = Q.from_axis_angle(axis, rng.uniform(lo, hi, k))
                cand = q[todo].copy()
                cand[:, j] = Q.multiply(Q.from_two_vectors(np.broadcast_to(axis, d.shape), d),
                                        tw)
                ok = oracle.evaluate(cand).valid[:, j]
                q[todo[ok], j] = cand[ok, j]
                todo = todo[~ok]
                if not len(todo):
                    break
            else:
                raise ValueError(f"{limb.name}: joint {limb.joints[j].name!r}: no valid "
                                 f"posture found")
        if limb.coupled:  # a coupled joint must still be valid at its hinge's angle
            assert oracle.evaluate(q).limb_valid.all()
        return q

    n_uni = n // 3
    n_valid = n // 3
    n_near = n - n_uni - n_valid
    uni = draw(n_uni)
    near: list[np.ndarray] = []
    have = 0
    for _ in range(1000):
        c = draw(max(4 * n_near, 4096))
        d = oracle.evaluate(c).distance[:, swing]
        keep = c[(np.abs(d) <= band).any(axis=1)]
        near.append(keep)
        have += len(keep)
        if have >= n_near:
            break
    q = np.concatenate([uni, np.concatenate(near)[:n_near], valid(n_valid)])
    return q[rng.permutation(len(q))]


def _proposal(joint) -> tuple[np.ndarray, float, float, float]:
    """A cap (centre, radius) holding a swing joint's region at every coupling angle, and the
    hull (radians) of its twist intervals: where :func:`held_out_postures` draws valid
    orientations from."""

    members = [joint.constraint] if joint.coupling is None else list(joint.coupling.keyframes)
    centre = np.zeros(3)
    for c in members:
        centre += c.swing.centre if isinstance(c.swing, ConeSwing) else (
            c.swing.interior if c.swing is not None else c.limb_axis)
    centre /= np.linalg.norm(centre)
    radius = 0.0
    for c in members:
        if c.swing is None:
            radius = math.pi
        elif isinstance(c.swing, ConeSwing):
            radius = max(radius, math.acos(np.clip(centre @ c.swing.centre, -1, 1))
                         + c.swing.radius)
        else:
            radius = max(radius, float(np.arccos(np.clip(c.swing.vertices @ centre, -1,
                                                         1)).max()))
    radius = min(radius + math.radians(2.0), math.pi)
    if members[0].twist is None:
        return centre, radius, -math.pi, math.pi
    return (centre, radius, min(c.twist.min for c in members),
            max(c.twist.max for c in members))


def uncoupled_model(limb: Limb, step_deg: float = 5.0) -> Callable[[np.ndarray], np.ndarray]:
    """The uncoupled approximation as a limb model: every coupled joint at its loosest limits
    (a hinge: the hull of its keyframe intervals; a swing joint: the union of its regions at
    every ``step_deg`` of the source's range, the twist at the hull of its intervals), every
    other joint exact. What ignoring the coupling costs is its score beside the exact model's.
    """

    per_joint: list[list[ConstraintOracle]] = []
    for joint in limb.joints:
        if joint.coupling is None:
            per_joint.append([ConstraintOracle(joint.constraint)])
        elif joint.loosest() is not None:  # a coupled hinge: the hull of its intervals
            per_joint.append([ConstraintOracle(joint.loosest())])
        else:
            cp = joint.coupling
            lo = min(c.twist.min_deg for c in cp.keyframes) if cp.keyframes[0].twist else None
            hi = max(c.twist.max_deg for c in cp.keyframes) if cp.keyframes[0].twist else None
            angles = np.arange(cp.at_deg[0], cp.at_deg[-1] + 1e-9, step_deg)
            members = []
            for a in np.unique(np.concatenate((angles, cp.at_deg))):
                d = cp.at(float(a)).to_dict()
                if lo is not None:
                    d["twist"] = {"min_deg": lo, "max_deg": hi}
                members.append(ConstraintOracle(JointConstraint.from_dict(d)))
            per_joint.append(members)

    def predict(q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=np.float64)
        n, jn = q.shape[:2]
        out = np.empty((n, jn, 4))
        for j, members in enumerate(per_joint):
            qj = q[:, j]
            best_d = np.full(n, np.inf)
            best_c = np.tile(Q.IDENTITY, (n, 1))
            for o in members:
                r = o.evaluate(qj)
                better = r.distance < best_d
                best_d = np.where(better, r.distance, best_d)
                best_c[better] = r.correction[better]
            out[:, j] = best_c
        return out
    return predict
