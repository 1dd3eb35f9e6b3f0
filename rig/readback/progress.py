"""``rig progress`` as a library: one patient's range of motion across visits, and whether each
change exceeds what the measurement can resolve.

For a patient in a store, every recording session (a *visit*) is listed with its date, joint
(a whole-limb session: each of its joints), side, measurement method (``imu``, ``servo``,
``file``: :data:`calibration.mdc.METHODS`), coverage and whether it was cut short. Each
joint's range of motion per visit is :func:`rig.readback.rom.run_rom`'s (the same service as
``rig rom --db --session``). Per joint, side and movement, the change since the first and since
the previous *usable* visit is compared with the minimal detectable change of that joint,
movement and method (:func:`calibration.mdc.mdc_for`, :func:`calibration.mdc.verdict`).

A visit is *usable as evidence* when it ended normally (not interrupted, not still being
recorded) and its coverage was sufficient where the joint has a swing sphere to cover
(:class:`~rig.readback.data.RecordingFacts`); the others are listed, marked with the reason,
and never used as a reference or a point of change. Two visits measured by different methods
are compared without an MDC verdict (the published values are per method).

**Cost per patient, not per database.** Sessions are selected by the patient's pseudonym (an
indexed join); each visit's range of motion is computed once from its samples and kept in the
session's metadata (``meta["rom_cache"]``, keyed by :data:`ROM_CACHE_VERSION` and the rig's
version), so a later call reads one row per visit. Only ended sessions are cached (a running
session's samples may still grow), and nothing is written to a read-only store.

**Couplings.** A whole-limb session with a stored limb boundary (``rig boundary --limb``) has
coupled limits: per visit, each coupled joint's range of motion at each keyframe angle of the
joint it depends on (:func:`coupled_limits`), so visits compare at the same coupling angles.
A whole-limb session's visits also carry the named coupled clinical tests (straight-leg raise,
popliteal angle, Silfverskiöld, Thomas test, the shoulder's reach with the elbow straight vs
bent: :func:`coupled_tests_of`, cached with the visit's range of motion), each under the joint
its definition names, with a value or "not reached in this recording".

**Norms for the patient.** Given the patient's age and/or sex (``rig progress --age --sex``,
``rig report --age --sex``), each movement's series carries the published norm for them
(:func:`norms_of`: :func:`calibration.norms.norm_band` from the report's sources for the
joint — Soucie et al. 2011 for the hip, knee and ankle, Gill et al. 2020 for the shoulder,
Boone & Azen 1979 and Macedo & Magee 2008 for the elbow and wrist), with its source and
measurement method; a movement no source publishes has none.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Any

from calibration.clinical import RangeOfMotion
from calibration.clinical_tests import MEASURES
from calibration.joint_angles import CLINICAL_MOVEMENTS, allowed_rom
from calibration.joints import LIMB_CHAINS
from calibration.mdc import METHODS, MdcValue, mdc_for, verdict
from calibration.norms import JOINT_MOVEMENTS, SEXES, Norm, norm_band, norm_text
from models.limb import loads_limb
from rig import __version__
from rig.errors import RigConfigError
from rig.readback.data import CUT_SHORT
from rig.readback.rom import RomRequest, run_rom, session_coupled_tests
from rig.readback.source import RecordingSource, check_joint
from rig.store import open_store

__all__ = ["ROM_CACHE_VERSION", "ProgressRequest", "ProgressResult", "Visit",
           "coupled_limits", "coupled_test_rows", "coupled_tests_of", "merged_progress",
           "movements_of", "norm_words", "norms_of", "run_progress", "sessions_of"]

#: Bumped when what the cache holds, or how a visit's range of motion is computed, changes;
#: a cached entry of another version (or another rig version) is recomputed.
ROM_CACHE_VERSION = 2  # 2: coupled tests of uncoupled limits read the recording


def movements_of(joint: str) -> tuple[str, ...]:
    """The clinical movements reported for ``joint`` (the shoulder's from its boundary)."""
    return RangeOfMotion.MOVEMENTS if joint == "shoulder" else CLINICAL_MOVEMENTS[joint]


def coupled_tests_of(store, sess: dict, entry: dict) -> dict[str, list[dict]]:
    """The named coupled clinical tests of a whole-limb session (straight-leg raise, popliteal
    angle, Silfverskiöld, Thomas test, the shoulder's reach with the elbow straight vs bent:
    :func:`rig.readback.rom.session_coupled_tests`), by the joint each measures: joint → the
    tests' JSON (``measure``, ``value``, ``status`` — "not reached in this recording" where the
    session never came to the test position —, norm, source, ...). Cached in the session's
    ROM cache ``entry`` (key ``coupled_tests``); empty for a session of one joint or one whose
    postures cannot be read."""
    got = entry.get("coupled_tests")
    if got is not None:
        return got
    got: dict[str, list[dict]] = {}
    try:
        for m in session_coupled_tests(store, int(sess["id"]), side=sess.get("side")):
            js = m.to_json()
            got.setdefault(js["joint"], []).append(js)
    except RigConfigError:  # a session of one joint, postures that cannot be read
        got = {}
    entry["coupled_tests"] = got
    return got


@dataclass(frozen=True)
class ProgressRequest:
    """A store (``db``: path or URL), a patient's pseudonym, optionally one joint, and the
    patient's age (years) and sex when known: with either, each movement's published norm for
    them comes with its series (:func:`norms_of`)."""

    db: str
    patient: str
    joint: str | None = None
    age: float | None = None
    sex: str | None = None

    def check(self) -> None:
        """The joint's name, the age and the sex, before any work (one-line errors)."""
        if not isinstance(self.patient, str) or not self.patient.strip():
            raise RigConfigError("--patient: give the patient's pseudonym")
        check_joint(self.joint)
        if self.sex is not None and self.sex not in SEXES:
            raise RigConfigError(f"--sex {self.sex!r}: expected one of {', '.join(SEXES)}")
        if self.age is not None and (isinstance(self.age, bool)
                                     or not isinstance(self.age, int | float)
                                     or not 0 <= self.age < 150):
            raise RigConfigError(f"--age {self.age!r}: expected years (0-149)")

    @property
    def with_norms(self) -> bool:
        """Whether the norms for the patient are asked for (an age or a sex given)."""
        return self.age is not None or self.sex is not None


def norms_of(joint: str, movements, *, age: float | None = None,
             sex: str | None = None) -> dict[str, list[Norm]]:
    """Each movement's published norm for a patient of ``age`` and ``sex`` (either None when
    unknown): :func:`calibration.norms.norm_band` from the report's sources for the joint,
    one value per sex when the sex is unknown; a movement with no published value is left
    out."""
    out = {}
    for m in movements:
        if m not in JOINT_MOVEMENTS.get(joint, ()):
            continue
        got = norm_band(joint, m, age=age, sex=sex)
        if got:
            out[m] = got
    return out


def norm_words(norms: list[Norm]) -> str:
    """One movement's norms for people: the values with their sex and age band, the source
    and how it measured (``"138 (women, 45-69): Soucie JM et al. 2011, Haemophilia
    17:500-507; passive motion, universal goniometer, ..."``)."""
    cites = dict.fromkeys(f"{n.source.cite}; {n.source.method}" for n in norms)
    return f"{norm_text(norms)}: {' | '.join(cites)}"


@dataclass
class Visit:
    """One joint of one session: when, how it was measured, whether it is evidence, and the
    peak per movement (degrees; None where the recording does not tell it)."""

    session_id: int
    started_at: float
    joint: str
    side: str | None
    limb: str | None
    method: str
    status: str
    interrupted: bool
    coverage: float | None
    coverage_sufficient: bool | None
    values: dict[str, float | None]
    excluded: list[str] = field(default_factory=list)
    coupled: dict[str, Any] = field(default_factory=dict)
    tests: dict[str, Any] = field(default_factory=dict)

    @property
    def usable(self) -> bool:
        """Evidence: ended normally with sufficient coverage (:attr:`excluded` empty)."""
        return not self.excluded

    @property
    def date(self) -> str:
        return _dt.datetime.fromtimestamp(self.started_at, _dt.timezone.utc).strftime(
            "%Y-%m-%d %H:%M")

    def to_json(self) -> dict:
        return {"session": self.session_id, "date": self.date, "started_at": self.started_at,
                "joint": self.joint, "side": self.side, "limb": self.limb,
                "method": self.method, "status": self.status,
                "interrupted": self.interrupted,
                "coverage": None if self.coverage is None else round(self.coverage, 4),
                "coverage_sufficient": self.coverage_sufficient, "usable": self.usable,
                "excluded": list(self.excluded),
                "values": {m: None if v is None else round(float(v), 2)
                           for m, v in self.values.items()},
                "coupled": self.coupled, "coupled_tests": self.tests}


@dataclass
class Point:
    """One usable visit of a movement's series, and its changes since the first and the
    previous usable visit (degrees, positive: a larger peak), each with its MDC verdict."""

    session_id: int
    date: str
    method: str
    value: float | None
    since_first: float | None = None
    since_previous: float | None = None
    first_verdict: str | None = None
    previous_verdict: str | None = None
    mdc: MdcValue | None = None
    mdc_text: str = ""

    def to_json(self) -> dict:
        r = (lambda v: None if v is None else round(float(v), 2))  # noqa: E731
        return {"session": self.session_id, "date": self.date, "method": self.method,
                "value": r(self.value), "since_first": r(self.since_first),
                "since_first_verdict": self.first_verdict,
                "since_previous": r(self.since_previous),
                "since_previous_verdict": self.previous_verdict,
                "mdc": None if self.mdc is None else self.mdc.to_json(),
                "mdc_text": self.mdc_text}


def _change(a: Visit, b: Visit, movement: str, point: Point) -> tuple[float | None,
                                                                      str | None]:
    """The change of ``movement`` from visit ``a`` to ``b`` and its verdict (None across
    methods: the published MDCs are per method)."""
    va, vb = a.values.get(movement), b.values.get(movement)
    if va is None or vb is None:
        return None, None
    d = float(vb) - float(va)
    return d, (verdict(d, point.mdc) if a.method == b.method else None)


@dataclass
class ProgressResult:
    """Every visit (:class:`Visit`, oldest first) and, per joint and side, each movement's
    series of usable visits (:class:`Point`)."""

    patient: str
    visits: list[Visit]
    series: dict[tuple[str, str | None], dict[str, list[Point]]]
    computed: int = 0
    cached: int = 0
    #: joint → movement → the published norms for the patient's age and sex
    #: (:func:`norms_of`), when an age or a sex was given; None otherwise
    norms: dict[str, dict[str, list[Norm]]] | None = None
    age: float | None = None
    sex: str | None = None

    def to_json(self) -> dict:
        """``rig progress --json``: ``patient``, ``visits`` (:meth:`Visit.to_json`),
        ``series`` (one per joint and side: ``joint``, ``side``, ``movements``: movement →
        list of :meth:`Point.to_json`; with an age or a sex, ``norms``: movement → the
        published values for the patient, :meth:`calibration.norms.Norm.to_json`, with their
        source and method), ``rom`` (``computed`` from samples this call, ``cached``) and,
        with an age or a sex, ``norms_for`` (``age``, ``sex``)."""
        series = []
        for (j, s), mv in self.series.items():
            one: dict[str, Any] = {"joint": j, "side": s,
                                   "movements": {m: [p.to_json() for p in pts]
                                                 for m, pts in mv.items()}}
            if self.norms is not None:
                one["norms"] = {m: [n.to_json() for n in ns]
                                for m, ns in self.norms.get(j, {}).items()}
            series.append(one)
        out = {"patient": self.patient, "visits": [v.to_json() for v in self.visits],
               "series": series, "rom": {"computed": self.computed, "cached": self.cached}}
        if self.norms is not None:
            out["norms_for"] = {"age": self.age, "sex": self.sex}
        return out

    def table(self) -> str:
        """What ``rig progress`` prints: the visits, then per joint and side each movement's
        values with the changes and their verdicts against the MDC."""
        n_bad = sum(not v.usable for v in self.visits)
        lines = [f"patient {self.patient}: {len({v.session_id for v in self.visits})} "
                 f"session(s), {len(self.visits)} joint visit(s), {n_bad} not used as evidence",
                 "", "visits"]
        if self.norms is not None:
            lines[1:1] = [f"norms for: {_patient_words(self.age, self.sex)}"]
        rows = [("session", "date (UTC)", "joint", "side", "method", "coverage", "status",
                 "evidence")]
        for v in self.visits:
            cov = "-" if v.coverage is None else f"{100 * v.coverage:.0f}%"
            rows.append((str(v.session_id), v.date, v.joint, v.side or "-", v.method, cov,
                         v.status, "yes" if v.usable else "no: " + "; ".join(v.excluded)))
        lines += _text_table(rows)
        for (joint, side), mv in self.series.items():
            lines += ["", f"{joint} ({side or 'side unknown'})"]
            rows = [("movement", "session", "date (UTC)", "value", "since first",
                     "since previous")]
            for m, pts in mv.items():
                for p in pts:
                    rows.append((m.replace("_", " "), str(p.session_id), p.date,
                                 "-" if p.value is None else f"{p.value:.1f}°",
                                 _delta(p.since_first, p.first_verdict),
                                 _delta(p.since_previous, p.previous_verdict)))
            lines += _text_table(rows)
            for m, pts in mv.items():
                texts = dict.fromkeys(p.mdc_text for p in pts)
                lines.append(f"MDC {m.replace('_', ' ')}: {' | '.join(texts)}")
            for m, ns in (self.norms or {}).get(joint, {}).items():
                if m in mv:
                    lines.append(f"norm {m.replace('_', ' ')}: {norm_words(ns)}")
        coupled = [v for v in self.visits if v.coupled]
        for v in coupled:
            for joint, c in v.coupled.items():
                at = ", ".join(f"{a:g}°" for a in c["at_deg"])
                lines.append(f"coupled: session {v.session_id} {joint} at {c['by']} {at}: "
                             + "; ".join(f"{a}: " + ", ".join(
                                 f"{m.replace('_', ' ')} {x:.1f}°" for m, x in vals.items()
                                 if x is not None) for a, vals in c["rom"].items()))
        rows = coupled_test_rows(self.visits)
        if rows:
            lines += ["", "coupled clinical tests across visits"]
            lines += _text_table([("test", "session", "date (UTC)", "value", "evidence"),
                                  *((r["label"], str(r["session"]), r["date"], r["text"],
                                     "yes" if r["usable"] else "no") for r in rows)])
        lines.append("")
        lines.append("verdicts: 'exceeds' = larger than the MDC (a real change); 'within' = "
                     "not distinguishable from measurement error; 'uncertain' = inside a "
                     "published MDC range; none across methods. Visits not used as evidence "
                     "are neither a reference nor a change.")
        return "\n".join(lines)


def _patient_words(age: float | None, sex: str | None) -> str:
    """The patient the norms are for, for people: ``"age 50, female"``."""
    return ", ".join(x for x in (None if age is None else f"age {age:g}",
                                 sex, None if age is not None else "age unknown") if x)


def coupled_test_rows(visits: list[Visit]) -> list[dict[str, Any]]:
    """The coupled clinical tests of every visit (:attr:`Visit.tests`), test by test in
    :data:`calibration.clinical_tests.MEASURES` order, then by date: ``label``, ``measure``,
    ``session``, ``date``, ``value`` (degrees or None), ``text`` (``"61.2°"``, or the status:
    "not reached in this recording", ...), ``usable`` (the visit is evidence)."""
    order = {s.key: i for specs in MEASURES.values() for i, s in enumerate(specs)}
    rows = []
    for v in visits:
        for key, m in v.tests.items():
            value = m.get("value")
            rows.append({"label": m.get("label") or key, "measure": key,
                         "session": v.session_id, "date": v.date, "value": value,
                         "text": f"{value:.1f}°" if value is not None else m.get("status", "-"),
                         "usable": v.usable, "_k": (order.get(key, 99), v.started_at)})
    rows.sort(key=lambda r: r["_k"])
    for r in rows:
        del r["_k"]
    return rows


def merged_progress(results: list[ProgressResult]) -> ProgressResult:
    """Several joints' progress of one patient (a limb's, one :func:`run_progress` per
    joint) as one: the visits in date order, every series."""
    visits = sorted((v for r in results for v in r.visits),
                    key=lambda v: (v.started_at, v.session_id))
    series = {k: v for r in results for k, v in r.series.items()}
    asked = [r for r in results if r.norms is not None]
    norms = {j: mv for r in asked for j, mv in r.norms.items()} if asked else None
    return ProgressResult(results[0].patient if results else "", visits, series,
                          sum(r.computed for r in results), sum(r.cached for r in results),
                          norms, asked[0].age if asked else None,
                          asked[0].sex if asked else None)


def _delta(d: float | None, v: str | None) -> str:
    if d is None:
        return "-"
    return f"{d:+.1f}°" + ("" if v is None else f" {v}")


def _text_table(rows: list[tuple[str, ...]]) -> list[str]:
    w = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w[i]) for i, c in enumerate(r)).rstrip() for r in rows]


def _method(store, sess: dict) -> str:
    """How a session measured: ``meta["method"]`` where the writer said, else servo for
    joint samples and IMU otherwise."""
    m = (sess.get("meta") or {}).get("method")
    if m in METHODS:
        return m
    sensors = store.samples.sensors(int(sess["id"]))
    return "servo" if any(r["kind"] == "joint" for r in sensors) else "imu"


def _joints_of(sess: dict) -> tuple[str | None, tuple[str, ...]]:
    """(limb, its joints) of a whole-limb session, else (None, (its joint,))."""
    limb = (sess.get("meta") or {}).get("limb")
    if limb in LIMB_CHAINS:
        return limb, tuple(name for name, _, _ in LIMB_CHAINS[limb])
    return None, (sess.get("joint") or "shoulder",)


def _cache_ok(entry: Any) -> bool:
    return (isinstance(entry, dict) and entry.get("version") == ROM_CACHE_VERSION
            and entry.get("rig") == __version__ and isinstance(entry.get("joints"), dict))


def _rom_entry(db: str, sess: dict, joint: str, limb: str | None) -> dict:
    """One joint's range of motion of a session (:func:`run_rom`) as the cache keeps it."""
    src = RecordingSource(db=db, session_id=int(sess["id"]), joint=joint if limb else None)
    res = run_rom(RomRequest(src, coupled_tests=False))  # the tests: coupled_tests_of
    out = res.to_json()
    values = {m: out.get(m) for m in movements_of(joint)
              if m not in (out.get("not_measured") or {})}
    facts = res.facts.as_dict() if res.facts is not None else {}
    return {"values": values, "facts": facts}


def coupled_limits(store, session_id: int, side: str | None,
                   joints: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Per coupled joint (of ``joints``; default every one) of the session's latest stored
    limb boundary: ``by`` (the joint it depends on), ``at_deg`` (its keyframe angles) and
    ``rom`` (angle text → movement → the range of motion that keyframe allows, degrees).
    Empty without a limb boundary."""
    rows = store.boundaries.list(session_id, limb=True)
    if not rows:
        return {}
    limb = loads_limb(rows[-1]["constraint_yaml"], source=f"session {session_id}")
    out: dict[str, Any] = {}
    for lj in limb.joints:
        if lj.coupling is None or (joints is not None and lj.name not in joints):
            continue
        per = {}
        for a, kf in zip(lj.coupling.at_deg, lj.coupling.keyframes, strict=True):
            r = allowed_rom([kf], lj.name, side or limb.side or "right")
            vals = r.to_dict() if isinstance(r, RangeOfMotion) else dict(r.peaks)
            per[f"{a:g}"] = {m: None if vals.get(m) is None else round(float(vals[m]), 2)
                             for m in movements_of(lj.name)}
        out[lj.name] = {"by": lj.coupling.by, "at_deg": [float(a) for a in lj.coupling.at_deg],
                        "rom": per}
    return out


def sessions_of(store, patient: str, joints: tuple[str, ...]) -> int:
    """How many recording sessions of patient ``patient`` recorded any of ``joints`` (a
    cheap count before :func:`run_progress`: the report shows progress from two on)."""
    return sum(1 for s in store.sessions.list(patient=patient)
               if s.get("kind") == "record" and set(_joints_of(s)[1]) & set(joints))


def _visits_of(store, db: str, sess: dict, joint_filter: str | None,
               counts: dict[str, int]) -> list[Visit]:
    """The visits (one per joint) of one session, its range of motion from the cache or
    computed (and cached when the session has ended and the store is writable)."""
    limb, joints = _joints_of(sess)
    if joint_filter is not None:
        joints = tuple(j for j in joints if j == joint_filter)
    if not joints:
        return []
    meta = sess.get("meta") or {}
    status = sess.get("status") or "unknown"
    entry = meta.get("rom_cache")
    if not _cache_ok(entry):
        entry = {"version": ROM_CACHE_VERSION, "rig": __version__, "joints": {}}
    dirty = False
    method = entry.get("method") or _method(store, sess)
    if entry.get("method") != method:
        entry["method"], dirty = method, True
    coupled = entry.setdefault("coupled", {})  # joint → a limb file's keyframes ({}: none)
    todo = tuple(j for j in joints if j not in coupled)
    if todo:  # only the joints asked for: a coupled joint's ranges cost ~0.1-0.3 s a keyframe
        found = coupled_limits(store, int(sess["id"]), sess.get("side"), todo)
        coupled.update({j: found.get(j, {}) for j in todo})
        dirty = True
    had_tests = "coupled_tests" in entry
    tests = coupled_tests_of(store, sess, entry) if limb else {}
    dirty = dirty or (bool(limb) and not had_tests)
    visits = []
    for j in joints:
        got = entry["joints"].get(j)
        if got is None:
            try:
                got = _rom_entry(db, sess, j, limb)
            except RigConfigError as err:  # no samples, no calibration: listed, not evidence
                got = {"values": {}, "facts": {}, "error": str(err)}
            entry["joints"][j] = got
            dirty = True
            counts["computed"] += 1
        else:
            counts["cached"] += 1
        facts = got.get("facts") or {}
        interrupted = status in CUT_SHORT or bool(facts.get("interrupted"))
        excluded = []
        if got.get("error"):
            excluded.append(got["error"])
        if status == "running":
            excluded.append("interrupted (recorder gone)" if facts.get("interrupted")
                            else "still being recorded")
        elif interrupted:
            excluded.append(f"interrupted (status {status})")
        if facts.get("coverage_sufficient") is False:
            excluded.append(f"poor coverage ({facts.get('explored_sectors')} of "
                            f"{facts.get('sectors')} directions)")
        visits.append(Visit(int(sess["id"]), float(sess["started_at"]), j, sess.get("side"),
                            limb, method, status, interrupted, facts.get("coverage"),
                            facts.get("coverage_sufficient"), dict(got.get("values") or {}),
                            excluded, {j: coupled[j]} if coupled.get(j) else {},
                            {m["measure"]: m for m in tests.get(j, [])}))
    if dirty and status != "running" and not store.readonly:
        store.sessions.merge_meta(int(sess["id"]), {"rom_cache": entry})
    return visits


def _series(visits: list[Visit]) -> dict[tuple[str, str | None], dict[str, list[Point]]]:
    """Per joint and side, each movement's usable visits with their changes."""
    out: dict[tuple[str, str | None], dict[str, list[Point]]] = {}
    groups: dict[tuple[str, str | None], list[Visit]] = {}
    for v in visits:
        if v.usable:
            groups.setdefault((v.joint, v.side), []).append(v)
    for (joint, side), vs in groups.items():
        mv: dict[str, list[Point]] = {}
        for m in movements_of(joint):
            have = [v for v in vs if m in v.values]
            if not have:
                continue
            pts = []
            first = prev = None
            for v in have:
                mdc, text = mdc_for(joint, m, v.method)
                p = Point(v.session_id, v.date, v.method, v.values.get(m), mdc=mdc,
                          mdc_text=text)
                if v.values.get(m) is not None:
                    if first is not None:
                        p.since_first, p.first_verdict = _change(first, v, m, p)
                        p.since_previous, p.previous_verdict = _change(prev, v, m, p)
                    else:
                        first = v
                    prev = v
                pts.append(p)
            mv[m] = pts
        out[(joint, side)] = mv
    return out


def run_progress(request: ProgressRequest) -> ProgressResult:
    """Check the request, read the patient's sessions (oldest first), each visit's range of
    motion (cached or computed), and the changes between usable visits."""
    request.check()
    with open_store(request.db, create=False) as store:
        if store.patients.find(request.patient) is None:
            raise RigConfigError(f"no patient {request.patient!r} in {store.url}")
        sessions = [s for s in store.sessions.list(patient=request.patient)
                    if s.get("kind") == "record"]
        if not sessions:
            raise RigConfigError(f"patient {request.patient!r} has no recording sessions in "
                                 f"{store.url}")
        sessions.sort(key=lambda s: (float(s["started_at"]), int(s["id"])))
        if request.joint is not None:
            have = sorted({j for s in sessions for j in _joints_of(s)[1]})
            if request.joint not in have:
                raise RigConfigError(f"patient {request.patient!r} has no session of the "
                                     f"{request.joint} (recorded: {', '.join(have)})")
        counts = {"computed": 0, "cached": 0}
        visits = [v for s in sessions
                  for v in _visits_of(store, request.db, s, request.joint, counts)]
    series = _series(visits)
    norms = None
    if request.with_norms:
        norms = {}
        for joint, _side in series:
            norms.setdefault(joint, norms_of(joint, movements_of(joint), age=request.age,
                                             sex=request.sex))
    return ProgressResult(request.patient, visits, series, counts["computed"],
                          counts["cached"], norms, request.age, request.sex)
