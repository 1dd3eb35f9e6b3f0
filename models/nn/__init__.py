"""Learned corrective joint constraints: GMLP networks, RPROP, NetGEN-style evolution.

Public API::

    from models.nn import GMLP, get_config, load_config, evolve, train_network
"""

from models.nn.config import PRESETS, ConfigError, get_config, load_config
from models.nn.evolution import EvolutionResult, Evolver, evolve
from models.nn.gmlp import GMLP, PopulationSpec
from models.nn.rprop import train_population

__all__ = [
    "GMLP",
    "PRESETS",
    "ConfigError",
    "EvolutionResult",
    "Evolver",
    "PopulationSpec",
    "evolve",
    "get_config",
    "load_config",
    "train_population",
]
