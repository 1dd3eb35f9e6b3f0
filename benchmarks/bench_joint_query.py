"""A limb joint's single-orientation query (the control loop's), per call: a coupled joint's
compiled path against its kind's batched evaluation on a batch of one (what it replaced), the
uncoupled joints' queries and the source's coupling angle.

Two held-out arms (:func:`models.limb_evaluation.random_limb`): the hinge-elbow arm of
``bench_loop_limb.py`` (a polygon shoulder coupled to the elbow's angle) and one with a forearm
elbow (the shoulder coupled to its flexion). Orientations: the limb's held-out postures (a third
uniform, a third near a boundary, a third valid), each joint's coupling angle drawn over its
coupling range; every call a new orientation (the query's memory of its last answers never
hits). Then the coupled query's growth with the polygon: a leg whose hip is coupled to the knee
through three star polygons of 50, 200 and 500 vertices (the corresponding vertices of a
keyframe interval about twice as many: the per-query work is O(vertices)). Medians of single
calls timed one by one; prints the machine's 10⁷-additions loop time beside them.

Run: ``python benchmarks/bench_joint_query.py [--n 2000]``. Figures, never assertions.
"""

from __future__ import annotations

import argparse
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import additions_s

from models import quaternion as Q
from models.limb import Limb
from models.limb_evaluation import held_out_postures, random_limb
from models.oracle import ConstraintOracle


def per_call(fn, args) -> float:
    """Median µs of ``fn(*a)`` over ``args``, each call timed alone."""
    out = np.empty(len(args))
    clock = time.perf_counter
    for i, a in enumerate(args):
        t0 = clock()
        fn(*a)
        out[i] = clock() - t0
    return float(np.median(out)) * 1e6


def star(centre, radius_deg: float, n: int, wobble: float) -> dict:
    """A star polygon's swing of ``n`` vertices about ``centre`` (three lobes) with a twist."""
    c = np.asarray(centre, dtype=float) / np.linalg.norm(centre)
    e1, e2 = Q.tangent_basis(c)
    a = 2 * np.pi * np.arange(n) / n
    r = np.radians(radius_deg) * (1 + wobble * np.cos(3 * a))
    v = (np.cos(r)[:, None] * c
         + np.sin(r)[:, None] * (np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2))
    return {"swing": {"polygon": {"vertices": v.tolist(), "interior": c.tolist()}},
            "twist": {"min_deg": -30, "max_deg": 40}}


def coupled_leg(n: int) -> Limb:
    """A leg whose hip is coupled to the knee through star polygons of about ``n`` vertices."""
    frames = [star([1, 0, 0], 40, n, 0.3), star([0.8, 0.6, 0], 55, n + 7, 0.25),
              star([0.6, 0.8, 0], 65, n - 5, 0.1)]
    return Limb.from_dict({"name": "leg", "limb": "leg", "joints": [
        {"name": "hip", "parent": "pelvis", "child": "thigh", "coupled": {"by": "knee",
         "keyframes": [{"at_deg": a, "constraint": f}
                       for a, f in zip((0, 60, 120), frames, strict=True)]}},
        {"name": "knee", "parent": "thigh", "child": "shank", "constraint": {
            "kind": "hinge", "hinge": {"axis": [0, 0, 1], "min_deg": 0, "max_deg": 135}}}]})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="calls per figure")
    args = ap.parse_args()
    print(f"10^7 additions: {additions_s():.2f} s")
    rng = np.random.default_rng(3)
    for title, limb in (("hinge elbow", random_limb(20261128, "arm")),
                        ("forearm elbow", random_limb(20261128, "arm", forearm=True))):
        oracle = ConstraintOracle(limb).prepare()
        pool = held_out_postures(limb, args.n, rng, oracle=oracle)
        pool = pool[:args.n]
        print(f"{title} arm ({', '.join(f'{j.name} {j.kind}' for j in limb.joints)}):")
        for j in range(oracle.n_joints):
            q = [tuple(map(float, p)) for p in pool[:, j]]
            src = oracle.joint_source(j)
            query = oracle.joint_query(j)
            if src is None:
                print(f"  {limb.joints[j].name}: query {per_call(query, q):.1f} us")
                continue
            lo, hi = oracle.coupling_range(j)
            ang = rng.uniform(lo, hi, len(q))
            calls = [(*qi, float(a)) for qi, a in zip(q, ang, strict=True)]
            m = len(oracle.limb.joints[j].coupling.limits.polygons[0][0]) \
                if oracle.limb.joints[j].coupling.limits.polygons else 0
            fast = per_call(query, calls)
            batched = [(j, np.array([qi]), np.array([a])) for qi, a in
                       zip(q[:200], ang[:200], strict=True)]
            slow = per_call(oracle.evaluate_joint, batched)
            angle = per_call(oracle.coupling_angle_one,
                             [(src, *map(float, p)) for p in pool[:, src]])
            print(f"  {limb.joints[j].name} (coupled, {m} corresponding vertices): query "
                  f"{fast:.1f} us; batched evaluation of one {slow:.0f} us "
                  f"({slow / fast:.0f}x); its source's coupling angle {angle:.1f} us")
    for n in (50, 200, 500):
        oracle = ConstraintOracle(coupled_leg(n)).prepare()
        m = len(oracle.limb.joints[0].coupling.limits.polygons[0][0])
        q = Q.random_quaternions(args.n, rng).tolist()
        ang = rng.uniform(0.0, np.radians(135), args.n).tolist()
        fast = per_call(oracle.joint_query(0), [(*qi, a) for qi, a in zip(q, ang, strict=True)])
        print(f"coupled hip, {n} vertices a keyframe ({m} corresponding): query {fast:.1f} us")


if __name__ == "__main__":
    main()
