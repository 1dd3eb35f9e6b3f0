"""The norms table (calibration/norms.yaml) and the band chooser (issue 42, item 4)."""

from __future__ import annotations

import pytest

from calibration.clinical import RangeOfMotion
from calibration.joint_angles import CLINICAL_MOVEMENTS, POPULATION
from calibration.joints import JOINTS
from calibration.norms import (
    JOINT_MOVEMENTS,
    NORMS,
    REPORT_SOURCES,
    load_norms,
    norm_band,
    norm_text,
    norms_for,
)


def test_every_joint_has_a_norm_source_and_every_row_its_source_and_method():
    assert set(JOINT_MOVEMENTS) == set(JOINTS)  # shoulder, elbow (and forearm), wrist, hip, ...
    assert JOINT_MOVEMENTS["shoulder"] == RangeOfMotion.MOVEMENTS
    for joint, movements in CLINICAL_MOVEMENTS.items():
        assert JOINT_MOVEMENTS[joint] == movements
    for joint in JOINT_MOVEMENTS:
        rows = [r for r in NORMS.rows if r.joint == joint]
        assert rows, joint
        assert REPORT_SOURCES[joint], joint
    # the arm's joints by age band and sex (Soucie 2011): shoulder, elbow, forearm
    for joint, movement in (("shoulder", "flexion"), ("elbow", "flexion"),
                            ("elbow", "pronation"), ("elbow", "supination")):
        bands = {(r.sex, r.band) for r in norms_for(joint, movement)
                 if r.source.key == "soucie2011"}
        assert {("female", "20-44"), ("male", "45-69")} <= bands, (joint, movement)
    for r in NORMS.rows:
        j = r.to_json()
        assert j["source"] and j["cite"] and j["method"] and j["where"]
        assert j["age"] is None or j["age"][0] <= j["age"][1]


def test_published_cells():
    def cell(joint, movement, source, sex, band):
        (r,) = [r for r in norms_for(joint, movement)
                if r.source.key == source and r.sex == sex and r.band == band]
        return r

    # CDC study page, "Age 2-8" table, hip flexion, females: 140.8 (139.2 - 142.4)
    r = cell("hip", "flexion", "soucie2011", "female", "2-8")
    assert (r.value, r.ci95) == (140.8, (139.2, 142.4))
    # Soucie 2011 45-69, knee flexion, males: 132.9 (131.6-134.2)
    r = cell("knee", "flexion", "soucie2011", "male", "45-69")
    assert (r.value, r.ci95) == (132.9, (131.6, 134.2))
    # Soucie 2011 45-69, supination, females: 87.2 (86.0-88.4); 20-44 shoulder flexion, men 168.8
    assert cell("elbow", "supination", "soucie2011", "female", "45-69").ci95 == (86.0, 88.4)
    assert cell("shoulder", "flexion", "soucie2011", "male", "20-44").value == 168.8
    # Gill 2020 abstract: abduction 149.7 (women); TABLE A.1: Boone & Azen ulnar deviation 36
    assert cell("shoulder", "abduction", "gill2020", "female", "all ages").value == 149.7
    assert cell("wrist", "ulnar_deviation", "boone1979", "male", "1-54").value == 36.0
    # Gill 2020 band medians: abduction, men 80-84: 132
    r = cell("shoulder", "abduction", "gill2020", "male", "80-84")
    assert (r.value, r.stat) == (132.0, "median")


@pytest.mark.parametrize("age, band", [
    (2, "2-8"), (8, "2-8"), (8.9, "2-8"), (9, None), (19, None), (20, "20-44"), (44, "20-44"),
    (44.9, "20-44"), (45, "45-69"), (69, "45-69"), (70, "45-69"), (101, "45-69"), (1, None)])
def test_band_edges_soucie(age, band):
    got = norm_band("knee", "flexion", age=age, sex="female")
    assert (got[0].band if got else None) == band


def test_band_edges_gill_and_sex():
    def band(age, sex="male", movement="abduction"):
        got = norm_band("shoulder", movement, age=age, sex=sex)
        return [(r.sex, r.band, r.value) for r in got]

    assert band(24) == [("male", "20-24", 164.0)]
    assert band(25) == [("male", "25-29", 160.0)]
    assert band(84.5) == [("male", "80-84", 132.0)]
    assert band(90) == [("male", "80-84", 132.0)]  # past the oldest band: the oldest
    assert band(19) == [("male", "all ages", 151.5)]  # below the youngest band: the overall
    assert band(19, movement="external_rotation") == []  # no overall value published
    assert band(47, sex=None) == [("female", "45-49", 152.0), ("male", "45-49", 156.0)]
    # elbow: one source per sex (Macedo & Magee women 18-59, Boone & Azen men 1-54)
    assert [(r.source.key, r.band) for r in norm_band("elbow", "flexion", age=10)] == [
        ("boone1979", "1-54")]


def test_without_age_or_sex_the_overall_value():
    got = norm_band("shoulder", "flexion")
    assert [(r.sex, r.band, r.value) for r in got] == [("female", "all ages", 158.5),
                                                        ("male", "all ages", 161.5)]
    assert norm_text(got) == "158 (women, all ages) / 162 (men, all ages)"
    assert norm_text(norm_band("shoulder", "flexion", sex="male")) == "162 (men, all ages)"
    # no overall value published: the band of an adult of 30 (named), or none when asked
    assert norm_text(norm_band("hip", "extension")) == "18 (women, 20-44) / 17 (men, 20-44)"
    assert norm_band("hip", "extension", unknown_age=None) == []
    # the elbow's Soucie bands, asked by source
    assert norm_text(norm_band("elbow", "pronation", age=50, sources=["soucie2011"])) == \
        "81 (women, 45-69) / 78 (men, 45-69)"
    assert norm_band("knee", "extension", age=30) == []


def test_report_column_is_the_table():
    for joint, src in POPULATION.items():
        keys = REPORT_SOURCES[joint]
        for movement, values in src["movements"].items():
            rows = [r for r in norms_for(joint, movement) if r.source.key in keys]
            assert sorted((v.sex, v.age_lo, v.mean) for v in values) == \
                sorted((r.sex, r.age_lo, r.value) for r in rows)


def test_bad_arguments():
    with pytest.raises(ValueError, match="joint must be one of"):
        norm_band("neck", "flexion")
    with pytest.raises(ValueError, match="movement of the knee"):
        norm_band("knee", "abduction")
    with pytest.raises(ValueError, match="sex must be"):
        norm_band("knee", "flexion", sex="f")
    with pytest.raises(ValueError, match="age must be"):
        norm_band("knee", "flexion", age=-1)


_MINIMAL = """\
sources:
  s:
    cite: "A 2000"
    reference: "A. Title. J 2000;1:1"
    method: "passive, goniometer"
    ages: [20, 60]
    n: 10
where:
  w: "table 1"
norms:
  - {joint: knee, movement: flexion, source: s, sex: male, age: [20, 39], value: 140.0, where: w}
  - {joint: knee, movement: flexion, source: s, sex: male, age: [40, 60], value: 135.0, where: w}
report:
  knee: [s]
"""


@pytest.mark.parametrize("change, message", [
    (("ages: [20, 60]", "ages: [20, 60]\n    doi: x"), "unknown key"),
    (("value: 140.0,", "value: 140.0, mean: 1,"), "unknown key"),
    (("report:", "extra: 1\nreport:"), "unknown key"),
    (("age: [40, 60]", "age: [39, 60]"), "overlap"),
    (("value: 140.0,", "value: 140.0, ci95: [141, 150],"), "outside its ci95"),
    (("source: s, sex: male, age: [20", "source: t, sex: male, age: [20"), "not among the sources"),
    (("movement: flexion, source: s, sex: male, age: [20",
      "movement: pronation, source: s, sex: male, age: [20"), "movement of the knee"),
    (("sex: male, age: [20", "sex: M, age: [20"), "sex must be"),
    (("age: [20, 39]", "age: [39, 20]"), "whole years"),
    (("value: 140.0,", "value: high,"), "finite number"),
    (("where: w}\n  - {joint: knee, movement: flexion, source: s, sex: male, age: [40",
      "where: x}\n  - {joint: knee, movement: flexion, source: s, sex: male, age: [40"),
     "'where' entries"),
])
def test_load_refuses(tmp_path, change, message):
    path = tmp_path / "norms.yaml"
    path.write_text(_MINIMAL, encoding="utf-8")
    table = load_norms(path)
    assert [r.band for r in table.rows] == ["20-39", "40-60"]
    old, new = change
    assert old in _MINIMAL
    path.write_text(_MINIMAL.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(ValueError, match=message) as err:
        load_norms(path)
    assert str(path) in str(err.value)


def test_both_sexes_and_a_band_containing_the_age_first():
    arm = ["macedo2008", "boone1979", "walker1984"]
    # 70: no sex-specific band contains it; Walker 1984's both-sexes 60-84 does, listed once
    got = norm_band("wrist", "flexion", age=70, sources=arm)
    assert [(r.sex, r.band, r.value) for r in got] == [("both", "60-84", 64.0)]
    assert norm_text(got) == "64 (women and men, 60-84)"
    assert norm_text(norm_band("wrist", "flexion", age=40, sources=arm)) == \
        "93 (women, 18-59) / 76 (men, 1-54)"
    # past every band: the oldest of the first source with a fallback (Macedo 18-59, women)
    assert norm_text(norm_band("wrist", "flexion", age=90, sex="female", sources=arm)) == \
        "93 (women, 18-59)"
    # TABLE A.1, Walker et al: extension "4†" is a limitation, kept negative
    (r,) = [r for r in norms_for("elbow", "extension") if r.source.key == "walker1984"]
    assert r.value == -4.0
