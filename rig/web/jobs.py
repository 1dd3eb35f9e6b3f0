"""Long work off the request path: a recording, a boundary extraction, a training, each run by
the server process in a thread of its own, its state in the store, its events live.

Shape
-----
A request starts a job (:meth:`JobRunner.start_record`, :meth:`~JobRunner.start_boundary`,
:meth:`~JobRunner.start_train`): every check a user mistake can fail (the rig's configuration,
its side, the patient, a wrong port, a session without a boundary, a busy rig) runs first, in
the request, and raises the one-line error the CLI gives; then a thread runs the service
function the CLI runs (:func:`rig.record.record_session`, :func:`rig.readback.run_boundary`,
:func:`rig.training.run_train`) and the request returns the job's id at once. Closing the page
changes nothing: the job runs in the server, not in the request.

- **The store** keeps each job (``store.jobs``, :mod:`rig.store.jobs`): its status, its latest
  progress (about once a second: phase, counts, coverage, the messages said so far) and its
  result, so a page reloaded later, or after a restart of the server, finds it; a job whose
  server died reads ``died`` (the writer's liveness, as a session's).
- **The channel** (:class:`Channel`) carries the live events of a running job to any number of
  viewers as Server-Sent Events: ``message`` (every line the CLI prints: the calibration's
  steps, the checkpoints, training progress), ``status`` (the recorder's counters and, while it
  waits for Enter, what Enter would do), ``coverage`` (the swing map), ``session`` and ``end``.
  ``status`` and ``coverage`` keep their newest value only: a slow viewer skips to the present,
  it never holds the recorder back. Messages are all delivered, in order.
- **The recording's display** is the recorder's own display interface (``start``,
  ``update(status)``, ``message(text)``, ``stop``: :mod:`rig.record.display`) implemented by
  :class:`WebDisplay`, so the browser sees what the terminal shows, from the same
  :class:`~rig.record.display.RecordStatus`. Where ``rig record`` waits for Enter (hardware: the
  calibration's start, each neutral checkpoint) the recorder reads a pipe
  (``record(stdin=...)``) that the page's "continue" button writes a newline to
  (:meth:`JobRunner.press`). Stop ends the session ``completed`` (``record(complete=...)``),
  Interrupt ``interrupted`` (as Ctrl-C): either way everything recorded is committed, as at the
  CLI.

One job at a time per resource: a rig's ports for a recording, a session for its boundary or
model (:meth:`rig.store.jobs.JobRepository.start` refuses a second, naming the first).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import math
import os
import threading
import time
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from models.fileio import write_owner_only
from rig.devices.config import rig_config_names
from rig.errors import RigConfigError, RigError, user_errors
from rig.readback import BoundaryRequest, RecordingSource, run_boundary
from rig.record import RecordOptions, RecordStatus, record_session
from rig.record.rigio import load_config, open_rig
from rig.store import open_store
from rig.store.pseudonyms import pseudonym_warning
from rig.training import PRESET_NAMES, TrainRequest, run_train
from rig.training.limb import LIMB_PRESETS

__all__ = ["Channel", "JobRunner", "RecordJob", "WebDisplay", "offered_rigs", "shipped_rigs"]

log = logging.getLogger("rig.web.jobs")

#: Events every viewer receives, in order; the others keep only their newest value.
KEPT_EVENTS = ("message", "session", "end")
#: Messages a channel (and a job's stored progress) keeps.
MAX_MESSAGES = 500
STORED_MESSAGES = 50


def shipped_rigs() -> dict[str, str]:
    """The shipped rig configurations (``rig/configs/*.yaml``): name → name (what
    :func:`rig.record.rigio.load_config` takes)."""
    return {name: name for name in rig_config_names()}


def offered_rigs(files: Sequence[str] = ()) -> dict[str, str]:
    """The shipped rigs and the configuration ``files`` (a clinic's own hardware, ``rig serve
    --rig FILE``), each file read now (:func:`rig.record.rigio.load_config`: a missing file, an
    unknown key, a name taken twice — one line, before the server starts): name → what
    ``load_config`` takes."""
    out = shipped_rigs()
    for f in files:
        cfg = load_config(str(f))
        if cfg.name in out and out[cfg.name] != str(f):
            raise RigConfigError(f"--rig {f}: a rig named {cfg.name!r} is offered already "
                                 "(name it otherwise in its file)")
        out[cfg.name] = str(f)
    return out


def _epoch_ms(t_monotonic: float) -> float | None:
    """A host monotonic time (a sample's ``t``) on the Unix clock, in milliseconds — the clock
    a browser on this machine reads (``performance.timeOrigin + performance.now()``)."""
    if not math.isfinite(t_monotonic):
        return None
    return (time.time() - time.monotonic() + t_monotonic) * 1000.0


def _num(x: float, nd: int = 1) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), nd)


class Channel:
    """Live events of one job for any number of Server-Sent-Event viewers.

    :meth:`publish` is called from the job's thread; :meth:`sse` runs in the server's event
    loop, one per viewer, and wakes when something is published (no polling).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._seq = 0
        self._log: list[tuple[int, str, str]] = []
        self._latest: dict[str, tuple[int, str, str]] = {}
        self._waiters: set[tuple[asyncio.AbstractEventLoop, asyncio.Event]] = set()
        self.closed = False
        self.viewers = 0

    def publish(self, name: str, data: Mapping[str, Any]) -> int:
        """Publish an event (JSON-able ``data``); its sequence number."""
        text = json.dumps(data, separators=(",", ":"))
        with self._lock:
            self._seq += 1
            ev = (self._seq, name, text)
            if name in KEPT_EVENTS:
                self._log.append(ev)
                if len(self._log) > MAX_MESSAGES:
                    del self._log[: len(self._log) - MAX_MESSAGES]
            else:
                self._latest[name] = ev
            waiters = list(self._waiters)
            seq = self._seq
        self._wake(waiters)
        return seq

    def close(self) -> None:
        """No more events: every viewer's stream ends after what it has not yet received."""
        with self._lock:
            self.closed = True
            waiters = list(self._waiters)
        self._wake(waiters)

    @staticmethod
    def _wake(waiters) -> None:
        for loop, event in waiters:
            with contextlib.suppress(RuntimeError):  # a viewer's loop already closed
                loop.call_soon_threadsafe(event.set)

    def since(self, cursor: int) -> tuple[list[tuple[int, str, str]], bool]:
        """Events after sequence number ``cursor`` in order, and whether the channel is
        closed."""
        with self._lock:
            out = [e for e in self._log if e[0] > cursor]
            out += [e for e in self._latest.values() if e[0] > cursor]
            closed = self.closed
        out.sort()
        return out, closed

    async def sse(self, cursor: int = 0, *, keepalive_s: float = 15.0) -> AsyncIterator[str]:
        """The ``text/event-stream`` of this channel from ``cursor`` (a reconnecting
        EventSource's ``Last-Event-ID``) until it is closed."""
        loop = asyncio.get_running_loop()
        wake = asyncio.Event()
        me = (loop, wake)
        with self._lock:
            self._waiters.add(me)
            self.viewers += 1
        try:
            yield "retry: 1000\n\n"
            while True:
                wake.clear()
                events, closed = self.since(cursor)
                if events:
                    yield "".join(f"id: {seq}\nevent: {name}\ndata: {text}\n\n"
                                  for seq, name, text in events)
                    cursor = events[-1][0]
                    continue
                if closed:
                    return
                try:
                    await asyncio.wait_for(wake.wait(), keepalive_s)
                except asyncio.TimeoutError:
                    yield ": keep-alive\n\n"
        finally:
            with self._lock:
                self._waiters.discard(me)
                self.viewers -= 1


def status_event(st: RecordStatus) -> dict:
    """The ``status`` event of a recorder status: counters, phase, what Enter does, and the
    newest sample's host time on the Unix clock (``sample_ms``, for sample-to-screen
    latency)."""
    return {
        "phase": st.phase, "elapsed_s": _num(st.elapsed_s, 2), "duration_s": st.duration_s,
        "samples": int(st.samples), "rate_hz": _num(st.rate_hz, 0), "dropped": int(st.dropped),
        "checkpoints": st.checkpoints, "enter": st.enter,
        "sample_ms": _num(_epoch_ms(st.last_t), 3), "sent_ms": round(time.time() * 1000.0, 3),
    }


def coverage_event(st: RecordStatus) -> dict:
    """The ``coverage`` event: the sectors (azimuth from-to, reach, near-limit samples, all
    samples, twist extremes, stable, explored), the overall twist, the visited cells of the
    swing map (azimuth, reach; degrees), a whole limb's other joints' movements reached
    (``angles``: ``{joint: {movement: degrees}}``, the elbow's or knee's hinge angles) and the
    newest sample's host time (``sample_ms``, as :func:`status_event`)."""
    cov = st.coverage
    out: dict[str, Any] = {"sectors": [], "explored": 0, "sufficient": False,
                           "need": 0, "twist": [None, None], "reached": [], "angles": {}}
    if cov is not None:
        out.update(
            explored=int(cov.explored), sufficient=bool(cov.sufficient),
            need=int(cov.min_boundary_samples),
            twist=[_num(cov.twist_deg[0]), _num(cov.twist_deg[1])],
            sectors=[[s.azimuth_deg[0], s.azimuth_deg[1], _num(s.reach_deg),
                      int(s.boundary_samples), int(s.samples), _num(s.twist_deg[0]),
                      _num(s.twist_deg[1]), bool(s.stable), bool(s.explored)]
                     for s in cov.sectors])
    out["angles"] = {j: {m: _num(v) for m, v in moves.items()}
                     for j, moves in (st.angles or {}).items()}
    out["sample_ms"] = _num(_epoch_ms(st.last_t), 3)
    if st.reached is not None and len(st.reached):
        out["reached"] = np.round(np.asarray(st.reached, dtype=np.float64), 1).tolist()
    return out


class WebDisplay:
    """The recorder's display (:mod:`rig.record.display` interface) for the browser: status
    at most ``status_hz`` times a second, coverage whenever the recorder refreshes it, every
    message; the job's progress written to the store every ``store_every_s`` seconds.

    Parameters
    ----------
    channel : Channel
    save : callable(progress dict)
        Stores the job's progress (called from the recorder's thread).
    """

    def __init__(self, channel: Channel, save: Callable[[dict], None], *,
                 status_hz: float = 20.0, store_every_s: float = 1.0) -> None:
        self.channel = channel
        self.save = save
        self.min_dt = 1.0 / float(status_hz)
        self.store_every_s = float(store_every_s)
        self.messages: list[str] = []
        self._last = -math.inf
        self._last_store = -math.inf
        self._coverage: object = None  # the summary last published (by identity)
        self.status: dict = {}
        self.coverage: dict = {}

    def start(self) -> None:
        pass

    def update(self, st: RecordStatus, *, force: bool = False) -> None:
        now = time.monotonic()
        if st.coverage is not self._coverage or force:  # a new summary (or the last)
            self._coverage = st.coverage
            if st.coverage is not None:
                self.coverage = coverage_event(st)
                self.channel.publish("coverage", self.coverage)
        if not force and now - self._last < self.min_dt:
            return
        self._last = now
        self.status = status_event(st)
        self.channel.publish("status", self.status)
        if force or now - self._last_store >= self.store_every_s:
            self._last_store = now
            try:
                self.save(self.progress())
            except Exception:  # the snapshot is for a reload; the samples come first
                log.warning("job progress not stored (the recording goes on)", exc_info=True)

    def message(self, text: str) -> None:
        self.messages.append(text)
        self.channel.publish("message", {"text": text})

    def progress(self) -> dict:
        """What the store keeps of the running recording (a reload's starting point)."""
        cov = {k: v for k, v in self.coverage.items() if k != "reached"}
        return {"status": self.status, "coverage": cov,
                "messages": self.messages[-STORED_MESSAGES:]}

    def stop(self) -> None:
        pass


@dataclass(frozen=True)
class RecordJob:
    """A guided recording asked from the browser.

    Attributes
    ----------
    patient_id : int
        The patient (by id: pseudonyms never travel in URLs).
    rig : str
        A rig offered by the runner (:attr:`JobRunner.rigs`).
    side : str, optional
        ``left`` or ``right``: must be the rig's (its configuration's ``joint.side``).
    duration_s : float, optional
        Seconds of recording after the calibration; None: until Stop.
    calibrate : bool
        The guided calibration first (default), as ``rig record``.
    """

    patient_id: int
    rig: str
    side: str | None = None
    duration_s: float | None = None
    calibrate: bool = True


@dataclass
class _Live:
    """A job running in this process."""

    job_id: int
    kind: str
    channel: Channel
    thread: threading.Thread | None = None
    stop: threading.Event = dataclasses.field(default_factory=threading.Event)
    complete: threading.Event = dataclasses.field(default_factory=threading.Event)
    enter_w: int | None = None  # the write end of the recorder's Enter pipe
    stdin: Any = None


class JobRunner:
    """Runs the web app's long jobs in threads of the server process.

    Parameters
    ----------
    db : str
        The store (path or URL), as ``rig serve --db``.
    files_dir : str or Path
        Where a session's files go (``session-N/boundary-jobJ.yaml``, ``model-jobJ.onnx``, the
        constraint a model was trained on ``train-jobJ.yaml``); created owner-only.
    rigs : mapping, optional
        The rigs offered: name → configuration name or YAML path (default
        :func:`shipped_rigs`: the shipped configurations, the simulators included).
    status_hz : float
        Most ``status`` events a second of a recording.
    opener : callable(config, calibrate=bool) -> OpenRig
        Opens a rig (default :func:`rig.record.rigio.open_rig`); tests give one whose
        simulated rig answers as hardware does, to drive the Enter prompts.
    """

    def __init__(self, db: str, files_dir: str | os.PathLike, *,
                 rigs: Mapping[str, str] | None = None, status_hz: float = 20.0,
                 opener: Callable[..., Any] = open_rig) -> None:
        self.opener = opener
        self.db = db
        self.files_dir = Path(files_dir)
        self.rigs = dict(shipped_rigs() if rigs is None else rigs)
        self.status_hz = float(status_hz)
        self._live: dict[int, _Live] = {}
        self._lock = threading.Lock()
        self._starting = threading.Lock()
        with open_store(db) as store:  # created if new; jobs of a dead server closed
            store.jobs.close_died()

    # -- what the pages ask ------------------------------------------------------------------
    def rig_choices(self) -> list[dict]:
        """The rigs offered, each with what it records (name, description, joint, limb, side,
        whether simulated); a configuration that does not load is listed with its error."""
        out = []
        for name, ref in self.rigs.items():
            try:
                cfg = load_config(ref)
            except RigError as err:
                out.append({"name": name, "error": str(err)})
                continue
            ports = _ports(cfg)
            out.append({"name": name, "description": cfg.description or "",
                        "joint": cfg.joint.name, "limb": cfg.limb, "side": cfg.joint.side,
                        "simulated": all(p.startswith("sim://") for p in ports)})
        return out

    def job(self, job_id: int) -> dict:
        """The job's row (``state``: its status, or ``died``) and whether it runs here."""
        with open_store(self.db, create=False) as store:
            row = store.jobs.get(job_id)
        row["live"] = job_id in self._live
        return row

    def channel(self, job_id: int) -> Channel | None:
        """The live channel of a job running in this process (None otherwise)."""
        live = self._live.get(int(job_id))
        return None if live is None else live.channel

    # -- recording ---------------------------------------------------------------------------
    def start_record(self, req: RecordJob) -> int:
        """Check, open the rig and start recording; the job's id.

        Raises
        ------
        RigConfigError, RigConnectionError, RigTimeoutError
            A user mistake (unknown rig or patient, another side than the rig's, a bad
            duration, a busy rig) or a missing device: one line, nothing recorded.
        """
        if req.rig not in self.rigs:
            raise RigConfigError(f"rig {req.rig!r}: not one of {', '.join(self.rigs)}")
        config = load_config(self.rigs[req.rig])
        if req.side is not None and req.side != config.joint.side:
            raise RigConfigError(f"side {req.side!r}: the rig {req.rig} records the "
                                 f"{config.joint.side} {config.limb or config.joint.name} "
                                 "(joint.side of its configuration); choose a rig configured "
                                 f"for the {req.side} side")
        resource = "rig:" + ",".join(_ports(config))
        # one start at a time here: a second request for the same rig waits, then is refused
        # by the check, before it opens the ports (the store's check covers other processes)
        with self._starting, open_store(self.db, create=False) as store:
            pseudonym = store.patients.get(req.patient_id)["pseudonym"]
            options = RecordOptions(rig=self.rigs[req.rig], db=self.db, patient=pseudonym,
                                    duration_s=req.duration_s, calibrate=req.calibrate)
            options.check()
            store.jobs.check_free(resource)
            rig = self.opener(config, calibrate=req.calibrate)  # a wrong port fails here
            try:
                job_id = store.jobs.start(
                    "record", resource, patient_id=req.patient_id,
                    params={"rig": req.rig, "side": config.joint.side,
                            "joint": config.joint.name, "limb": config.limb,
                            "duration_s": req.duration_s, "calibrate": req.calibrate})
            except BaseException:
                rig.close()
                raise
        live = _Live(job_id, "record", Channel())
        r, live.enter_w = os.pipe()
        live.stdin = os.fdopen(r, "r")
        if pseudonym_warning(pseudonym):
            live.channel.publish("message", {"text": f"warning: {pseudonym_warning(pseudonym)}"})
        live.thread = threading.Thread(target=self._record, args=(live, options, rig),
                                       name=f"rig-web-record-{job_id}", daemon=True)
        self._run(live)
        return job_id

    def _record(self, live: _Live, options: RecordOptions, rig) -> None:
        status, message, result = "failed", None, {}
        with open_store(self.db, create=False) as store:
            def save(progress: dict) -> None:
                store.jobs.update(live.job_id, progress=progress)

            def on_event(name: str, info: dict) -> None:
                if name == "session":
                    store.jobs.update(live.job_id, session_id=info["session_id"])
                    live.channel.publish("session", {"session_id": info["session_id"]})

            display = WebDisplay(live.channel, save, status_hz=self.status_hz)
            try:
                res = record_session(options, display=display, stop=live.stop,
                                     on_event=on_event, rig=rig, stdin=live.stdin,
                                     complete=live.complete)
                status = res.status if res.status in ("completed", "interrupted") else "failed"
                message = res.summary() + (f"; device lost: {res.error}"
                                            if res.status == "device_lost" else "")
                result = {"session_id": res.session_id, "status": res.status,
                          "samples": res.samples, "dropped": res.dropped, "gaps": res.gaps,
                          "overflow": res.overflow, "span_s": res.span_s,
                          "calibrated": res.calibrated, "rom_note": res.rom_note,
                          "rom_table": res.rom_table,
                          "coverage_sufficient": bool(res.coverage.get("sufficient"))}
            except user_errors() as err:
                message = str(err)
            except Exception as err:  # logged in full for the server's operator
                log.exception("recording job %s failed", live.job_id)
                message = f"{type(err).__name__}: {err}"
            finally:
                self._finish(live, store, status, message, result, display.progress())

    # -- boundary and training ---------------------------------------------------------------
    def start_boundary(self, session_id: int) -> int:
        """Extract the boundary of a recorded session (one joint, or every joint of a whole
        limb), write it under the session's folder and store it with the session."""
        with open_store(self.db, create=False) as store:
            sess = self._ended_session(store, session_id)
            job_id = store.jobs.start("boundary", f"session:{session_id}",
                                      patient_id=sess["patient_id"], session_id=session_id)
        live = _Live(job_id, "boundary", Channel())
        limb = (sess.get("meta") or {}).get("limb")
        live.thread = threading.Thread(target=self._boundary, args=(live, session_id, limb),
                                       name=f"rig-web-boundary-{job_id}", daemon=True)
        self._run(live)
        return job_id

    def _boundary(self, live: _Live, session_id: int, limb: str | None) -> None:
        status, message, result = "failed", None, {}
        say = _sayer(live.channel)
        with open_store(self.db, create=False) as store:
            try:
                folder = self._folder(session_id)
                out = folder / f"boundary-job{live.job_id}.yaml"
                say(f"reading session {session_id} and extracting its boundary"
                    + (f" (whole {limb})" if limb else ""))
                res = run_boundary(BoundaryRequest(
                    RecordingSource(db=self.db, session_id=session_id), out, limb=limb))
                for line in res.describe().splitlines():
                    say(line)
                for w in res.warnings:
                    say(f"warning: {w}")
                status, message = "completed", f"boundary {res.boundary_id} stored"
                result = {"boundary_id": res.boundary_id, "file": out.name,
                          "warnings": list(res.warnings)}
            except user_errors() as err:
                message = str(err)
            except Exception as err:
                log.exception("boundary job %s failed", live.job_id)
                message = f"{type(err).__name__}: {err}"
            finally:
                self._finish(live, store, status, message, result,
                             {"messages": say.lines[-STORED_MESSAGES:]})

    def start_train(self, session_id: int, *, preset: str | None = None, seed: int = 0) -> int:
        """Train a model on the session's newest stored boundary (``rig train``'s defaults),
        write it under the session's folder and register it with the session and boundary."""
        with open_store(self.db, create=False) as store:
            sess = self._ended_session(store, session_id)
            rows = store.boundaries.list(session_id)
            if not rows:
                raise RigConfigError(f"session {session_id} has no boundary yet: extract it "
                                     "first")
            boundary = rows[-1]
            if preset is not None and preset not in PRESET_NAMES + LIMB_PRESETS:
                raise RigConfigError(f"preset {preset!r}: expected one of "
                                     f"{', '.join(PRESET_NAMES + LIMB_PRESETS)}")
            job_id = store.jobs.start("train", f"session:{session_id}",
                                      patient_id=sess["patient_id"], session_id=session_id,
                                      params={"boundary_id": boundary["id"], "preset": preset,
                                              "seed": seed})
        live = _Live(job_id, "train", Channel())
        live.thread = threading.Thread(target=self._train,
                                       args=(live, session_id, boundary, preset, seed),
                                       name=f"rig-web-train-{job_id}", daemon=True)
        self._run(live)
        return job_id

    def _train(self, live: _Live, session_id: int, boundary: dict, preset: str | None,
               seed: int) -> None:
        status, message, result = "failed", None, {}
        say = _sayer(live.channel)
        with open_store(self.db, create=False) as store:
            try:
                folder = self._folder(session_id)
                bid = int(boundary["id"])
                constraint = write_owner_only(folder / f"train-job{live.job_id}.yaml",
                                              boundary["constraint_yaml"])
                out = folder / f"model-job{live.job_id}.onnx"
                say(f"training on boundary {bid}" + (f" (preset {preset})" if preset else ""))
                res = run_train(TrainRequest(out, constraint=str(constraint), preset=preset,
                                             seed=seed), echo=say)
                os.chmod(out, 0o600)
                try:
                    mid = store.models.add(out, boundary_id=bid, session_id=session_id,
                                           metrics=res.metrics)
                except RigConfigError:  # a metric JSON cannot hold (NaN): the file still is
                    mid = store.models.add(out, boundary_id=bid, session_id=session_id)
                status = "completed"
                message = f"model {mid} trained in {res.seconds:.1f} s"
                result = {"model_id": mid, "file": out.name, "seconds": res.seconds,
                          "warnings": list(res.warnings)}
            except user_errors() as err:
                message = str(err)
            except Exception as err:
                log.exception("training job %s failed", live.job_id)
                message = f"{type(err).__name__}: {err}"
            finally:
                self._finish(live, store, status, message, result,
                             {"messages": say.lines[-STORED_MESSAGES:]})

    # -- the buttons -------------------------------------------------------------------------
    def press(self, job_id: int) -> None:
        """The "continue" button: Enter, where ``rig record`` waits for it."""
        with self._lock:  # not while the job ends and closes the pipe (:meth:`_finish`)
            live = self._running(job_id, "record")
            if live.enter_w is not None:
                os.write(live.enter_w, b"\n")

    def stop(self, job_id: int) -> None:
        """End the recording now as ``completed`` (everything recorded is kept)."""
        self._running(job_id, "record").complete.set()

    def interrupt(self, job_id: int) -> None:
        """End the recording now as ``interrupted`` (as Ctrl-C; everything recorded is kept)."""
        self._running(job_id, "record").stop.set()

    def wait(self, job_id: int, timeout: float | None = None) -> bool:
        """Wait for a job running here to end; False on timeout."""
        live = self._live.get(int(job_id))
        if live is None or live.thread is None:
            return True
        live.thread.join(timeout)
        return not live.thread.is_alive()

    def close(self, timeout: float = 30.0) -> None:
        """The server stops: recordings are interrupted (kept), every job waited for up to
        ``timeout`` seconds (a training still running then is left to die with the process and
        reads ``died`` afterwards)."""
        lives = list(self._live.values())
        for live in lives:
            live.stop.set()
        end = time.monotonic() + timeout
        for live in lives:
            if live.thread is not None:
                live.thread.join(max(0.0, end - time.monotonic()))

    # -- helpers -----------------------------------------------------------------------------
    def _running(self, job_id: int, kind: str) -> _Live:
        live = self._live.get(int(job_id))
        if live is None or live.kind != kind:
            raise RigConfigError(f"job {job_id}: no {kind} job of that id is running")
        return live

    def _run(self, live: _Live) -> None:
        with self._lock:
            self._live[live.job_id] = live
        assert live.thread is not None
        live.thread.start()

    def _finish(self, live: _Live, store, status: str, message: str | None, result: dict,
                progress: dict) -> None:
        try:
            store.jobs.end(live.job_id, status, result=result, message=message,
                           progress=progress)
        finally:
            # first the buttons refuse (a viewer that saw "end" and presses gets "not
            # running"), and Enter's pipe is closed under the lock a press writes under (its
            # descriptor number is never written after it is closed and reused)
            with self._lock:
                self._live.pop(live.job_id, None)
                if live.enter_w is not None:
                    os.close(live.enter_w)
                    live.enter_w = None
            live.channel.publish("end", {"status": status, "message": message,
                                         "result": result})
            live.channel.close()
            if live.stdin is not None:
                live.stdin.close()

    @staticmethod
    def _ended_session(store, session_id: int) -> dict:
        sess = store.sessions.get(session_id)
        if sess["status"] == "running":
            raise RigConfigError(f"session {session_id} is still recording: stop it first")
        return sess

    def _folder(self, session_id: int) -> Path:
        """The session's folder of files, owner-only."""
        self.files_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
        folder = self.files_dir / f"session-{int(session_id)}"
        folder.mkdir(mode=0o700, exist_ok=True)
        return folder


def _ports(config) -> list[str]:
    sensors = getattr(config, "sensors", None)
    if sensors is not None:
        return list(sensors.ports)
    return [config.servos.port]


class _sayer:
    """``echo`` for a service function: each line a ``message`` event, kept for the store."""

    def __init__(self, channel: Channel) -> None:
        self.channel = channel
        self.lines: list[str] = []

    def __call__(self, text: str) -> None:
        for line in str(text).splitlines() or [""]:
            self.lines.append(line)
            self.channel.publish("message", {"text": line})


