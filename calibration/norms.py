"""Published range-of-motion norms by joint, movement, sex and age band: one cited table.

The table is ``calibration/norms.yaml`` (:data:`NORMS`, read once with the project's safe YAML
reader, :func:`models.yamlio.safe_load_yaml`). Each row is one published value — a mean (or a
median) of one sex in one age band, or over all the source's ages (its *overall* value) — with
its source (authors, journal, year), the measurement method (active or passive, instrument,
position) and where the number was read (table cell, page or note). :func:`load_norms` refuses
an unknown key, joint, movement, sex or source, a band whose ends are not whole years in
order, two bands of one source, joint, movement and sex that overlap, and a mean outside its
95 % confidence interval, with the file and row named.

Sources (``norms.yaml`` ``sources``):

- Soucie JM et al. Range of motion measurements: reference values and a database for
  comparison studies. *Haemophilia* 2011;17(3):500-507: 674 healthy people aged 2-69, passive
  motion, universal goniometer; shoulder flexion, elbow flexion and extension, forearm
  pronation and supination, hip flexion and extension, knee flexion and extension, ankle
  dorsiflexion and plantarflexion, by sex and age group (2-8, 9-19, 20-44, 45-69).
- Gill TK et al. Shoulder range of movement in the general population. *BMC Musculoskelet
  Disord* 2020;21:676: 2404 adults, active, inclinometer; means by sex, medians by 5-year band.
- Boone DC, Azen SP. *J Bone Joint Surg Am* 1979;61:756-759 (109 men, 1-54, active,
  goniometer) and Macedo LG, Magee DJ. *J Manipulative Physiol Ther* 2008;31:577-582 (90 women,
  18-59, goniometer): elbow, forearm and wrist, one band per sex.
- Walker JM et al. Active mobility of the extremities in older subjects. *Phys Ther*
  1984;64:919-923 (60 people aged 60-69 and 75-84, active, goniometer): elbow, forearm and
  wrist, one value for both sexes.

Choosing the band (:func:`norm_band`)
-------------------------------------
Per sex (women then men when the sex is unknown), the first of the given sources whose band
contains the age; failing that, the first with a fallback value, as below (a source that
publishes no value of that sex gives its value for both sexes together, if any, listed once):

- **age known**: the band containing the age in whole years (44.9 is in 20-44); past the
  oldest band, the oldest when it is an adult band (``age_hi ≥ 18``); otherwise the source's
  overall value for that sex; otherwise none (a child below a source's youngest band gets no
  adult value);
- **age unknown**: the overall value; a source without one gives the band containing an adult
  of ``unknown_age`` years (:data:`UNKNOWN_AGE`, 30; the text names the band, so the choice
  shows), or nothing when ``unknown_age`` is None.

The report's population column uses the sources :data:`REPORT_SOURCES` names per joint
(``norms.yaml`` ``report``); :func:`norms_for` lists every row of a joint and movement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from models.yamlio import safe_load_yaml

__all__ = ["JOINT_MOVEMENTS", "NORMS", "NORMS_PATH", "REPORT_SOURCES", "SEXES", "UNKNOWN_AGE",
           "Norm", "NormSource", "NormTable", "load_norms", "norm_band", "norm_text", "norms_for"]

NORMS_PATH = Path(__file__).with_name("norms.yaml")

#: The movements a norm may be given for, per joint (the clinical movements the reports show:
#: the one list, which :data:`calibration.clinical.RangeOfMotion.MOVEMENTS` and
#: :data:`calibration.joint_angles.CLINICAL_MOVEMENTS` are made from; pronation and
#: supination are the forearm's, listed under the elbow as the reports list them).
JOINT_MOVEMENTS: dict[str, tuple[str, ...]] = {
    "shoulder": ("flexion", "extension", "abduction", "adduction", "horizontal_adduction",
                 "internal_rotation", "external_rotation"),
    "elbow": ("flexion", "extension", "pronation", "supination"),
    "wrist": ("flexion", "extension", "radial_deviation", "ulnar_deviation"),
    "hip": ("flexion", "extension", "abduction", "adduction", "internal_rotation",
            "external_rotation"),
    "knee": ("flexion", "extension"),
    "ankle": ("dorsiflexion", "plantarflexion", "inversion", "eversion"),
}

SEXES = ("female", "male")

#: With the age unknown and no overall value published, the band containing an adult of this
#: age (years) is shown.
UNKNOWN_AGE = 30

_TOP_KEYS = {"sources", "where", "norms", "report"}
_SOURCE_KEYS = {"cite", "reference", "method", "ages", "n"}
_ROW_KEYS = {"joint", "movement", "source", "sex", "age", "stat", "value", "sd", "ci95", "where",
             "bands5"}
_STATS = ("mean", "median")


@dataclass(frozen=True)
class NormSource:
    """One publication: its key, short and full citation, how it measured, its sample."""

    key: str
    cite: str
    reference: str
    method: str
    ages: tuple[int, int]
    n: int


@dataclass(frozen=True)
class Norm:
    """One published value (degrees): ``stat`` (mean or median) of one sex (``"both"``: one
    value for women and men together) in one age band (years, inclusive; both None for the
    source's overall value), its sd and 95 % CI where published, its source and where it was
    read."""

    joint: str
    movement: str
    sex: str
    age_lo: int | None
    age_hi: int | None
    value: float
    source: NormSource
    where: str
    stat: str = "mean"
    sd: float | None = None
    ci95: tuple[float, float] | None = None

    @property
    def overall(self) -> bool:
        """True for the source's value over all its ages (no band)."""
        return self.age_lo is None

    @property
    def band(self) -> str:
        """The band as text: ``"20-44"``, or ``"all ages"``."""
        return "all ages" if self.overall else f"{self.age_lo}-{self.age_hi}"

    def contains(self, years: int) -> bool:
        """Whether an age in whole years falls in the band (never for an overall value)."""
        return not self.overall and self.age_lo <= years <= self.age_hi

    def to_json(self) -> dict:
        """Plain types: joint, movement, sex, age band (None: all ages), stat, value, sd, ci95,
        source (key), cite, method, where."""
        return {"joint": self.joint, "movement": self.movement, "sex": self.sex,
                "age": None if self.overall else [self.age_lo, self.age_hi],
                "stat": self.stat, "value": self.value, "sd": self.sd,
                "ci95": None if self.ci95 is None else list(self.ci95),
                "source": self.source.key, "cite": self.source.cite,
                "method": self.source.method, "where": self.where}


@dataclass(frozen=True)
class NormTable:
    """The loaded table: sources by key, rows, and the report's sources per joint."""

    sources: dict[str, NormSource]
    rows: tuple[Norm, ...]
    report: dict[str, tuple[str, ...]]


def _fail(path, where: str, what: str):
    raise ValueError(f"{path}: {where}: {what}")


def _keys(path, where: str, got: dict, allowed: set, required: set) -> None:
    if not isinstance(got, dict):
        _fail(path, where, f"expected a mapping, got {type(got).__name__}")
    unknown = sorted(set(got) - allowed)
    if unknown:
        _fail(path, where, f"unknown key(s) {', '.join(unknown)} (allowed: "
                           f"{', '.join(sorted(allowed))})")
    missing = sorted(required - set(got))
    if missing:
        _fail(path, where, f"missing key(s) {', '.join(missing)}")


def _number(path, where: str, v, name: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        _fail(path, where, f"{name} must be a finite number, got {v!r}")
    return float(v)


def _years(path, where: str, v, name: str) -> tuple[int, int]:
    if (not isinstance(v, list) or len(v) != 2
            or not all(isinstance(x, int) and not isinstance(x, bool) for x in v)
            or not 0 <= v[0] <= v[1] < 150):
        _fail(path, where, f"{name} must be [lo, hi] whole years, 0 <= lo <= hi < 150, "
                           f"got {v!r}")
    return int(v[0]), int(v[1])


def _source(path, key: str, d) -> NormSource:
    where = f"source {key!r}"
    _keys(path, where, d, _SOURCE_KEYS, _SOURCE_KEYS)
    for k in ("cite", "reference", "method"):
        if not isinstance(d[k], str) or not d[k].strip():
            _fail(path, where, f"{k} must be a non-empty string")
    if not isinstance(d["n"], int) or isinstance(d["n"], bool) or d["n"] <= 0:
        _fail(path, where, f"n must be a positive whole number, got {d['n']!r}")
    return NormSource(key, d["cite"].strip(), " ".join(d["reference"].split()),
                      " ".join(d["method"].split()), _years(path, where, d["ages"], "ages"),
                      d["n"])


def _rows(path, i: int, d, sources: dict[str, NormSource], wheres: dict[str, str]) -> list[Norm]:
    where = f"norms[{i}]"
    _keys(path, where, d, _ROW_KEYS, {"joint", "movement", "source", "sex", "where"})
    joint, movement = d["joint"], d["movement"]
    if joint not in JOINT_MOVEMENTS:
        _fail(path, where, f"joint must be one of {', '.join(JOINT_MOVEMENTS)}, got {joint!r}")
    if movement not in JOINT_MOVEMENTS[joint]:
        _fail(path, where, f"movement of the {joint} must be one of "
                           f"{', '.join(JOINT_MOVEMENTS[joint])}, got {movement!r}")
    if d["source"] not in sources:
        _fail(path, where, f"source {d['source']!r} is not among the sources "
                           f"({', '.join(sources)})")
    if d["sex"] not in (*SEXES, "both"):
        _fail(path, where, f"sex must be 'female', 'male' or 'both', got {d['sex']!r}")
    if d["where"] not in wheres:
        _fail(path, where, f"where {d['where']!r} is not among the 'where' entries")
    stat = d.get("stat", "mean")
    if stat not in _STATS:
        _fail(path, where, f"stat must be one of {', '.join(_STATS)}, got {stat!r}")
    sd = None if d.get("sd") is None else _number(path, where, d["sd"], "sd")
    ci = None
    if d.get("ci95") is not None:
        c = d["ci95"]
        if not isinstance(c, list) or len(c) != 2:
            _fail(path, where, f"ci95 must be [lo, hi], got {c!r}")
        ci = (_number(path, where, c[0], "ci95"), _number(path, where, c[1], "ci95"))
    common = {"joint": joint, "movement": movement, "sex": d["sex"],
              "source": sources[d["source"]], "where": wheres[d["where"]], "stat": stat,
              "sd": sd, "ci95": ci}
    if "bands5" in d:  # consecutive 5-year bands: [[age_lo, value], ...]
        if "value" in d or "age" in d or ci is not None:
            _fail(path, where, "bands5 replaces age, value and ci95")
        out = []
        for lo_v in d["bands5"]:
            if not isinstance(lo_v, list) or len(lo_v) != 2:
                _fail(path, where, f"bands5 entries must be [age_lo, value], got {lo_v!r}")
            lo, _ = _years(path, where, [lo_v[0], lo_v[0] + 4], "bands5 age")
            out.append(Norm(age_lo=lo, age_hi=lo + 4,
                            value=_number(path, where, lo_v[1], "value"), **common))
        return out
    if "value" not in d:
        _fail(path, where, "missing key(s) value")
    value = _number(path, where, d["value"], "value")
    if ci is not None and not ci[0] <= value <= ci[1]:
        _fail(path, where, f"the value {value} lies outside its ci95 {list(ci)}")
    lo = hi = None
    if d.get("age") is not None:
        lo, hi = _years(path, where, d["age"], "age")
    return [Norm(age_lo=lo, age_hi=hi, value=value, **common)]


def load_norms(path: str | Path = NORMS_PATH) -> NormTable:
    """Read and validate a norms table (module doc); ValueError naming the file and row."""
    path = Path(path)
    data = safe_load_yaml(path.read_text(encoding="utf-8"))
    _keys(path, "top level", data, _TOP_KEYS, _TOP_KEYS)
    if not isinstance(data["where"], dict) or not all(
            isinstance(v, str) for v in data["where"].values()):
        _fail(path, "where", "expected a mapping of names to text")
    wheres = {k: " ".join(v.split()) for k, v in data["where"].items()}
    if not isinstance(data["sources"], dict):
        _fail(path, "sources", "expected a mapping")
    sources = {k: _source(path, k, v) for k, v in data["sources"].items()}
    if not isinstance(data["norms"], list):
        _fail(path, "norms", "expected a list")
    rows: list[Norm] = []
    for i, d in enumerate(data["norms"]):
        rows += _rows(path, i, d, sources, wheres)
    seen: dict[tuple, list[Norm]] = {}
    for r in rows:
        key = (r.source.key, r.joint, r.movement, r.sex)
        for o in seen.setdefault(key, []):
            clash = (r.overall and o.overall) or (
                not r.overall and not o.overall and r.age_lo <= o.age_hi and o.age_lo <= r.age_hi)
            if clash:
                _fail(path, f"{r.joint} {r.movement} ({r.sex}, {r.source.key})",
                      f"bands {o.band} and {r.band} overlap")
        seen[key].append(r)
    report = data["report"]
    if not isinstance(report, dict):
        _fail(path, "report", "expected a mapping of joint to sources")
    for joint, keys in report.items():
        if joint not in JOINT_MOVEMENTS:
            _fail(path, "report", f"joint must be one of {', '.join(JOINT_MOVEMENTS)}, "
                                  f"got {joint!r}")
        if not isinstance(keys, list) or not all(k in sources for k in keys):
            _fail(path, f"report {joint!r}", f"expected a list of sources, got {keys!r}")
    return NormTable(sources, tuple(rows), {j: tuple(k) for j, k in report.items()})


#: The table, loaded once from ``calibration/norms.yaml``.
NORMS: NormTable = load_norms()

#: The sources of the report's population column per joint (``norms.yaml`` ``report``).
REPORT_SOURCES: dict[str, tuple[str, ...]] = dict(NORMS.report)


def _check(joint: str, movement: str, age, sex) -> None:
    if joint not in JOINT_MOVEMENTS:
        raise ValueError(f"joint must be one of {', '.join(JOINT_MOVEMENTS)}, got {joint!r}")
    if movement not in JOINT_MOVEMENTS[joint]:
        raise ValueError(f"movement of the {joint} must be one of "
                         f"{', '.join(JOINT_MOVEMENTS[joint])}, got {movement!r}")
    if sex is not None and sex not in SEXES:
        raise ValueError(f"sex must be 'male' or 'female', got {sex!r}")
    if age is not None and (isinstance(age, bool) or not isinstance(age, int | float)
                            or not 0 <= age < 150):
        raise ValueError(f"age must be years (0-149), got {age!r}")


def norms_for(joint: str, movement: str, *, table: NormTable = NORMS) -> list[Norm]:
    """Every row of one joint and movement, in table order (all sources, sexes and bands)."""
    _check(joint, movement, None, None)
    return [r for r in table.rows if r.joint == joint and r.movement == movement]


def _pick(rows: list[Norm], age, unknown_age: int | None, *, exact: bool) -> Norm | None:
    """One source's value for one sex (module doc); ``exact``: only a band containing the age."""
    bands = sorted((r for r in rows if not r.overall), key=lambda r: r.age_lo)
    overall = next((r for r in rows if r.overall), None)
    if age is None:
        if overall is not None or unknown_age is None:
            return overall
        years = unknown_age
    else:
        years = math.floor(age)
    hit = next((r for r in bands if r.contains(years)), None)
    if exact:
        return hit
    if hit is None and bands and years > bands[-1].age_hi and bands[-1].age_hi >= 18:
        hit = bands[-1]
    if hit is None and age is not None:
        hit = overall
    return hit


def norm_band(joint: str, movement: str, *, age: float | None = None, sex: str | None = None,
              sources: tuple[str, ...] | list[str] | None = None,
              unknown_age: int | None = UNKNOWN_AGE, table: NormTable = NORMS) -> list[Norm]:
    """The published values that apply to a patient (module doc, "Choosing the band").

    Parameters
    ----------
    joint, movement : str
        As :data:`JOINT_MOVEMENTS`.
    age : float, optional
        Years; None when unknown.
    sex : "female" or "male", optional
        None when unknown: one value per sex, women first.
    sources : sequence of str, optional
        Source keys in order of preference; default the report's for the joint
        (:data:`REPORT_SOURCES`), else every source of the table.
    unknown_age : int or None
        With the age unknown and no overall value, the band containing this age (None: none).

    Returns
    -------
    list of :class:`Norm`, one per sex at most; empty when no published value applies.
    """
    _check(joint, movement, age, sex)
    if sources is None:
        sources = table.report.get(joint, tuple(table.sources))
    rows = norms_for(joint, movement, table=table)
    out: list[Norm] = []
    for sx in (sex,) if sex is not None else SEXES:
        hit = None
        for exact in (True, False):  # a band containing the age first, from any source
            for key in sources:
                mine = [r for r in rows if r.source.key == key and r.sex == sx]
                if not mine:  # the source's value for both sexes together, if any
                    mine = [r for r in rows if r.source.key == key and r.sex == "both"]
                hit = _pick(mine, age, unknown_age, exact=exact)
                if hit is not None:
                    break
            if hit is not None:
                break
        if hit is not None and hit not in out:  # one value for both sexes is listed once
            out.append(hit)
    return out


_WORD = {"female": "women", "male": "men", "both": "women and men"}


def norm_text(norms: list[Norm]) -> str | None:
    """The values as the report's population column shows them: ``"138 (women, 45-69)"``,
    women and men apart with " / "; None for no value."""
    parts = [f"{n.value:.0f} ({_WORD[n.sex]}, {n.band})" for n in norms]
    return " / ".join(parts) if parts else None
