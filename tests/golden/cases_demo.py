"""Golden cases: the demos' deterministic pieces — the patient, the rig configurations they
write, the comparison of an extracted limb with the truth (``run_demo``/``run_limb_demo`` run
against the host's clock and are not compared; README)."""

from __future__ import annotations

from rig.demo.limb import LIMB_SIZES, compare_limbs, write_limb_rig
from rig.demo.pipeline import SIZES, patient_constraint, write_rig_configs
from rig.sim.patients import anatomical_limb
from tests.golden.cli import root_relative
from tests.golden.harness import case, normalise, tmpdir
from tests.golden.util import jtext


@case("joint")
def case_demo_joint_pieces() -> dict:
    """The joint demo's patient constraint and the three rig files it writes (quick, full)."""
    out: dict = {"patient": patient_constraint().to_yaml(), "sizes": jtext(
        {k: v.__dict__ for k, v in SIZES.items()})}
    with tmpdir() as d:
        pf = d / "patient.yaml"
        pf.write_text(patient_constraint().to_yaml())
        for size in SIZES:
            paths = write_rig_configs(d / size, pf, 3, SIZES[size])
            for name, p in paths.items():
                key = f"{size}_{name}".replace("-", "_")
                out[key] = root_relative(normalise(p.read_text(), [d]))
    return out


@case("limb")
def case_demo_limb_pieces() -> dict:
    """The limb demo's rig files (arm, leg; quick, full) and compare_limbs of one anatomical
    limb against another (hinges, couplings, twist)."""
    out: dict = {"sizes": jtext({k: v.__dict__ for k, v in LIMB_SIZES.items()})}
    with tmpdir() as d:
        for limb in ("arm", "leg"):
            for size, s in LIMB_SIZES.items():
                p = write_limb_rig(d / size, limb, 5, s)
                out[f"{limb}_{size}_rig"] = root_relative(normalise(p.read_text(), [d]))
    for limb, a, b in (("leg", 11, 12), ("arm", 7, 8)):
        out[f"compare_{limb}"] = jtext(compare_limbs(anatomical_limb(a, limb),
                                                     anatomical_limb(b, limb)))
    return out
