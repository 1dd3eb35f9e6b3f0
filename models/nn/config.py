"""Training configuration: presets and YAML files, validated field by field.

A configuration is a nested mapping with five sections (``model`` chooses the method); a YAML
file (``rig train --config``) overrides any subset of a preset's fields. Unknown fields and bad
values raise :class:`models.errors.ConfigError` naming the dotted field, e.g.
``evolution.population: expected an integer >= 2, got 'fifty'``.

Presets
-------
``field`` (the default of ``rig train``)
    Not a network: :mod:`models.field` — the swing correction sampled from the exact oracle on
    a grid of ~0.5° node spacing (``model.grid: 400``), the twist clamped exactly in the ONNX
    graph (``model.method: field``). On held-out irregular boundaries with twist it is ~10×
    more accurate than ``best`` and leaves valid orientations unchanged
    (``docs/learned-constraints.md``); < 1 s to build. The ``network``, ``evolution`` and
    ``training`` sections are unused; ``data.test`` sets the size of the held-out check.
``thesis``
    TABLE I/II/VIII: max 20 hidden nodes, population 50, 20 generations, ≤ 500 epochs, stop at
    training MSE 0.001 (SNNS convention, SSE / patterns; our ``stop_mse`` is per output
    component, so 0.00025), learning rate (RPROP Δ₀) 0.1, links regulariser α₂ = 0.01, evolve links,
    hidden nodes and epochs, hidden sigmoid + linear output (TABLE XII's baseline), 500
    training patterns, 5 repeats.
``best``
    What wins on accuracy per microsecond of inference (``benchmarks/bench_accuracy.py``,
    ``benchmarks/bench_onnx.py --hidden N``): through onnxruntime a single orientation costs
    the same ~9.5 µs with 20 or 80 hidden nodes, so the larger network wins. A fully connected
    GMLP with 80 leaky-ReLU hidden nodes and linear outputs, iRprop− with Δ₀ = 0.01, Δmax = 1
    for 3000 epochs on 2000 training patterns, best of 10 random starts on 500 validation
    patterns, the in-graph *swing* input map (the network sees the twist-free swing of any
    orientation, so it serves live, twisted orientations; for a constraint with twist limits
    training falls back to the ``centre`` hemisphere rule on twisted patterns), in the *centre
    frame* (``network.frame: centre``, :mod:`models.nn.gmlp`: the input map's singularity sits
    on the correctional discontinuity opposite the boundary centre, so +Y/+Z-centred cones
    reach the +X figures). Training targets overshoot the boundary by 0.5°
    (``data.overshoot_deg``): the network's smooth undershoot at the boundary discontinuity then
    lands inside, which takes the invalid inputs left > 1° outside from 1.2 % to under 0.1 % on
    cones for +0.08 percentage points of mean 3-D error. ~25 s of training on one core.
``compact``
    ``best`` within the thesis's 20-hidden-node limit (1000 patterns, 2000 epochs, ~2 s of
    training): about twice the error of ``best``. Topology evolution did not pay against it: on
    a 45° cone an evolved leaky-ReLU GMLP (population 20 × 5 generations, same training)
    reached 0.63 % mean 3-D error in 155 s, the fixed one 0.52 % in 13 s.
    ``thesis`` and ``fixed`` keep ``network.frame: parent`` (the thesis's encoding).
``fixed``
    The thesis's baseline without evolution: a fully connected GMLP (20 sigmoid hidden nodes,
    linear outputs) with the thesis's training settings (≤ 500 epochs, stop MSE 0.001 SNNS,
    Δ₀ 0.1), best of 10 random starts.
"""

from __future__ import annotations

import copy
from typing import Any

import yaml

from models.errors import ModelsError
from models.nn import activations as act
from models.yamlio import safe_load_yaml


class ConfigError(ModelsError, ValueError):
    """A training configuration (preset override or YAML file) is invalid; names the field."""


_THESIS: dict[str, Any] = {
    "model": {
        "method": "gmlp",  # gmlp: a network regresses the correction; field: models.field
        "grid": 400,  # field: nodes per octahedral-diamond side (~0.5° node spacing)
    },
    "network": {
        "max_hidden": 20,
        "hidden_activations": ["sigmoid"],
        "output_activations": ["linear"],
        "spline_control_points": 9,
        "spline_templates": 4,
        "canonicalise": "w-positive",
        "frame": "parent",
    },
    "evolution": {
        "population": 50,
        "generations": 20,
        "tournament": 2,
        "crossover_rate": 0.9,
        "mutation_rate": 0.01,
        "alpha2": 0.01,
        "link_probability": 0.5,
        "hidden_probability": 0.75,
        "evolve_links": True,
        "evolve_hidden": True,
        "evolve_epochs": True,
        "evolve_learning": False,
        "evolve_activations": False,
        "evolve_splines": False,
        "elitism": 0,
        "repeats": 5,
    },
    "training": {
        "max_epochs": 500,
        "min_epochs": 50,
        # thesis: "stop at MSE 0.001" in SNNS's convention (NetGEN trained with SNNS), where
        # MSE = SSE / patterns, summed over the 4 outputs: 0.001 / 4 per output component
        "stop_mse": 0.00025,
        "learning_rate": 0.1,
        "delta_max": 50.0,
        "variant": "irprop-",
        "dtype": "float32",
        "huber": 0.0,
    },
    "data": {
        "train": 500,
        "validation": 250,
        "test": 3000,
        "distribution": "even",
        "order": "valid-first",
        "hemisphere": "w-positive",
        "overshoot_deg": 0.0,
        "twist": False,
    },
}

PRESETS: dict[str, dict[str, Any]] = {"thesis": _THESIS}
PRESETS["compact"] = copy.deepcopy(_THESIS)
PRESETS["compact"]["network"].update(
    {"hidden_activations": ["leaky_relu"], "canonicalise": "swing", "frame": "centre"})
PRESETS["compact"]["training"].update(
    {"max_epochs": 2000, "min_epochs": 2000, "stop_mse": 1e-6, "learning_rate": 0.01,
     "delta_max": 1.0})
PRESETS["compact"]["evolution"].update(
    {"generations": 0, "population": 10, "repeats": 1, "link_probability": 1.0,
     "hidden_probability": 1.0, "evolve_links": False, "evolve_hidden": False,
     "evolve_epochs": False})
PRESETS["compact"]["data"].update({"train": 1000, "validation": 500})
PRESETS["best"] = copy.deepcopy(PRESETS["compact"])
PRESETS["best"]["network"]["max_hidden"] = 80
PRESETS["best"]["training"].update({"max_epochs": 3000, "min_epochs": 3000})
PRESETS["best"]["data"].update({"train": 2000, "overshoot_deg": 0.5})
PRESETS["field"] = copy.deepcopy(PRESETS["best"])
PRESETS["field"]["model"]["method"] = "field"
PRESETS["fixed"] = copy.deepcopy(_THESIS)
PRESETS["fixed"]["evolution"].update({"generations": 0, "population": 10, "repeats": 1,
                                      "link_probability": 1.0, "hidden_probability": 1.0,
                                      "evolve_links": False, "evolve_hidden": False,
                                      "evolve_epochs": False})

_CHOICES = {
    ("model", "method"): ("gmlp", "field"),
    ("network", "canonicalise"): ("swing", "w-positive", "centre", "none"),
    ("network", "frame"): ("centre", "parent"),
    ("training", "variant"): ("irprop-", "irprop+"),
    ("training", "dtype"): ("float32", "float64"),
    ("data", "distribution"): ("even", "clustered", "uniform"),
    ("data", "order"): ("valid-first", "random", "reversed"),
    ("data", "hemisphere"): ("ambiguous", "centre", "w-positive"),
}
_INT_MIN = {
    ("model", "grid"): 8,
    ("network", "max_hidden"): 1, ("network", "spline_control_points"): 4,
    ("network", "spline_templates"): 1, ("evolution", "population"): 2,
    ("evolution", "generations"): 0, ("evolution", "tournament"): 1,
    ("evolution", "elitism"): 0, ("evolution", "repeats"): 1,
    ("training", "max_epochs"): 1, ("training", "min_epochs"): 0,
    ("data", "train"): 8, ("data", "validation"): 4, ("data", "test"): 4,
}
_UNIT = {("evolution", k) for k in ("crossover_rate", "mutation_rate", "alpha2",
                                    "link_probability", "hidden_probability")}
_POS = {("training", k) for k in ("stop_mse", "learning_rate", "delta_max")}
_NONNEG = {("data", "overshoot_deg"), ("training", "huber")}


def _check_field(sec: str, key: str, value: Any, default: Any) -> Any:
    where = f"{sec}.{key}"
    if (sec, key) in _CHOICES:
        ok = _CHOICES[(sec, key)]
        if value not in ok:
            raise ConfigError(f"{where}: expected one of {list(ok)}, got {value!r}")
    elif (sec, key) in _INT_MIN:
        lo = _INT_MIN[(sec, key)]
        if isinstance(value, bool) or not isinstance(value, int) or value < lo:
            raise ConfigError(f"{where}: expected an integer >= {lo}, got {value!r}")
    elif (sec, key) in _UNIT or (sec, key) in _POS or (sec, key) in _NONNEG:
        if isinstance(value, str):  # YAML 1.1 reads 1e-4 (no dot) as a string
            try:
                value = float(value)
            except ValueError:
                pass
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        value = float(value)
        if (sec, key) in _UNIT and not 0.0 <= value <= 1.0:
            raise ConfigError(f"{where}: expected a number in [0, 1], got {value!r}")
        if (sec, key) in _POS and not value > 0.0:
            raise ConfigError(f"{where}: expected a positive number, got {value!r}")
        if (sec, key) in _NONNEG and not 0.0 <= value < 45.0:
            raise ConfigError(f"{where}: expected a number in [0, 45), got {value!r}")
    elif isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
    elif isinstance(default, list):
        if not isinstance(value, list) or not value:
            raise ConfigError(f"{where}: expected a non-empty list of activation names")
        for v in value:
            try:
                act.index_of(str(v))
            except ValueError as err:
                raise ConfigError(f"{where}: {err}") from None
    return value


def validate(cfg: Any, source: str = "configuration") -> dict[str, Any]:
    """Check a complete configuration mapping; returns a normalised deep copy."""
    if not isinstance(cfg, dict):
        raise ConfigError(f"{source}: expected a mapping with sections {list(_THESIS)}")
    out: dict[str, Any] = {}
    for sec, fields in _THESIS.items():
        got = cfg.get(sec, {})
        if not isinstance(got, dict):
            raise ConfigError(f"{sec}: expected a mapping, got {got!r}")
        out[sec] = {k: _check_field(sec, k, got[k], fields[k]) if k in got else fields[k]
                    for k in fields}
        unknown = set(got) - set(fields)
        if unknown:
            raise ConfigError(f"{sec}.{sorted(unknown)[0]}: unknown field; "
                              f"expected one of {sorted(fields)}")
    unknown = set(cfg) - set(_THESIS)
    if unknown:
        raise ConfigError(f"{sorted(unknown)[0]}: unknown section; expected {list(_THESIS)}")
    if out["training"]["min_epochs"] > out["training"]["max_epochs"]:
        raise ConfigError("training.min_epochs: must not exceed training.max_epochs "
                          f"({out['training']['max_epochs']})")
    return out


def merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """Deep-merge ``override`` into a copy of ``base`` (two levels: section, field)."""
    out = copy.deepcopy(base)
    for sec, fields in override.items():
        if isinstance(fields, dict) and isinstance(out.get(sec), dict):
            out[sec].update(fields)
        else:
            out[sec] = fields
    return out


def get_config(preset: str = "field", override: dict[str, Any] | None = None,
               source: str = "configuration") -> dict[str, Any]:
    """A validated configuration: ``preset`` with ``override`` applied."""
    if preset not in PRESETS:
        raise ConfigError(f"preset: expected one of {sorted(PRESETS)}, got {preset!r}")
    try:
        return validate(merge(PRESETS[preset], override or {}), source)
    except ConfigError as err:
        raise ConfigError(f"{source}: {err}" if source != "configuration" else str(err)) from None


def load_config(path: str, preset: str = "field") -> dict[str, Any]:
    """Read a YAML override file (:func:`models.yamlio.safe_load_yaml`) and apply it to
    ``preset``."""
    with open(path, encoding="utf-8") as fh:
        try:
            data = safe_load_yaml(fh)
        except yaml.YAMLError as err:
            raise ConfigError(f"{path}: not valid YAML ({err})".replace("\n", " ")) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping with sections {list(_THESIS)}")
    return get_config(preset, data, source=path)
