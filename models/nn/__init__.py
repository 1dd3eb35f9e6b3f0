"""Learned corrective joint constraints: GMLP networks, RPROP, NetGEN-style evolution.

Public API::

    from models.nn import GMLP, get_config, load_config, evolve, train_correction

    model = train_correction(constraint, get_config("best"), np.random.default_rng(0))
    model.network.predict(q)        # (N, 4) unit corrections; corrected = correction ⊗ q
    models.onnx_io.export_onnx(model.network, "m.onnx", constraint_yaml=constraint.to_yaml())

Modules: :mod:`~models.nn.activations` (node functions, spline templates),
:mod:`~models.nn.gmlp` (stacked forward/backward), :mod:`~models.nn.rprop` (population
iRprop−/+), :mod:`~models.nn.evolution` (NetGEN-style GA), :mod:`~models.nn.config` (presets,
YAML), :mod:`~models.nn.train` (patterns from :mod:`models.datasets` → evolution →
metrics), :mod:`~models.nn.ndf` (the distance field of a coupled swing: the trained limb
model), :mod:`~models.nn.sdf` (the earlier single-joint distance MLP). Exact oracles:
:mod:`models.oracle` (a joint's and a limb's).
"""

from models.nn.config import PRESETS, ConfigError, get_config, load_config
from models.nn.evolution import EvolutionResult, Evolver, evolve
from models.nn.gmlp import GMLP, PopulationSpec
from models.nn.rprop import train_population
from models.nn.train import TrainedModel, train_correction

__all__ = [
    "GMLP",
    "PRESETS",
    "ConfigError",
    "EvolutionResult",
    "Evolver",
    "PopulationSpec",
    "TrainedModel",
    "evolve",
    "get_config",
    "load_config",
    "train_correction",
    "train_population",
]
