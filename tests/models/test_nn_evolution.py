"""Genome encoding, GA operators, presets and configuration validation, small evolutions."""

from __future__ import annotations

import numpy as np
import pytest

from models.constraint import JointConstraint
from models.datasets import quaternion_dataset
from models.nn import evolution as E
from models.nn.config import ConfigError, get_config, load_config


def cone_patterns(n, centre, radius_deg, rng):
    """Twist-free ``w ≥ 0`` patterns of a cone, valid first: (inputs, targets)."""
    ds = quaternion_dataset(JointConstraint.cone(centre, radius_deg), n, rng,
                            hemisphere="w-positive")
    return ds.inputs, ds.targets


def _cfg(**evo):
    return get_config("thesis", {
        "evolution": {"population": 6, "generations": 2, "repeats": 1, **evo},
        "training": {"max_epochs": 40, "min_epochs": 10},
        "network": {"max_hidden": 6},
    })


def test_thesis_preset_is_table_ii():
    c = get_config("thesis")
    assert c["network"]["max_hidden"] == 20
    assert c["evolution"]["population"] == 50
    assert c["evolution"]["generations"] == 20
    assert c["evolution"]["repeats"] == 5
    assert c["evolution"]["tournament"] == 2
    assert 0.001 <= c["evolution"]["alpha2"] <= 0.01
    assert c["training"]["max_epochs"] == 500
    assert c["training"]["stop_mse"] == 0.001 / 4  # SNNS: SSE / patterns over 4 outputs
    assert c["training"]["learning_rate"] == 0.1
    assert c["data"]["train"] == 500


@pytest.mark.parametrize(("override", "field"), [
    ({"evolution": {"population": "fifty"}}, "evolution.population"),
    ({"evolution": {"alpha2": 2.0}}, "evolution.alpha2"),
    ({"training": {"variant": "sgd"}}, "training.variant"),
    ({"network": {"hidden_activations": ["swish"]}}, "network.hidden_activations"),
    ({"network": {"hidden": 3}}, "network.hidden"),
    ({"bogus": {}}, "bogus"),
    ({"training": {"min_epochs": 900}}, "training.min_epochs"),
])
def test_config_errors_name_the_field(override, field):
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        get_config("thesis", override)


def test_yaml_config_file(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("evolution:\n  population: 12\ntraining: {stop_mse: 1e-4}\n")
    c = load_config(str(p), "thesis")
    assert c["evolution"]["population"] == 12 and c["training"]["stop_mse"] == 1e-4
    p.write_text("evolution: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(str(p))
    p.write_text("training:\n  max_epochs: -3\n")
    with pytest.raises(ConfigError, match=r"c\.yaml: training\.max_epochs"):
        load_config(str(p))


def test_genome_layout_and_decoding():
    ev = E.Evolver(_cfg())
    lay = ev.layout
    assert lay.length == 3 + 4 * 9 + 6 * (2 + 4) + 4 * (1 + 4 + 6)
    g = ev.random_genomes(5, np.random.default_rng(0))
    assert np.all(g >= 0) and np.all(g < ev.alleles)
    dec = ev.decode(g)
    # absent hidden nodes carry no links; biases only on present nodes
    present = dec.spec.mask1[:, -1, :]
    assert np.all(dec.spec.mask1[:, :-1, :][~np.repeat(present[:, None, :], 4, 1)] == 0)


def test_network_without_input_output_path_gets_lowest_fitness():
    rng = np.random.default_rng(1)
    ev = E.Evolver(_cfg())
    g = ev.random_genomes(3, rng)
    lay = ev.layout
    out = g[:, lay.out_start:].reshape(3, lay.n_out, lay.out_row)
    out[0, 0, 1:] = 0  # output 0 of network 0: no link at all
    dec = ev.decode(g)
    assert not dec.feasible[0]
    x, t = cone_patterns(60, [1, 0, 0], 45, rng)
    fit, *_ = ev.evaluate(g, x[:40], t[:40], x[40:], t[40:], rng)
    assert fit[0] == E.LOWEST_FITNESS and np.all(fit[1:] > E.LOWEST_FITNESS)


def test_crossover_and_mutation_respect_alleles_and_frozen_genes():
    rng = np.random.default_rng(2)
    ev = E.Evolver(_cfg(mutation_rate=0.5))
    g = ev.random_genomes(20, rng)
    a, b = g[:10], g[10:]
    c1, c2 = ev._crossover(a, b, rng)
    # two-point crossover swaps genes position-wise
    assert np.all((c1 == a) | (c1 == b)) and np.all(c1 + c2 == a + b)
    m = ev._mutate(g.copy(), rng)
    assert np.all(m < ev.alleles) and np.all(m >= 0)
    assert np.all(m[:, ~ev.mutable] == g[:, ~ev.mutable])
    assert np.any(m[:, ev.mutable] != g[:, ev.mutable])


def test_evolution_is_deterministic_and_improves():
    rng_data = np.random.default_rng(3)
    x, t = cone_patterns(150, [0, 1, 0], 60, rng_data)
    cfg = _cfg(evolve_activations=True, evolve_splines=True, evolve_learning=True)
    cfg["network"]["hidden_activations"] = ["sigmoid", "tanh", "leaky_relu", "spline0"]
    runs = [E.evolve(cfg, x[:100], t[:100], x[100:], t[100:], np.random.default_rng(7))
            for _ in range(2)]
    a, b = runs
    np.testing.assert_array_equal(a.network.w1, b.network.w1)
    best = [s.best_fitness for s in a.history]
    assert best == sorted(best) and len(best) == 3
    assert a.network.info["hidden"] == a.network.n_hidden
