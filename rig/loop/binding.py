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
"""

from __future__ import annotations

from dataclasses import dataclass, field

from calibration.joints import joint_mismatch
from models.constraint import loads_constraint
from models.errors import ModelsError
from rig.errors import RigConfigError

__all__ = ["Binding", "ModelBindingError", "bind_model"]


class ModelBindingError(RigConfigError):
    """The model does not belong to this rig / session / constraint."""


@dataclass
class Binding:
    """Result of :func:`bind_model`.

    Attributes
    ----------
    constraint : models.constraint.JointConstraint
        The constraint enforced by the supervisor.
    source : str
        Where it came from (``"--constraint FILE"``, ``"session N"``, ``"rig NAME"``,
        ``"model"``).
    model_constraint : JointConstraint or None
        The model's embedded constraint.
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
    constraint : JointConstraint, optional
        Explicit constraint (``--constraint``).
    session_constraint : JointConstraint, optional
        The session's stored boundary.
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
    try:
        embedded = loads_constraint(text, source=f"{path} (embedded constraint)") if text \
            else None
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
    rig_joint = getattr(rig, "joint", None)
    if rig_joint is not None:
        # what the rig drives is not the model's to override: --force-model never reaches here

        why = joint_mismatch(enforced, for_joint=rig_joint.name, for_side=rig_joint.side)
        if why is not None:
            raise ModelBindingError(
                f"{source}: constraint {_who(enforced)} {why}: rig {rig.name!r} drives the "
                f"{rig_joint.side} {rig_joint.name} (--force-model overrides the model, never "
                "the joint the rig drives)")
    problems: list[str] = []
    if embedded is None:
        problems.append(f"{path}: the model embeds no constraint, so it cannot be checked "
                        f"against {source}")
    else:
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
    if problems and not force:
        raise ModelBindingError(f"{problems[0]}; use --force-model to run it anyway (the "
                                "supervisor still enforces the constraint)")
    return Binding(constraint=enforced, source=source, model_constraint=embedded,
                   mismatches=problems)
