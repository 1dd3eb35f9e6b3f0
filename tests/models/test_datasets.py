"""Dataset generators, splits and the .npz format (models.datasets)."""

from __future__ import annotations

import json
import math
import re
import zipfile

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import JointConstraint
from models.datasets import (
    REGION_NAMES,
    Dataset,
    ball_dataset,
    common_test_set,
    cone_constraint,
    interval_dataset,
    load_dataset,
    quaternion_dataset,
    sphere_quaternion_dataset,
    sphere_vector_dataset,
    split_dataset,
)
from models.errors import DatasetError
from models.oracle import ConstraintOracle
from models.shapes import SHAPES, load_shape

X = np.array([1.0, 0.0, 0.0])
AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


def _labels_agree_with_oracle(ds: Dataset, constraint: JointConstraint) -> None:
    res = ConstraintOracle(constraint).evaluate(ds.inputs)
    band = math.radians(ds.meta["generator"]["band_deg"])
    np.testing.assert_array_equal(ds.valid, res.valid)
    d = res.distance
    r = ds.regions
    assert np.all(d[r == 0] <= -band) and np.all(d[r == 3] > band)
    assert np.all((d[r == 1] > -band) & (d[r == 1] <= 0))
    assert np.all((d[r == 2] > 0) & (d[r == 2] <= band))


# -- chapter 4: distributions ------------------------------------------------------------------
@pytest.mark.parametrize("radius", [5.0, 45.0, 150.0])
@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_even_regions_have_equal_counts_whatever_the_radius(radius, axis):
    c = cone_constraint(AXES[axis], radius)
    ds = quaternion_dataset(c, 1000, 7)
    assert list(np.bincount(ds.regions, minlength=4)) == [250, 250, 250, 250]
    expected_band = min(10.0, radius / 2, (180 - radius) / 2)
    assert ds.meta["generator"]["band_deg"] == pytest.approx(expected_band)
    _labels_agree_with_oracle(ds, c)


@pytest.mark.parametrize("name", SHAPES)
def test_even_on_irregular_shapes(name):
    c = load_shape(name)
    ds = quaternion_dataset(c, 402, 1)
    assert list(np.bincount(ds.regions, minlength=4)) == [101, 101, 100, 100]
    _labels_agree_with_oracle(ds, c)


def test_clustered_band_is_within_5_degrees():
    c = load_shape("original")
    ds = quaternion_dataset(c, 800, 2, distribution="clustered")
    assert ds.meta["generator"]["band_deg"] == pytest.approx(5.0)
    assert list(np.bincount(ds.regions, minlength=4)) == [200] * 4
    d = np.degrees(ConstraintOracle(c).signed_distance(ds.inputs))
    near = np.isin(ds.regions, (1, 2))
    assert np.all(np.abs(d[near]) <= 5.0 + 1e-9)
    assert near.mean() == 0.5  # half the patterns in the dense 5° band
    _labels_agree_with_oracle(ds, c)


def test_uniform_directions_cover_the_sphere():
    r = 60.0
    c = cone_constraint((0, 1, 0), r)
    ds = quaternion_dataset(c, 20000, 3, distribution="uniform")
    d = Q.limb_direction(ds.inputs)
    assert np.abs(d.mean(axis=0)).max() < 0.03
    cap = (1 - math.cos(math.radians(r))) / 2  # area fraction of the valid cap
    assert ds.valid.mean() == pytest.approx(cap, abs=0.015)
    _labels_agree_with_oracle(ds, c)


# -- chapter 4: targets, twist, hemisphere, order ----------------------------------------------
@pytest.mark.parametrize(
    "constraint",
    [
        cone_constraint((0, 0, 1), 45),
        load_shape("c-shape"),
        JointConstraint.cone((1, 0, 0), 50, twist=(-40, 70)),
    ],
    ids=["cone", "polygon", "cone+twist"],
)
@pytest.mark.parametrize("twist", [False, True])
def test_targets_are_the_oracle_corrections(constraint, twist):
    ds = quaternion_dataset(constraint, 600, 4, twist=twist)
    oracle = ConstraintOracle(constraint)
    np.testing.assert_allclose(ds.targets, oracle.correction(ds.inputs), atol=1e-12)
    assert np.all(ds.targets[:, 0] >= 0.0)
    np.testing.assert_array_equal(ds.targets[ds.valid], np.tile(Q.IDENTITY, (ds.valid.sum(), 1)))
    np.testing.assert_allclose(np.linalg.norm(ds.inputs, axis=1), 1.0)
    np.testing.assert_allclose(np.linalg.norm(ds.targets, axis=1), 1.0)
    _labels_agree_with_oracle(ds, constraint)


def test_cone_targets_match_thesis_eq_59_68():
    r = math.radians(30.0)
    ds = quaternion_dataset(cone_constraint((1, 0, 0), 30.0), 400, 5, hemisphere="w-positive")
    p = Q.rotate(ds.inputs, X)  # limb direction
    theta = np.arccos(np.clip(p @ X, -1, 1))  # eq. 63
    inv = theta > r
    axis = np.cross(p[inv], X)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    qo = Q.from_axis_angle(axis, theta[inv] - r)  # eq. 65-67
    np.testing.assert_allclose(ds.targets[inv], qo, atol=1e-9)
    corrected = Q.multiply(ds.targets, ds.inputs)  # eq. 68
    ang = Q.angle_between(Q.rotate(corrected, X), X)
    assert np.all(ang <= r + 1e-9)


def test_twist_free_inputs_have_zero_twist_and_w_positive():
    c = load_shape("highly-irregular")
    ds = quaternion_dataset(c, 400, 6, hemisphere="w-positive")
    np.testing.assert_allclose(Q.twist_angle(ds.inputs), 0.0, atol=1e-12)
    assert np.all(ds.inputs[:, 0] >= 0.0)
    np.testing.assert_allclose(ds.inputs[:, 1], 0.0, atol=1e-12)  # axis X × V has no x


def test_twist_inputs_and_twist_limits():
    free = quaternion_dataset(cone_constraint((1, 0, 0), 40), 2000, 8, twist=True)
    assert np.degrees(np.std(Q.twist_angle(free.inputs))) > 60  # spread over (-180, 180]
    c = JointConstraint.cone((1, 0, 0), 40, twist=(-30, 30))
    ds = quaternion_dataset(c, 2000, 8, twist=True)
    assert list(np.bincount(ds.regions, minlength=4)) == [500] * 4
    res = ConstraintOracle(c).evaluate(ds.inputs)
    swing_ok = res.swing_distance <= 0
    assert (swing_ok & ~res.valid).sum() > 50  # invalid by twist alone are represented
    phi = np.degrees(res.twist[res.valid])
    assert np.all((phi >= -30 - 1e-6) & (phi <= 30 + 1e-6))
    bad = JointConstraint.cone((1, 0, 0), 40, twist=(10, 50))
    with pytest.raises(DatasetError, match="twist"):
        quaternion_dataset(bad, 100, 0, twist=False)  # zero twist is never valid


def test_twist_only_constraint():
    c = JointConstraint.from_dict({"name": "tw", "twist": {"min_deg": -30, "max_deg": 45}})
    ds = quaternion_dataset(c, 400, 1, twist=True)
    assert list(np.bincount(ds.regions)) == [100] * 4
    np.testing.assert_allclose(ds.targets, ConstraintOracle(c).correction(ds.inputs), atol=1e-12)
    with pytest.raises(DatasetError, match="invalid"):
        quaternion_dataset(c, 400, 1)  # twist-free inputs are all valid here


def test_hemisphere_rules():
    c = cone_constraint((0, 1, 0), 120)
    amb = quaternion_dataset(c, 2000, 9, hemisphere="ambiguous")
    assert 0.4 < (amb.inputs[:, 0] < 0).mean() < 0.6
    cen = quaternion_dataset(c, 2000, 9, hemisphere="centre")
    qc = np.array(cen.meta["centre_rotation"])
    np.testing.assert_allclose(qc, Q.from_two_vectors(X, np.array([0.0, 1.0, 0.0])))
    assert np.all(cen.inputs @ qc >= 0.0)
    assert (cen.inputs[:, 0] < 0).any()  # not the same rule as w-positive
    wpos = quaternion_dataset(c, 2000, 9, hemisphere="w-positive", twist=True)
    assert np.all(wpos.inputs[:, 0] >= 0.0)

    # the same patterns up to sign (the order differs: the sign draws use the generator)
    def rows(ds):
        both = np.concatenate((Q.canonical(ds.inputs), ds.targets), axis=1)
        return both[np.lexsort(both.T[::-1])]

    np.testing.assert_allclose(rows(amb), rows(cen), atol=1e-12)


@pytest.mark.parametrize("order", ["valid-first", "random", "reversed"])
def test_orders(order):
    ds = quaternion_dataset(cone_constraint((1, 0, 0), 45), 400, 10, order=order)
    v = ds.valid.astype(int)
    if order == "valid-first":
        assert np.all(np.diff(v) <= 0) and v[0] == 1
    elif order == "reversed":
        assert np.all(np.diff(v) >= 0) and v[0] == 0
    else:
        assert np.count_nonzero(np.diff(v)) > 10
    base = quaternion_dataset(cone_constraint((1, 0, 0), 45), 400, 10)
    assert sorted(map(tuple, ds.inputs)) == sorted(map(tuple, base.inputs))


def test_reproducible():
    c = load_shape("original")
    a = quaternion_dataset(c, 300, 123, twist=True)
    b = quaternion_dataset(c, 300, 123, twist=True)
    np.testing.assert_array_equal(a.inputs, b.inputs)
    np.testing.assert_array_equal(a.targets, b.targets)
    np.testing.assert_array_equal(a.regions, b.regions)
    assert a.content_hash() == b.content_hash()
    g = quaternion_dataset(c, 300, np.random.default_rng(123), twist=True)
    np.testing.assert_array_equal(a.inputs, g.inputs)
    assert a.meta["seed"] == 123 and g.meta["seed"] is None
    rng = np.random.default_rng()
    rng.bit_generator.state = g.meta["rng_state"]  # the recorded state regenerates it
    np.testing.assert_array_equal(quaternion_dataset(c, 300, rng, twist=True).inputs, a.inputs)
    other = quaternion_dataset(c, 300, 124, twist=True)
    assert not np.array_equal(a.inputs, other.inputs)
    assert interval_dataset(50, 1).content_hash() == interval_dataset(50, 1).content_hash()


def test_meta_records_the_request():
    c = load_shape("small")
    ds = quaternion_dataset(c, 100, 5, distribution="clustered", order="random")
    m = ds.meta
    assert m["kind"] == "quaternion" and m["constraint_name"] == "small"
    assert m["generator"]["distribution"] == "clustered" and m["generator"]["order"] == "random"
    assert m["created_by"].startswith("jointlimits-rig")
    assert m["region_names"] == list(REGION_NAMES)
    assert ds.constraint() == c
    json.dumps(m)


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"n": 0}, "n"),
        ({"n": -5}, "n"),
        ({"n": 2.5}, "n"),
        ({"distribution": "gaussian"}, "distribution"),
        ({"order": "sorted"}, "order"),
        ({"hemisphere": "north"}, "hemisphere"),
        ({"band_deg": 0}, "band_deg"),
        ({"band_deg": 120}, "band_deg"),
        ({"rng": "seed"}, "rng"),
        ({"constraint": "cone.yaml"}, "constraint"),
    ],
)
def test_bad_requests_name_the_argument(kwargs, word):
    args = {"constraint": cone_constraint((1, 0, 0), 30), "n": 10, "rng": 0}
    args.update(kwargs)
    c, n, rng = args.pop("constraint"), args.pop("n"), args.pop("rng")
    with pytest.raises(DatasetError, match=f"^{word}"):
        quaternion_dataset(c, n, rng, **args)


@pytest.mark.parametrize("radius", [0, 180, 200, -3, float("nan")])
def test_cone_radius_out_of_range(radius):
    with pytest.raises(DatasetError, match="radius_deg"):
        cone_constraint((1, 0, 0), radius)
    with pytest.raises(DatasetError, match="radius_deg"):
        sphere_vector_dataset(10, 0, (1, 0, 0), radius)


def test_common_test_set():
    ds = common_test_set(cone_constraint((1, 0, 0), 90), 11)
    assert len(ds) == 3000 and ds.meta["role"] == "common-test"
    assert list(np.bincount(ds.regions)) == [750] * 4


# -- chapter 3 ---------------------------------------------------------------------------------
def test_interval_eq_45_47():
    ds = interval_dataset(2000, 1, lower=-0.3, upper=0.6)
    p, c = ds.inputs[:, 0], ds.targets[:, 0]
    valid = (p > -0.3) & (p < 0.6)  # eq. 45
    np.testing.assert_array_equal(ds.valid, valid)
    np.testing.assert_array_equal(c[valid], 0.0)
    below, above = p <= -0.3, p >= 0.6
    np.testing.assert_allclose(c[below], -0.3 - p[below])  # eq. 46
    np.testing.assert_allclose(p[above] + c[above], 0.6)  # moved to the nearer bound
    np.testing.assert_allclose((p + c)[~valid], np.where(below, -0.3, 0.6)[~valid])
    thesis = interval_dataset(2000, 1, lower=-0.3, upper=0.6, convention="thesis")
    np.testing.assert_allclose(thesis.targets[above, 0], p[above] - 0.6)  # eq. 47 as printed
    assert p.min() >= -1 and p.max() <= 1
    with pytest.raises(DatasetError, match=r"^lower"):
        interval_dataset(10, 0, lower=0.5, upper=0.2)
    with pytest.raises(DatasetError, match=r"^convention"):
        interval_dataset(10, 0, convention="other")


@pytest.mark.parametrize("dim", [2, 3])
def test_ball_eq_48_49(dim):
    r = 0.7
    ds = ball_dataset(3000, 2, dim=dim, radius=r)
    v, c = ds.inputs, ds.targets
    assert v.shape == (3000, dim) and np.abs(v).max() <= 1.0
    norm = np.linalg.norm(v, axis=1)
    invalid = norm > r  # eq. 48
    np.testing.assert_array_equal(~ds.valid, invalid)
    np.testing.assert_allclose(c[invalid], -v[invalid] * (1 - r / norm[invalid])[:, None])
    np.testing.assert_allclose(np.linalg.norm(v + c, axis=1)[invalid], r)
    np.testing.assert_array_equal(c[~invalid], 0.0)
    with pytest.raises(DatasetError, match=r"^dim"):
        ball_dataset(10, 0, dim=4)
    with pytest.raises(DatasetError, match=r"^radius"):
        ball_dataset(10, 0, dim=dim, radius=0)


def test_sphere_datasets_eq_50_56():
    centre, r = np.array([0.0, 0.0, 1.0]), math.radians(35.0)
    vec = sphere_vector_dataset(1500, 3, centre, 35.0)
    quat = sphere_quaternion_dataset(1500, 3, centre, 35.0)
    v = vec.inputs
    np.testing.assert_array_equal(v, quat.inputs)
    theta = np.arccos(np.clip(v @ centre, -1, 1))  # eq. 50
    invalid = theta > r  # eq. 51
    np.testing.assert_array_equal(~vec.valid, invalid)
    axis = np.cross(v[invalid], centre)  # eq. 54
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    qo = Q.from_axis_angle(axis, theta[invalid] - r)  # eq. 53, 55
    np.testing.assert_allclose(quat.targets[invalid], qo, atol=1e-9)
    np.testing.assert_array_equal(
        quat.targets[~invalid], np.tile(Q.IDENTITY, ((~invalid).sum(), 1))
    )
    moved = Q.rotate(qo, v[invalid])
    np.testing.assert_allclose(vec.targets[invalid], moved - v[invalid], atol=1e-9)  # eq. 56
    np.testing.assert_array_equal(vec.targets[~invalid], 0.0)
    np.testing.assert_allclose(Q.angle_between(moved, centre), r, atol=1e-9)


# -- splits ------------------------------------------------------------------------------------
def test_split_is_stratified_and_keeps_the_order():
    ds = quaternion_dataset(load_shape("original"), 1000, 12)
    train, val, test = split_dataset(ds, (0.7, 0.15, 0.15), 3)
    assert [p.meta["split"] for p in (train, val, test)] == ["train", "validation", "test"]
    assert len(train) + len(val) + len(test) == 1000
    assert list(np.bincount(train.regions)) == [175] * 4
    for part in (train, val, test):
        assert np.all(np.diff(part.valid.astype(int)) <= 0)  # valid-first still holds
    rows = {tuple(r) for p in (train, val, test) for r in p.inputs}
    assert rows == {tuple(r) for r in ds.inputs}
    again = split_dataset(ds, (0.7, 0.15, 0.15), 3)
    np.testing.assert_array_equal(again[1].inputs, val.inputs)
    for bad in [(0.5, 0.6), (1.2, -0.2), ("a",)]:
        with pytest.raises(DatasetError, match=r"^fractions"):
            split_dataset(ds, bad, 0)


def test_split_without_regions():
    ds = Dataset(np.arange(10.0)[:, None], np.zeros((10, 1)), {"kind": "test"})
    a, b = split_dataset(ds, (0.5, 0.5), 0)
    assert len(a) == len(b) == 5 and a.meta["split"] == "part-0"


# -- storage -----------------------------------------------------------------------------------
def test_save_load_round_trip(tmp_path):
    ds = quaternion_dataset(load_shape("large"), 200, 13, twist=True)
    path = ds.save(tmp_path / "large.npz")
    back = load_dataset(path)
    np.testing.assert_array_equal(back.inputs, ds.inputs)
    np.testing.assert_array_equal(back.targets, ds.targets)
    np.testing.assert_array_equal(back.regions, ds.regions)
    assert back.regions.dtype == np.int8 and back.inputs.dtype == np.float64
    assert back.meta == ds.meta
    assert back.content_hash() == ds.content_hash()
    plain = Dataset(np.ones((3, 2)), np.zeros((3, 1)), {"kind": "x", "v": np.float32(0.5)})
    odd = plain.save(tmp_path / "plain.data")  # suffix kept as given
    assert odd.name == "plain.data"
    again = load_dataset(odd)
    assert again.regions is None and again.meta == {"kind": "x", "v": 0.5}


def _rewrite(path, **arrays):
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def test_corrupt_and_wrong_files_are_named(tmp_path):
    ds = interval_dataset(100, 1)
    good = ds.save(tmp_path / "good.npz")
    cases = {}
    cases["missing.npz"] = None
    p = tmp_path / "truncated.npz"
    p.write_bytes(good.read_bytes()[:200])
    cases[p.name] = "damaged|not a dataset"
    p = tmp_path / "text.npz"
    p.write_text("inputs,targets\n1,2\n")
    cases[p.name] = "not a dataset file"
    p = tmp_path / "empty.npz"
    p.write_bytes(b"")
    cases[p.name] = "empty"
    p = tmp_path / "norecord.npz"
    _rewrite(p, inputs=ds.inputs, targets=ds.targets)
    cases[p.name] = "missing array 'record'"
    with np.load(good) as z:
        record = json.loads(str(z["record"]))
    p = tmp_path / "pickled.npz"
    _rewrite(
        p,
        record=np.array(json.dumps(record)),
        inputs=np.array([{"a": 1}], dtype=object),
        targets=ds.targets,
    )
    cases[p.name] = "pickled"
    p = tmp_path / "altered.npz"
    _rewrite(
        p,
        record=np.array(json.dumps(record)),
        inputs=ds.inputs + 1e-9,
        targets=ds.targets,
        regions=ds.regions,
    )
    cases[p.name] = "hash mismatch"
    p = tmp_path / "format.npz"
    _rewrite(
        p,
        record=np.array(json.dumps({**record, "format": "other"})),
        inputs=ds.inputs,
        targets=ds.targets,
    )
    cases[p.name] = "format is 'other'"
    p = tmp_path / "version.npz"
    _rewrite(
        p,
        record=np.array(json.dumps({**record, "format_version": 99})),
        inputs=ds.inputs,
        targets=ds.targets,
    )
    cases[p.name] = "format_version 99"
    p = tmp_path / "json.npz"
    _rewrite(p, record=np.array("{not json"), inputs=ds.inputs, targets=ds.targets)
    cases[p.name] = "not valid JSON"
    p = tmp_path / "shape.npz"
    _rewrite(p, record=np.array(json.dumps(record)), inputs=ds.inputs[:5], targets=ds.targets)
    cases[p.name] = "rows"
    p = tmp_path / "crc.npz"
    raw = bytearray(good.read_bytes())
    raw[len(raw) // 3] ^= 0xFF  # flip a byte inside compressed data
    p.write_bytes(bytes(raw))
    cases[p.name] = "damaged|hash mismatch|not a dataset|not valid JSON"
    for name, what in cases.items():
        with pytest.raises(DatasetError) as err:
            load_dataset(tmp_path / name)
        msg = str(err.value)
        assert msg.startswith(str(tmp_path / name)), msg
        assert "\n" not in msg
        if what:
            assert re.search(what, msg), msg
        else:
            assert "not found" in msg
    with pytest.raises(DatasetError, match="directory"):
        load_dataset(tmp_path)
    assert zipfile.is_zipfile(good)


def test_save_to_a_missing_folder_names_the_file(tmp_path):
    target = tmp_path / "no" / "such" / "d.npz"
    with pytest.raises(DatasetError, match=re.escape(str(target))):
        interval_dataset(5, 0).save(target)


def test_dataset_validation():
    with pytest.raises(DatasetError, match="targets"):
        Dataset(np.zeros((3, 4)), np.zeros((2, 4)))
    with pytest.raises(DatasetError, match="regions"):
        Dataset(np.zeros((3, 4)), np.zeros((3, 4)), regions=np.array([0, 1, 4]))
    with pytest.raises(DatasetError, match="inputs"):
        Dataset(np.zeros(3), np.zeros((3, 4)))
    with pytest.raises(DatasetError, match=r"inputs\[1\]"):
        Dataset(np.array([[0.0], [np.nan]]), np.zeros((2, 1)))
    with pytest.raises(DatasetError, match="meta"):
        Dataset(np.zeros((1, 1)), np.zeros((1, 1)), {"f": object()})
