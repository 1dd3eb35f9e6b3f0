"""Model binding: which constraint the loop enforces, and whether the model was made for it.

The ONNX file's metadata (:mod:`models.onnx_io`) embeds the constraint it was trained on
(``jointlimits.constraint``, YAML); that constraint may name its ``joint``, ``side`` and
``patient`` (:class:`models.constraint.JointConstraint`). The **enforced** constraint — the one
the safety supervisor checks every goal against — is, in order of authority:

1. ``--constraint FILE`` (explicit);
2. the boundary stored for ``--session`` in the store (the patient's recorded range);
3. the rig configuration's ``constraint``;
4. the model's own embedded constraint.

The enforced constraint is **always refused** when it is for another joint or side than the
rig's, or its kind cannot be that joint's (:func:`calibration.joints.joint_mismatch`: a knee's
hinge on a shoulder rig): ``--force-model`` overrides the model, never the joint a rig drives.

The model is **refused** (:class:`ModelBindingError`, one line, exit 2) when its embedded
constraint differs from the enforced one (limits compared, names ignored), or names a joint or
side other than the rig configuration's, or a patient other than the session's — unless
``force`` (``--force-model``) is given, in which case the mismatch is reported as a warning and
the supervisor still enforces the enforced constraint (the model only shapes the goals inside
it; it never widens what is allowed).

**A servo limb** (a rig whose ``servos.joints`` drive a whole limb): the enforced limits are a
limb file (:class:`models.limb.Limb`; the session's stored limb boundary, a ``--constraint``
limb file, the model's embedded limb) and the model a limb model. Always refused, whatever
``force``: a one-joint constraint or model on a limb rig or a limb file or model on a one-joint
rig; a limb file or model of another limb (a leg's on an arm rig), another side, or whose
joints are not the rig's servo joints in the same order; a limb joint whose kind is not the one
the rig's servos drive (a forearm elbow's limits on a hinge elbow's one servo, a ball's on two
servos) — except a hinge's limits on a forearm joint's two servos whose flexion servo turns
about the hinge's axis (:func:`hinge_on_forearm`: a hinge is a forearm whose rotation interval is
[0, 0], so the servos reach every allowed posture and the hinge's oracle holds the rotation servo
at its zero; an elbow recorded as a hinge by IMUs enforced on a servo arm's forearm elbow). The
limits (content hash: names, side, patient left out), side and patient as above (forceable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calibration.joints import joint_mismatch
from models.constraint import loads_constraint
from models.errors import ModelsError
from models.kinds import get_kind
from models.limb import Limb, loads_limb
from rig.errors import RigConfigError

__all__ = ["HINGE_AXIS_DEG", "Binding", "ModelBindingError", "bind_model", "hinge_on_forearm"]

#: A hinge's limits are enforced on a forearm joint's servos when its axis is the flexion
#: servo's within this angle (degrees; the kinematics' IK tolerance).
HINGE_AXIS_DEG = 0.1


class ModelBindingError(RigConfigError):
    """The model does not belong to this rig / session / constraint."""


@dataclass
class Binding:
    """Result of :func:`bind_model`.

    Attributes
    ----------
    constraint : models.constraint.JointConstraint or models.limb.Limb
        The constraint (a servo limb's: limb file) enforced by the supervisor.
    source : str
        Where it came from (``"--constraint FILE"``, ``"session N"``, ``"rig NAME"``,
        ``"model"``).
    model_constraint : JointConstraint, Limb or None
        The model's embedded constraint (a limb model's: its limb file).
    mismatches : list of str
        What did not match (empty when bound cleanly; non-empty only with ``force``).
    """

    constraint: object
    source: str
    model_constraint: object = None
    mismatches: list[str] = field(default_factory=list)


def _who(c, patient: str | None = None) -> str:
    """A constraint as a person reads it: its name and, when known, its patient."""
    p = c.patient or patient
    return f"{c.name!r}" + (f" of patient {p!r}" if p else "")


def bind_model(model, *, rig=None, constraint=None, constraint_source: str = "--constraint",
               session_constraint=None, session_id=None, session_patient: str | None = None,
               force: bool = False) -> Binding:
    """Choose the enforced constraint and check the model against it.

    Parameters
    ----------
    model : models.onnx_io.CorrectionModel
    rig : rig.devices.config.RigConfig, optional
    constraint : JointConstraint or Limb, optional
        Explicit constraint or limb file (``--constraint``).
    session_constraint : JointConstraint or Limb, optional
        The session's stored boundary (a limb rig's: its stored limb file).
    session_patient : str, optional
        Pseudonym of the session's patient.
    force : bool
        Accept a mismatching model (mismatches returned, not raised).

    Raises
    ------
    ModelBindingError
        On the first mismatch, unless ``force``.
    """
    path = getattr(model, "path", "model")
    text = getattr(model, "constraint_yaml", "") or ""
    model_is_limb = bool(getattr(model, "joints", ()))
    try:
        embedded = None
        if model_is_limb:
            embedded = getattr(model, "limb", None) or loads_limb(
                text, source=f"{path} (embedded limb)")
        elif text:
            embedded = loads_constraint(text, source=f"{path} (embedded constraint)")
    except ModelsError as err:
        raise ModelBindingError(f"{path}: its embedded constraint does not load ({err})") \
            from None
    if constraint is not None:
        enforced, source = constraint, constraint_source
    elif session_constraint is not None:
        enforced, source = session_constraint, f"session {session_id}"
    elif rig is not None and rig.constraint is not None:
        enforced, source = rig.load_constraint(), f"rig {rig.name!r} constraint {rig.constraint}"
    elif embedded is not None:
        enforced, source = embedded, "the model's embedded constraint"
    else:
        raise ModelBindingError(f"{path}: the model embeds no constraint and none was given "
                                "(--constraint FILE)")
    # what the rig drives is not the model's to override: --force-model never reaches here
    why = _rig_mismatch(enforced, rig)
    if why is not None:
        what = "joints" if _servo_joints(rig) else "joint"
        raise ModelBindingError(f"{source}: {why} (--force-model overrides the model, never "
                                f"the {what} the rig drives)")
    if embedded is not None and (_limb_of(embedded) is None) != (_limb_of(enforced) is None):
        raise ModelBindingError(_model_shape_mismatch(path, embedded, rig))
    if _limb_of(enforced) is not None:
        problems = _limb_model_problems(path, embedded, enforced, source, rig, session_id,
                                        session_patient)
    else:
        problems = _joint_model_problems(path, embedded, enforced, source, rig, session_id,
                                         session_patient)
    if problems and not force:
        raise ModelBindingError(f"{problems[0]}; use --force-model to run it anyway (the "
                                "supervisor still enforces the constraint)")
    return Binding(constraint=enforced, source=source, model_constraint=embedded,
                   mismatches=problems)


def _limb_of(c) -> Limb | None:
    """The limb file ``c`` is, None for one joint's constraint: the one place binding asks."""
    return c if isinstance(c, Limb) else None


def _servo_joints(rig) -> tuple:
    """A servo limb rig's joints (``servos.joints``); empty for a rig of one joint."""
    servos = getattr(rig, "servos", None)
    return tuple(getattr(servos, "joints", ()) or ())


def _drives(rig) -> str:
    """What the rig drives, as a sentence's end."""
    joints = _servo_joints(rig)
    j = rig.joint
    if joints:
        return (f"rig {rig.name!r} drives the {j.side} {rig.limb or 'limb'}'s "
                f"{len(joints)} joints ({', '.join(sj.name for sj in joints)})")
    return f"rig {rig.name!r} drives the {j.side} {j.name}"


def _limits_words(c) -> str:
    if _limb_of(c) is not None:
        return (f"limb file {_who(c)} ({c.side + ' ' if c.side else ''}"
                f"{c.limb or 'limb'}: {', '.join(c.joint_names)})")
    return f"constraint {_who(c)}"


def _rig_mismatch(enforced, rig) -> str | None:
    """Why the enforced limits cannot be those of what the rig drives (None: they can)."""
    if rig is None:
        return None
    joints = _servo_joints(rig)
    rig_joint = getattr(rig, "joint", None)
    if not joints:
        if _limb_of(enforced) is not None:
            return f"a {_limits_words(enforced)}, but {_drives(rig)}: give its constraint file"
        if rig_joint is None:
            return None
        why = joint_mismatch(enforced, for_joint=rig_joint.name, for_side=rig_joint.side)
        return None if why is None else f"constraint {_who(enforced)} {why}: {_drives(rig)}"
    if _limb_of(enforced) is None:
        return (f"a one joint's constraint {_who(enforced)}, but {_drives(rig)}: give a limb "
                "file of that limb")
    names = tuple(sj.name for sj in joints)
    if enforced.limb and rig.limb and enforced.limb != rig.limb:
        return f"a {_limits_words(enforced)}, but {_drives(rig)}"
    if enforced.side and rig_joint is not None and enforced.side != rig_joint.side:
        return f"the {_limits_words(enforced)} is for the {enforced.side} side: {_drives(rig)}"
    if tuple(enforced.joint_names) != names:
        return (f"the joints of {_limits_words(enforced)} are not the rig's: {_drives(rig)}, "
                "in that order")
    for lj, sj in zip(enforced.joints, joints, strict=True):
        if lj.kind != sj.kind and not hinge_on_forearm(lj, sj):
            return (f"joint {lj.name!r} of {_limits_words(enforced)} holds {lj.kind} limits, "
                    f"but rig {rig.name!r} drives its {sj.name} as a {sj.kind} joint "
                    f"({len(sj.axes)} servos)" + _hinge_axis_words(lj, sj))
    return None


def hinge_on_forearm(limb_joint, servo_joint) -> bool:
    """Whether a servo limb's joint drives ``limb_joint``'s hinge limits: a forearm joint's
    two servos (flexion, then pronation–supination about the limb axis) whose flexion servo
    turns about the hinge's axis. A hinge is the forearm whose rotation interval is [0, 0]:
    its allowed rotations ``h(θ)`` about the axis are the forearm's ``F(θ) ⊗ R(0)``, which
    those servos reach exactly (the rotation servo at its zero), and the hinge's exact oracle
    judges any pronation as a distance from that arc — so the supervisor holds the rotation
    servo within the tolerance of its zero.

    Parameters
    ----------
    limb_joint : models.limb.LimbJoint
        A joint of the enforced limb file.
    servo_joint : rig.devices.config.ServoJoint
        The rig's joint at the same place.

    Returns
    -------
    bool
        True when the limb joint is a single-axis (hinge) joint, the servos' kind is a
        flexion-rotation (forearm) kind, and the first servo's axis is the hinge's (either
        sign) within 0.1°.
    """
    servo_kind = get_kind(servo_joint.kind)
    if not (limb_joint.joint_kind.single_axis and servo_kind.flexion_rotation):
        return False
    hinge_axis = limb_joint.joint_kind.flexion_axis(limb_joint.loosest())
    if hinge_axis is None or not servo_joint.axes:
        return False
    a = np.asarray(hinge_axis, dtype=np.float64)
    s = np.asarray(servo_joint.axes[0].axis, dtype=np.float64)
    cos = abs(float(a @ s)) / (float(np.linalg.norm(a)) * float(np.linalg.norm(s)))
    return cos >= math.cos(math.radians(HINGE_AXIS_DEG))


def _hinge_axis_words(limb_joint, servo_joint) -> str:
    """Why a hinge is not held by a forearm joint's servos when only its axis is wrong."""
    if not (limb_joint.joint_kind.single_axis
            and get_kind(servo_joint.kind).flexion_rotation and servo_joint.axes):
        return ""
    a = limb_joint.joint_kind.flexion_axis(limb_joint.loosest())
    s = servo_joint.axes[0].axis
    return (f" whose flexion servo turns about ({', '.join(f'{v:g}' for v in s)}), not the "
            f"hinge's axis ({', '.join(f'{v:.3g}' for v in a)})")


def _model_shape_mismatch(path, embedded, rig) -> str:
    if _limb_of(embedded) is not None:
        return (f"{path}: a limb model ({_limits_words(embedded)}), but "
                f"{_drives(rig) if rig is not None else 'the enforced limits are one joint'}"
                "'s: give a model trained on that joint's constraint file")
    return (f"{path}: a one-joint model, but "
            f"{_drives(rig) if rig is not None else 'the enforced limits are a limb'}: give a "
            "limb model (rig train on the limb's file)")


def _joint_model_problems(path, embedded, enforced, source, rig, session_id,
                          session_patient) -> list[str]:
    """A one-joint model against the enforced constraint, the rig and the session."""
    rig_joint = getattr(rig, "joint", None)
    problems: list[str] = []
    if embedded is None:
        problems.append(f"{path}: the model embeds no constraint, so it cannot be checked "
                        f"against {source}")
        return problems
    # the person first: a model made for someone else is the mistake that matters most
    if (embedded.patient is not None and session_patient is not None
            and embedded.patient != session_patient):
        problems.append(f"{path}: model is for patient {embedded.patient!r}, session "
                        f"{session_id} is patient {session_patient!r}")
    joint = getattr(rig_joint, "name", None)
    side = getattr(rig_joint, "side", None)
    if embedded.joint is not None and joint is not None and embedded.joint != joint:
        problems.append(f"{path}: model is for joint {embedded.joint!r}, rig "
                        f"{rig.name!r} drives joint {joint!r}")
    if embedded.side is not None and side is not None and embedded.side != side:
        problems.append(f"{path}: model is for the {embedded.side} side, rig "
                        f"{rig.name!r} is the {side} side")
    if enforced is not embedded and embedded != enforced:
        problems.append(f"{path}: model trained for constraint {_who(embedded)}, which "
                        f"differs from {source} ({_who(enforced, session_patient)})")
    return problems


def _limb_model_problems(path, embedded, enforced, source, rig, session_id,
                         session_patient) -> list[str]:
    """A limb model against the enforced limb file, the rig and the session (its joints
    refused outright: the network's input is those joints)."""
    if embedded is None:
        return [f"{path}: the model embeds no limb file, so it cannot be checked against "
                f"{source}"]
    if tuple(embedded.joint_names) != tuple(enforced.joint_names) or (
            embedded.limb and enforced.limb and embedded.limb != enforced.limb):
        raise ModelBindingError(f"{path}: a model of the {_limits_words(embedded)}, but "
                                f"{source} is the {_limits_words(enforced)}")
    problems: list[str] = []
    if embedded.patient and session_patient and embedded.patient != session_patient:
        problems.append(f"{path}: model is for patient {embedded.patient!r}, session "
                        f"{session_id} is patient {session_patient!r}")
    side = getattr(getattr(rig, "joint", None), "side", None)
    if embedded.side and side and embedded.side != side:
        problems.append(f"{path}: model is for the {embedded.side} side, rig "
                        f"{rig.name!r} is the {side} side")
    if enforced is not embedded and embedded.content_hash() != enforced.content_hash():
        problems.append(f"{path}: model trained for limb {_who(embedded)}, which differs "
                        f"from {source} ({_who(enforced, session_patient)})")
    return problems
