"""``rig dataset make`` / ``rig dataset info`` as a library: the thesis's vector-field
datasets (ch. 3-4).

:func:`make_dataset` writes one ``.npz`` dataset (:mod:`models.datasets`; with ``split`` one
file per part, ``<stem>-train.npz`` ...); :func:`dataset_info` summarises a dataset file, with
the PCA of its quaternion inputs (:mod:`models.pca`).

The options come as the command line gives them (text) and are parsed here rather than by
click's types, so that a bad value is reported as one line naming the option
(``rig: error: --n: ...``, exit status 2) like every other user error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from models import datasets as D
from models.datasets import cone_constraint, limb_postures, load_dataset
from models.errors import DatasetError
from models.fileio import check_output
from models.limb import load_limits
from models.pca import quaternion_pca
from models.shapes import load_shape
from rig.training.kinds import training_kind

__all__ = ["KINDS", "dataset_info", "make_dataset"]

KINDS = ("quaternion", "limb", "interval", "ball2", "ball3", "sphere-vector", "sphere-quaternion")


def _int(value: str | None, option: str, *, default: int | None = None) -> int:
    if value is None:
        if default is None:
            raise DatasetError(f"{option}: required")
        return default
    try:
        return int(value)
    except ValueError as err:
        raise DatasetError(f"{option}: expected an integer, got {value!r}") from err


def _float(value: str | None, option: str, default: float | None = None) -> float | None:
    if value is None:
        return default
    try:
        return float(value)
    except ValueError as err:
        raise DatasetError(f"{option}: expected a number, got {value!r}") from err


def _floats(value: str, option: str, count: int | None = None) -> tuple[float, ...]:
    try:
        out = tuple(float(p) for p in value.split(","))
    except ValueError as err:
        raise DatasetError(f"{option}: expected comma-separated numbers, got {value!r}") from err
    if count is not None and len(out) != count:
        raise DatasetError(f"{option}: expected {count} comma-separated numbers, got {value!r}")
    return out


def _constraint(constraint: str | None, loaded, shape: str | None, radius: str | None,
                centre: str):
    """The quaternion dataset's constraint; ``loaded``: the ``--constraint`` file's content."""

    given = [
        o
        for o, v in (("--constraint", constraint), ("--shape", shape), ("--cone-radius", radius))
        if v is not None
    ]
    if len(given) > 1:
        raise DatasetError(f"{' and '.join(given)}: give only one constraint source")
    if constraint is not None:
        loaded.require_swing_twist("rig dataset make")
        return loaded
    if shape is not None:
        return load_shape(shape)
    if radius is not None:
        return cone_constraint(_floats(centre, "--cone-centre", 3), _float(radius, "--cone-radius"))  # type: ignore[arg-type]
    raise DatasetError(
        "--kind quaternion needs a constraint: --constraint FILE, --shape NAME or "
        "--cone-radius DEG (with --cone-centre x,y,z)"
    )


#: library argument name -> the option that sets it, to name options in error messages
_OPTION_OF = {
    "n": "--n",
    "radius_deg": "--cone-radius",
    "centre": "--cone-centre",
    "band_deg": "--band-deg",
    "band": "--band-deg",
    "distribution": "--distribution",
    "order": "--order",
    "hemisphere": "--hemisphere",
    "lower": "--lower",
    "upper": "--upper",
    "radius": "--radius",
    "fractions": "--split",
}


def make_dataset(**options: Any) -> list[tuple[Path, Any]]:
    """Generate, optionally split, and save; returns ``[(path, Dataset), ...]`` written.

    Takes the ``rig dataset make`` options as strings (see :func:`_make`). A
    :class:`DatasetError` about a library argument is re-labelled with the option's name.
    """
    try:
        return _make(**options)
    except DatasetError as err:
        name, sep, rest = str(err).partition(": ")
        if sep and name in _OPTION_OF:
            raise DatasetError(f"{_OPTION_OF[name]}: {rest}") from err
        raise


def _make(
    *,
    kind: str,
    out: str | None,
    n: str | None,
    constraint: str | None = None,
    shape: str | None = None,
    cone_centre: str = "1,0,0",
    cone_radius: str | None = None,
    distribution: str | None = None,
    order: str | None = None,
    hemisphere: str | None = None,
    twist: bool = False,
    band_deg: str | None = None,
    lower: str | None = None,
    upper: str | None = None,
    radius: str | None = None,
    seed: str | None = None,
    split: str | None = None,
) -> list[tuple[Path, Any]]:

    if kind not in KINDS:
        raise DatasetError(f"--kind: unknown kind {kind!r}; choose one of {', '.join(KINDS)}")
    if out is None:
        raise DatasetError("--out: required (the .npz file to write)")

    check_output(out, "--out")  # before the dataset is drawn
    count = _int(n, "--n")
    rng = _int(seed, "--seed", default=0)
    if rng < 0:
        raise DatasetError(f"--seed: must be >= 0, got {rng}")
    if kind not in ("quaternion", "limb"):
        for option, value in (
            ("--distribution", distribution),
            ("--order", order),
            ("--hemisphere", hemisphere),
            ("--twist", twist or None),
            ("--constraint", constraint),
            ("--shape", shape),
        ):
            if value is not None:
                raise DatasetError(f"{option}: only for --kind quaternion, not {kind!r}")
    limits = None
    if kind in ("quaternion", "limb") and constraint is not None:
        limits = load_limits(constraint)  # read once, either kind
        # what the file makes: a limb file a limb dataset, one joint's a quaternion dataset
        kind = training_kind(limits).dataset_kind(kind, constraint)
    if kind == "limb":
        if limits is None:
            raise DatasetError("--kind limb: needs --constraint LIMB.yaml (a limb file)")
        return _limb(limits, target_path=out, n=count, seed=rng, split=split, others=(
            ("--shape", shape), ("--cone-radius", cone_radius),
            ("--distribution", distribution), ("--order", order),
            ("--hemisphere", hemisphere), ("--twist", twist or None),
            ("--band-deg", band_deg)))
    if kind == "quaternion":
        c = _constraint(constraint, limits, shape, cone_radius, cone_centre)
        ds = D.quaternion_dataset(
            c,
            count,
            rng,
            distribution=distribution or "even",
            order=order or "valid-first",
            hemisphere=hemisphere or "ambiguous",
            twist=twist,
            band_deg=_float(band_deg, "--band-deg"),
        )
    elif kind == "interval":
        ds = D.interval_dataset(
            count,
            rng,
            _float(lower, "--lower", -0.5),  # type: ignore[arg-type]
            _float(upper, "--upper", 0.5),
        )  # type: ignore[arg-type]
    elif kind in ("ball2", "ball3"):
        ds = D.ball_dataset(count, rng, dim=int(kind[-1]), radius=_float(radius, "--radius", 0.5))  # type: ignore[arg-type]
    else:
        make = D.sphere_vector_dataset if kind == "sphere-vector" else D.sphere_quaternion_dataset
        ds = make(
            count,
            rng,
            _floats(cone_centre, "--cone-centre", 3),
            _float(cone_radius, "--cone-radius", 45.0),  # type: ignore[arg-type]
            band_deg=_float(band_deg, "--band-deg"),
        )
    return _save(ds, out, split, rng)


def _limb(limb, *, target_path: str, n: int, seed: int, split: str | None,
          others) -> list[tuple[Path, Any]]:
    """A limb dataset (:func:`models.datasets.limb_dataset`)."""

    for option, value in others:
        if value is not None:
            raise DatasetError(f"{option}: not for a limb file (limb datasets take --n, "
                               "--seed, --split, --out)")
    return _save(D.limb_dataset(limb, n, seed), target_path, split, seed)


def _save(ds, out: str, split: str | None, rng: int) -> list[tuple[Path, Any]]:

    target = Path(out)
    if split is None:
        return [(ds.save(target), ds)]
    parts = D.split_dataset(ds, _floats(split, "--split"), rng + 1)
    written = []
    for part in parts:
        p = target.with_name(f"{target.stem}-{part.meta['split']}{target.suffix or '.npz'}")
        written.append((part.save(p), part))
    return written


def dataset_info(path: str) -> str:
    """The summary ``rig dataset info`` prints."""

    ds = load_dataset(path)
    lines = [f"{path}", ds.summary()]
    if ds.meta.get("kind") == "limb":
        lines.append(limb_postures(ds)[0].summary())
        return "\n".join(lines)
    c = ds.constraint()
    if c is not None:
        lines.append(c.summary())
    if ds.meta.get("kind") == "quaternion" and len(ds) >= 2:
        lines.append("inputs: " + quaternion_pca(ds.inputs).summary())
    return "\n".join(lines)
