"""ROBOTIS's own DynamixelSDK Python example programs, run as a user would, against ``rig sim
servos``.

A user with a U2D2 and a servo clones DynamixelSDK, opens ``python/tests/protocol2_0/*.py`` (or
``protocol1_0/*.py``, ``protocol_combined.py``), edits the port, the baud rate, the IDs and the
``MY_DXL`` selection line, runs it and presses keys. This script does exactly that against the
simulator, for every example and every simulated model:

1. starts the simulator as a user would, ``python -m rig sim servos URL`` in a child process
   (two of them for ``multi_port.py``: one per port), with the IDs the example uses and the
   model's factory-default baud rate; the pty path is the child's first line of output;
2. copies the example into a temporary directory and changes **only** the assignment lines a
   user edits — ``DEVICENAME`` / ``DEVICENAME1`` / ``DEVICENAME2`` / ``SERIAL_PORT`` (the pty),
   ``BAUDRATE`` (in the selected model's branch, when it differs from the servo's default) and
   the ``MY_DXL`` selection (the active line commented out, the model's line uncommented) — by
   regular expressions on those lines (``--show-diff`` prints the unified diff of each copy);
   the IDs are left as the examples have them (1, and 2 for a second servo): the simulator is
   started with those IDs;
3. runs the copy with this interpreter (the copy's folder is ``sys.path[0]``, so it imports the
   installed ``dynamixel_sdk`` — this checkout's venv — never the checkout's sources) on a
   pseudo-terminal as stdin/stdout, because the examples read keys with ``tty.setraw`` +
   ``sys.stdin.read(1)``; a key is sent only when the example has printed its prompt *and*
   switched the terminal out of canonical mode (it is then blocked reading the key): "Press
   any key to continue" is answered ``--moves`` times, then ESC; ``clear_multi_turn.py`` gets
   SPACE once the servo has turned more than a revolution;
4. judges what the example itself checks: the goal reached after each key (the example prints
   its prompt again only then), "[ID:001] ping Succeeded" with the model number the e-Manual
   gives, the baud-rate number read back after a factory reset, the present position after
   CLEAR, ... and no "[TxRxResult]" / "[RxPacketError]" / "failed" line. A run that makes no
   progress (no new prompt, no exit) for ``--timeout`` seconds is killed: HANG.

Outcomes: PASS, FAIL (with the example's last error line and how often it was printed, or a
Python traceback's last line), HANG ("timed out after N s still printing X"), SIM REFUSED (the
simulator rejects the model's URL: its one-line error), N/A (the example offers no selection for
the model's series, or the model speaks the other protocol).

Run (the script never downloads; DIR is a DynamixelSDK work tree)::

    git clone <DynamixelSDK> /tmp/dxlsdk
    python benchmarks/robotis_examples.py --sdk /tmp/dxlsdk [--only read_write] \
        [--models XM430-W350 XL-320] [--timeout 8] [--moves 2] [--jobs 1] [--retries 2] \
        [--show-diff] [--json out.json]

Sources of the per-model facts (:data:`MODELS`): model numbers from the SDK's
``dynamixel_easy_sdk/control_table/dynamixel.model`` and the e-Manual pages named there;
factory-default baud rates and their Baud Rate item values from each model's e-Manual control
table (X series, MX 2.0, P / PRO(A): 57 600 bit/s = 1; XL-320: 1 Mbit/s = 3,
<https://emanual.robotis.com/docs/en/dxl/x/xl320/>; AX-12A: 1 Mbit/s = 1, model number 12,
<https://emanual.robotis.com/docs/en/dxl/ax/ax-12a/>; MX-28 on Protocol 1.0: 57 600 bit/s = 34,
model number 29, <https://emanual.robotis.com/docs/en/dxl/mx/mx-28/>); positions per revolution:
4096 (X, MX), 1 003 846 (PH54-200-S500 and H54-200-S500-R(A): ±501 923,
<https://emanual.robotis.com/docs/en/dxl/p/ph54-200-s500-r/>).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import difflib
import inspect
import json
import os
import re
import select
import subprocess
import sys
import tempfile
import termios
import time
from collections import Counter
from pathlib import Path

import common

# --------------------------------------------------------------------------------------------
# The models, one row each: the simulator URL (without ids/baud, added per run), the protocol,
# the examples' MY_DXL selection, the factory-default baud rate and its Baud Rate item value,
# the e-Manual model number, positions per revolution. Edit the URLs here when the simulator
# learns a model or a key (the Protocol 1.0 keys are being added: model=AX-12A,
# model=MX-28&protocol=1, model=XM430-W350&protocol=1).


@dataclasses.dataclass(frozen=True)
class Model:
    """One simulated model as the examples see it."""

    url: str | None          # sim://dynamixel?... without ids and baud; None: not expressible
    protocol: float
    selection: str | None    # MY_DXL value (2.0 examples), None for 1.0
    baud: int                # factory default, bit/s
    baud_number: int         # the Baud Rate item's value for it
    model_number: int
    ticks_per_rev: int = 4096


MODELS: dict[str, Model] = {
    "XM430-W350": Model("sim://dynamixel?model=XM430-W350", 2.0, "X_SERIES", 57600, 1, 1020),
    "XL330-M288": Model("sim://dynamixel?model=XL330-M288", 2.0, "X_SERIES", 57600, 1, 1200),
    "XL-320": Model("sim://dynamixel?model=XL320", 2.0, "XL320", 1_000_000, 3, 350, 1024),
    "PH54-200-S500": Model("sim://dynamixel?model=PH54-200-S500", 2.0, "P_SERIES", 57600, 1,
                           2020, 1_003_846),
    "H54-200-S500-RA": Model("sim://dynamixel?model=H54-200-S500-RA", 2.0, "PRO_A_SERIES",
                             57600, 1, 54025, 1_003_846),
    "MX-28(2.0)": Model("sim://dynamixel?model=MX-28", 2.0, "MX_SERIES", 57600, 1, 30),
    "MX-64(2.0)": Model("sim://dynamixel?model=MX-64", 2.0, "MX_SERIES", 57600, 1, 311),
    "AX-12A": Model("sim://dynamixel?model=AX-12A", 1.0, None, 1_000_000, 1, 12, 1024),
    "MX-28(1.0)": Model("sim://dynamixel?model=MX-28&protocol=1", 1.0, None, 57600, 34, 29),
    "XM430-W350(1.0)": Model("sim://dynamixel?model=XM430-W350&protocol=1", 1.0, None, 57600, 1,
                             1020),
    # protocol_combined.py: ID 1 on Protocol 1.0 and ID 2 on 2.0 on one port, both with the
    # X-series addresses (64/116/132, 4-byte goals): an XM430 set to Protocol Type 1 beside one
    # on 2.0 (the URL names the IDs itself)
    "mixed 1.0+2.0": Model("sim://dynamixel?ids=1:XM430-W350:1,2:XM430-W350", 0.0, None,
                           57600, 1, 1020),
}

DEFAULT_MODELS = tuple(MODELS)

ESC = "\x1b"
PROMPT_CONTINUE = "Press any key to continue"
PROMPTS_ANY_KEY = ("Press any key to terminate", "Press any key to reboot")
PROMPT_SPACE = "Press SPACE key"
NO_STATUS = "[TxRxResult] There is no status packet!"
STUCK_LINES = 20
"""A progress line printed this many times unchanged: the servo does not move (HANG)."""
PORT_NAMES = ("DEVICENAME", "DEVICENAME1", "DEVICENAME2", "SERIAL_PORT")
MOVING_EXAMPLES = {"read_write", "sync_read_write", "bulk_read_write", "fast_sync_read",
                   "fast_bulk_read", "indirect_address", "multi_port", "sync_write",
                   "bulk_read", "protocol_combined"}
ERROR_LINE = re.compile(r"^.*(\[TxRxResult\].*|\[RxPacketError\].*|addparam failed|"
                        r"getdata failed|data unavailable|Failed to .*|Aborted)\s*$", re.M)


# --------------------------------------------------------------------------------------------
# Bugs of the SDK itself that make examples fail on any servo, found in the installed package
# by their signature: (exception text, function whose definition is the cause, explanation).

def _where(obj) -> str:
    """``file.py:line`` of a function of the installed SDK."""
    try:
        return f"{Path(inspect.getsourcefile(obj)).name}:{inspect.getsourcelines(obj)[1]}"
    except (OSError, TypeError):
        return "?"


def known_sdk_bugs() -> list[tuple[str, str]]:
    """(text in a traceback's last line, explanation naming file and line) of the installed
    ``dynamixel_sdk``."""
    from dynamixel_sdk import group_bulk_read, protocol1_packet_handler
    p1 = protocol1_packet_handler.Protocol1PacketHandler
    tx = inspect.getsourcelines(group_bulk_read.GroupBulkRead.txPacket)
    call_line = next((tx[1] + i for i, line in enumerate(tx[0]) if "* 3, False" in line), None)
    return [
        ("factoryReset() takes 3 positional arguments but 4 were given",
         f"SDK bug: Protocol1PacketHandler.factoryReset(port, dxl_id) "
         f"({_where(p1.factoryReset)}) has no option argument, the 1.0 example passes "
         f"OPERATION_MODE (the 2.0 handler's signature)"),
        ("bulkReadTx() takes 4 positional arguments but 5 were given",
         f"SDK bug: GroupBulkRead.txPacket (group_bulk_read.py:{call_line}) passes a "
         f"fast_option to Protocol1PacketHandler.bulkReadTx(port, param, param_length) "
         f"({_where(p1.bulkReadTx)}): every Protocol 1.0 bulk read raises"),
    ]


# --------------------------------------------------------------------------------------------
# Examples and their edits

@dataclasses.dataclass
class Example:
    """One example program of the SDK checkout."""

    name: str                # "2.0/read_write", "1.0/ping", "combined/protocol_combined"
    path: Path
    protocol: float          # 2.0, 1.0, or 0.0 for the mixed-protocol one
    source: str

    @property
    def stem(self) -> str:
        return self.path.stem

    def selections(self) -> list[str]:
        """The MY_DXL values the example offers (its selection lines, commented or not)."""
        return re.findall(r"^#?\s*MY_DXL\s*=\s*'(\w+)'", self.source, re.M)

    def ids(self) -> dict[str, int]:
        """Its ID assignments (``DXL_ID``, ``DXL1_ID``, ...)."""
        return {m[1]: int(m[2]) for m in re.finditer(r"^(DXL\d*_ID)\s*=\s*(\d+)", self.source,
                                                     re.M)}


def find_examples(sdk: Path) -> list[Example]:
    """The example programs of a DynamixelSDK work tree, 2.0 first."""
    tests = sdk / "python" / "tests"
    out = []
    for folder, protocol in (("protocol2_0", 2.0), ("protocol1_0", 1.0)):
        for p in sorted((tests / folder).glob("*.py")):
            out.append(Example(f"{protocol:.1f}/{p.stem}", p, protocol, p.read_text()))
    combined = tests / "protocol_combined.py"
    if combined.exists():
        out.append(Example("combined/protocol_combined", combined, 0.0, combined.read_text()))
    return out


def _branch_of(lines: list[str], i: int) -> str | None:
    """The ``if/elif MY_DXL ...`` line an indented line ``i`` belongs to (None: top level)."""
    indent = len(lines[i]) - len(lines[i].lstrip())
    if indent == 0:
        return None
    for j in range(i - 1, -1, -1):
        s = lines[j]
        if s.strip() and len(s) - len(s.lstrip()) < indent:
            return s if re.match(r"\s*(if|elif)\b.*MY_DXL", s) else None
    return None


def branch_value(ex: Example, selection: str | None, name: str) -> int | None:
    """The integer assigned to ``name`` in the branch of ``selection`` (or at top level)."""
    lines = ex.source.splitlines()
    for i, s in enumerate(lines):
        m = re.match(rf"^\s*{name}\s*=\s*(-?\d+)", s)
        if m:
            branch = _branch_of(lines, i)
            if branch is None or (selection and f"'{selection}'" in branch):
                return int(m[1])
    return None


def edit_example(ex: Example, model: Model, ports: list[str]) -> tuple[str, str]:
    """The user's edit of ``ex`` for ``model`` on ``ports``: (new source, unified diff).

    Only assignment lines change: the port names, the MY_DXL selection (the active line
    commented out, the model's uncommented), BAUDRATE of the selected branch when it differs
    from the servo's factory default.
    """
    lines = ex.source.splitlines(keepends=True)
    sel = model.selection
    if sel and ex.selections():
        for i, s in enumerate(lines):
            m = re.match(r"^MY_DXL(\s*)=\s*'(\w+)'", s)
            if m and m[2] != sel:
                lines[i] = "# " + s
            m = re.match(r"^#\s*(MY_DXL\s*=\s*'(\w+)'.*)$", s, re.S)
            if m and m[2] == sel:
                lines[i] = m[1]
    names = [n for n in PORT_NAMES if re.search(rf"^{n}\s*=", ex.source, re.M)]
    for i, s in enumerate(lines):
        m = re.match(r"^(\s*)(\w+)(\s*=\s*)(['\"])[^'\"]*\4(.*)$", s, re.S)
        if m and m[2] in names:
            k = names.index(m[2]) if len(names) > 1 else 0
            lines[i] = f"{m[1]}{m[2]}{m[3]}'{ports[min(k, len(ports) - 1)]}'{m[5]}"
        m = re.match(r"^(\s*)BAUDRATE(\s*=\s*)(\d+)(.*)$", s, re.S)
        if m and int(m[3]) != model.baud:
            branch = _branch_of(lines, i)
            if branch is None or (sel and f"'{sel}'" in branch):
                lines[i] = f"{m[1]}BAUDRATE{m[2]}{model.baud}{m[4]}"
    new = "".join(lines)
    diff = "".join(difflib.unified_diff(ex.source.splitlines(keepends=True),
                                        new.splitlines(keepends=True),
                                        f"a/{ex.path.name}", f"b/{ex.path.name}", n=0))
    return new, diff


# --------------------------------------------------------------------------------------------
# Simulator

class SimRefused(Exception):
    """The simulator exited instead of printing its pty path (its error line)."""


class Simulator:
    """``rig sim servos URL`` in a child process, as a user starts it; ``path`` is its pty."""

    def __init__(self, url: str, start_timeout: float = 30.0):
        self.url = url
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "rig", "sim", "servos", url], stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, env=common.child_env(),
            cwd=common.ROOT, text=True)
        ready, _, _ = select.select([self.proc.stdout], [], [], start_timeout)
        line = self.proc.stdout.readline().strip() if ready else ""
        if not line.startswith("/dev/"):
            self.proc.kill()
            _, err = self.proc.communicate()
            lines = [s for s in (err or "").splitlines() if s.strip()]
            line = lines[-1].split("; known ")[0] if lines else ""
            raise SimRefused(line or f"no pty path within {start_timeout} s")
        self.path = line

    def close(self) -> str:
        """Stop it (SIGTERM, as the docs say); returns its last error line if it failed."""
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            _, err = self.proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        if self.proc.returncode not in (0, -15):
            lines = [s for s in (err or "").splitlines() if s.strip()]
            return f"simulator exited {self.proc.returncode}: " + (lines[-1] if lines else "")
        return ""


# --------------------------------------------------------------------------------------------
# Running one example on a pty and answering its prompts

@dataclasses.dataclass
class Run:
    """What one run of an example printed and how it ended."""

    output: str
    returncode: int | None   # None: killed after the timeout
    seconds: float
    keys: str
    stalled_s: float = 0.0


def _raw(fd: int) -> bool:
    """Whether the terminal ``fd`` (the example's side of the pty) is out of canonical mode (the
    example is in ``getch``)."""
    try:
        return not termios.tcgetattr(fd)[3] & termios.ICANON
    except termios.error:
        return False


def _last_pos(text: str) -> int | None:
    m = re.findall(r"PresPos:\s*(-?\d+)", text[-400:])
    return int(m[-1]) if m else None


def run_example(script: Path, moves: int, timeout: float, model: Model) -> Run:
    """Run ``script`` on a pty, answer its prompts, kill it after ``timeout`` s without
    progress."""
    master, slave = os.openpty()
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, str(script)], stdin=slave, stdout=slave,
                            stderr=slave, cwd=script.parent, close_fds=True,
                            env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    # the slave stays open here: its termios say when the example waits in getch (a master's
    # own termios do not follow the slave's), and the end is the child's exit, not EIO
    buf = bytearray()
    keys = []
    answered: set[tuple[str, int]] = set()
    space_sent = False
    last_progress = time.monotonic()
    spin_goal = 1_048_575       # clear_multi_turn.py's MAX_POSITION_VALUE
    # past a turn (X: 1.25 turns); a P-series turn (1,003,846) is nearly the example's goal
    space_at = min(int(1.25 * model.ticks_per_rev), int(0.98 * spin_goal))
    killed = False

    def send(key: str) -> None:
        nonlocal last_progress
        os.write(master, key.encode())
        keys.append(key)
        last_progress = time.monotonic()

    while True:
        r, _, _ = select.select([master], [], [], 0.02)
        if r:
            try:
                chunk = os.read(master, 65536)
            except OSError:
                chunk = b""
            if chunk:
                buf.extend(chunk)
                if len(buf) > 4_000_000:  # keep the head (set-up) and the tail
                    del buf[200_000:len(buf) - 2_000_000]
        text = buf.decode(errors="replace")
        done = proc.poll() is not None
        if done and not r:
            break
        if _raw(slave):
            for prompt in (PROMPT_CONTINUE, *PROMPTS_ANY_KEY):
                pos = text.rfind(prompt)
                if pos >= 0 and (prompt, pos) not in answered:
                    answered.add((prompt, pos))
                    continues = sum(1 for p, _ in answered if p == PROMPT_CONTINUE)
                    more = continues <= moves and not space_sent  # CLEAR done: quit
                    send("k" if prompt != PROMPT_CONTINUE or more else ESC)
                    break
        if not space_sent and PROMPT_SPACE in text:
            pos = _last_pos(text)
            stalled = time.monotonic() - last_progress > 0.6 * timeout
            if (pos is not None and pos >= space_at) or stalled:
                send(" ")
                space_sent = True
        if time.monotonic() - last_progress > timeout:
            proc.kill()
            killed = True
            proc.wait()
            break
    try:
        while select.select([master], [], [], 0.05)[0]:
            chunk = os.read(master, 65536)
            if not chunk:
                break
            buf.extend(chunk)
    except OSError:
        pass
    os.close(master)
    os.close(slave)
    return Run(buf.decode(errors="replace"), None if killed else proc.returncode,
               time.monotonic() - t0, "".join(keys),
               time.monotonic() - last_progress if killed else 0.0)


# --------------------------------------------------------------------------------------------
# Judging

@dataclasses.dataclass
class Result:
    example: str
    model: str
    outcome: str             # PASS FAIL HANG SIM REFUSED N/A
    reason: str
    seconds: float = 0.0
    urls: tuple[str, ...] = ()
    diff: str = ""
    keys: str = ""
    output_head: str = ""
    output_tail: str = ""


def _lines(text: str) -> list[str]:
    return [s.strip() for s in re.split(r"[\r\n]+", text) if s.strip()]


def _errors(text: str) -> Counter:
    return Counter(m[1].strip() if m[1].startswith("[") else m[0].strip()
                   for m in ERROR_LINE.finditer(text.replace("\r", "\n")))


def _error_summary(errors: Counter, text: str = "") -> str:
    """The most printed error line and its count, the next one, and (given the output) the
    line printed just before the first error, with how often it was printed."""
    (line, n), *rest = errors.most_common()
    out = f'"{line}" ×{n}'
    if rest:
        out += f' (+ "{rest[0][0]}" ×{rest[0][1]}' + (f", {len(rest) - 1} more" if
                                                      len(rest) > 1 else "") + ")"
    lines = _lines(text)
    first = next((i for i, s in enumerate(lines) if ERROR_LINE.match(s)), None)
    if first:
        before = lines[first - 1]
        out += f', first after "{before[:90]}" (printed {lines.count(before)} times)'
    return out


def _negative_goal_note(ex: Example, model: Model) -> str:
    """The example bug of a negative goal compared with an unsigned read (P, PRO series)."""
    low = branch_value(ex, model.selection, "DXL_MINIMUM_POSITION_VALUE")
    if ex.stem not in MOVING_EXAMPLES or low is None or low >= 0:
        return ""
    return (f" — and it could not end there: the example compares its goal {low} with the "
            f"unsigned value the SDK reads ({low & 0xFFFFFFFF} when reached), an example bug "
            f"that hangs on hardware too")


def judge(ex: Example, model: Model, run: Run, moves: int, bugs: list[tuple[str, str]]
          ) -> tuple[str, str]:
    """(outcome, one-line reason) of a run, by what the example itself checks."""
    text = run.output
    lines = _lines(text)
    errors = _errors(text)
    if run.returncode is None:
        last = lines[-1][:100] if lines else "(nothing)"
        reason = f'timed out after {run.stalled_s:.0f} s still printing "{last}"'
        if errors:
            reason += f"; errors {_error_summary(errors)}"
        return "HANG", reason + _negative_goal_note(ex, model)
    if "Traceback (most recent call last)" in text:
        tail = _lines(text.split("Traceback (most recent call last)")[-1])
        last = tail[-1] if tail else "traceback"
        for needle, why in bugs:
            if needle in last:
                return "FAIL", f"{last} — {why}"
        if last.startswith("NameError") and model.selection and \
                model.selection in ex.selections():
            last += (f" — the example lists {model.selection} but has no branch for it "
                     f"(example bug)")
        if last.startswith("IndexError") and NO_STATUS in errors:
            last += (" in the SDK's readTxRx after late replies: a status packet of an "
                     "earlier instruction taken for this read's is shorter than asked")
        if errors:
            last += f"; errors {_error_summary(errors)}"
        return "FAIL", last
    timeouts = errors.get(NO_STATUS, 0)
    reads = len(re.findall(r"PresPos|Present Position", text))
    sporadic = set(errors) == {NO_STATUS} and timeouts <= max(2, 0.05 * reads)
    if errors and not sporadic:
        summary = _error_summary(errors, text)
        stuck = re.search(r'first after "(.*(PresPos|Present Position).*)" \(printed (\d+)',
                          summary)
        if stuck and int(stuck[3]) >= STUCK_LINES:  # no motion at all, ended by an error
            return "HANG", (f'stuck printing "{stuck[1]}" ({stuck[3]} times) until '
                            f'{summary.split(", first after")[0]} ended it'
                            + _negative_goal_note(ex, model))
        return "FAIL", summary + _negative_goal_note(ex, model)
    outcome, reason = _checks(ex, model, text, lines, run, moves)
    if sporadic and outcome == "PASS":
        reason += (f"; {timeouts} sporadic \"{NO_STATUS}\" in {reads} reads (the host's load: "
                   f"a reply later than the SDK's packet timeout)")
    elif sporadic:
        reason += f"; errors {_error_summary(errors)}"
    return outcome, reason


def _checks(ex: Example, model: Model, text: str, lines: list[str], run: Run, moves: int
            ) -> tuple[str, str]:
    """The example's own success checks on a run that ended without error lines."""
    stem = ex.stem
    if run.returncode != 0:
        return "FAIL", f"exit status {run.returncode}: {lines[-1] if lines else ''}"
    if stem == "ping":
        m = re.search(r"\[ID:(\d+)\] ping Succeeded\. Dynamixel model number : (\d+)", text)
        if not m:
            return "FAIL", "no 'ping Succeeded' line"
        if int(m[2]) != model.model_number:
            return "FAIL", f"model number {m[2]}, e-Manual {model.model_number}"
        return "PASS", f"[ID:{m[1]}] ping Succeeded, model number {m[2]}"
    if stem == "broadcast_ping":
        found = {int(i): int(n) for i, n in
                 re.findall(r"\[ID:(\d+)\] model version : (\d+)", text)}
        want = {i: model.model_number for i in (1, 2)}
        if found != want:
            return "FAIL", f"detected {found or 'nothing'}, expected {want}"
        return "PASS", f"detected IDs {sorted(found)}, model number {model.model_number}"
    if stem == "reboot":
        ok = "reboot Succeeded" in text
        return ("PASS", "reboot answered") if ok else ("FAIL", "no 'reboot Succeeded' line")
    if stem == "factory_reset":
        after = re.findall(r"DXL baudnum is now : (\d+)", text)
        final = re.findall(r"Dynamixel Baudnum is now : (\d+)", text)
        if not after or not final:
            return "FAIL", "the baud rate was not read back"
        if int(after[-1]) != model.baud_number or int(final[-1]) != model.baud_number:
            return "FAIL", (f"Baud Rate read {after[-1]} after the reset and {final[-1]} at "
                            f"the end; the factory default is {model.baud_number}")
        return "PASS", f"Baud Rate {after[-1]} after the reset ({model.baud} bit/s)"
    if stem == "clear_multi_turn":
        m = re.search(r"Present Position has been reset\. : (-?\d+)", text)
        before = re.findall(r"PresPos:\s*(-?\d+)", text.split("Stop & Clear")[0])
        if not m:
            return "FAIL", "no 'Present Position has been reset' line"
        b = int(before[-1]) if before else None
        after, tpr = int(m[1]), model.ticks_per_rev
        if after >= 2**31:  # the SDK reads 4 bytes unsigned: a negative position
            after -= 2**32
        # one turn: X / MX 0..4095; P-series / PRO(A) ±half a turn about 0 (their pages)
        lo = 0 if tpr <= 4096 else -tpr // 2
        if b is None or b < 0.9 * tpr:
            return "FAIL", f"present position {b} -> {after}: not a turn before CLEAR"
        off = (after - b) % tpr
        if not lo <= after < lo + tpr or min(off, tpr - off) > 0.05 * tpr:
            return "FAIL", (f"present position {b} -> {after} after CLEAR; one turn of the "
                            f"model is {tpr} ticks: expected ~{lo + (b - lo) % tpr}")
        return "PASS", f"present position {b} -> {after} after CLEAR ({tpr} ticks a turn)"
    if stem in MOVING_EXAMPLES:
        done = text.count(PROMPT_CONTINUE) - 1
        if done < moves:
            return "FAIL", f"{done} of {moves} moves completed"
        return "PASS", f"{moves} of {moves} moves reached their goal"
    return "PASS", "ran to its end without an error line"


# --------------------------------------------------------------------------------------------
# One (example, model)

def applicable(ex: Example, name: str, model: Model) -> str:
    """Why ``ex`` does not apply to ``model`` ('' when it does)."""
    if ex.protocol == 0.0 or model.protocol == 0.0:
        return "" if ex.protocol == model.protocol else "-"
    if ex.protocol != model.protocol:
        return "-"
    offered = ex.selections()
    if offered and model.selection not in offered:
        return f"the example offers no {model.selection} selection ({', '.join(offered)})"
    return ""


def sim_urls(ex: Example, model: Model) -> list[str]:
    """The simulator URL(s) a run needs: one per port, with the IDs the example uses."""
    ids = ex.ids()
    base = f"{model.url}&baud={model.baud}"
    if "ids=" in model.url:  # a mixed bus names its IDs and their models
        return [base]
    if "DEVICENAME2" in ex.source:
        return [f"{base}&ids={ids.get('DXL1_ID', 1)}", f"{base}&ids={ids.get('DXL2_ID', 2)}"]
    id_list = sorted(set(ids.values())) or [1, 2]
    return [f"{base}&ids={','.join(map(str, id_list))}"]


def run_one(ex: Example, name: str, model: Model, args, bugs) -> Result:
    """Start the simulator(s), edit and run the example, judge it."""
    why = applicable(ex, name, model)
    if why:
        return Result(ex.name, name, "N/A", why)
    if model.url is None:
        return Result(ex.name, name, "N/A", "no simulator URL expresses a bus of Protocol 1.0 "
                      "and 2.0 servos")
    urls = sim_urls(ex, model)
    sims: list[Simulator] = []
    t0 = time.monotonic()
    try:
        for url in urls:
            sims.append(Simulator(url))
    except SimRefused as err:
        for s in sims:
            s.close()
        return Result(ex.name, name, "SIM REFUSED", str(err), time.monotonic() - t0,
                      tuple(urls))
    try:
        with tempfile.TemporaryDirectory(prefix="dxl-example-") as tmp:
            source, diff = edit_example(ex, model, [s.path for s in sims])
            script = Path(tmp) / ex.path.name
            script.write_text(source)
            run = run_example(script, args.moves, args.timeout, model)
    finally:
        crashed = [c for c in (s.close() for s in sims) if c]
    outcome, reason = judge(ex, model, run, args.moves, bugs)
    if crashed:
        outcome, reason = "FAIL", f"{reason}; {crashed[0]}"
    return Result(ex.name, name, outcome, reason, run.seconds, tuple(urls), diff, run.keys,
                  run.output[:1500], run.output[-1500:])


def run_with_retries(ex: Example, name: str, model: Model, args, bugs) -> Result:
    """:func:`run_one`, again (up to ``--retries`` times) while a run FAILs through a status
    packet that came too late, no simulator crashed and the example was not stuck (printing
    one line over and over; a HANG is not retried either): on a loaded host a simulator's
    reply can miss the SDK's packet timeout (~36 ms), which a user would answer by running
    the example again. The result says so."""
    earlier: list[str] = []
    while True:
        r = run_one(ex, name, model, args, bugs)
        stuck = re.search(r"printed (\d+) times", r.reason)
        flaky = (r.outcome == "FAIL" and NO_STATUS in r.reason
                 and "simulator exited" not in r.reason
                 and not (stuck and int(stuck[1]) > 20))
        if not flaky or len(earlier) >= args.retries:
            break
        earlier.append(f"{r.outcome}: {r.reason}")
    if earlier:
        r.reason += f" [run {len(earlier) + 1}; before: " + " | ".join(earlier) + "]"
    return r


# --------------------------------------------------------------------------------------------

def print_table(results: list[Result], models: list[str]) -> None:
    """The example × model matrix of outcomes, then one line per (example, model) run."""
    examples = list(dict.fromkeys(r.example for r in results))
    cell = {(r.example, r.model): r.outcome for r in results}
    w = max(len(e) for e in examples) + 2
    cols = list(models)
    widths = [max(len(m), 11) + 2 for m in cols]
    print("".ljust(w) + "".join(m.ljust(cw) for m, cw in zip(cols, widths, strict=True)))
    for e in examples:
        row = [cell.get((e, m), "") for m in cols]
        if all(c in ("", "N/A") for c in row):
            continue
        print(e.ljust(w) + "".join(c.ljust(cw) for c, cw in zip(row, widths, strict=True)))
    print()
    for r in results:
        if r.outcome == "N/A" and r.reason == "-":
            continue
        print(f"{r.example:<30} {r.model:<17} {r.outcome:<11} {r.reason}"
              f"{f'  [{r.seconds:.1f} s]' if r.seconds else ''}")
    counts = Counter(r.outcome for r in results if r.reason != "-")
    print("\n" + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sdk", required=True, type=Path,
                        help="a DynamixelSDK work tree (its python/tests are run)")
    parser.add_argument("--only", action="append", default=[],
                        help="example name (read_write, 2.0/read_write); repeatable")
    parser.add_argument("--models", nargs="+", default=list(DEFAULT_MODELS),
                        help=f"models to run (default all: {', '.join(DEFAULT_MODELS)})")
    parser.add_argument("--timeout", type=float, default=8.0,
                        help="seconds a run may go without progress (a new prompt or its "
                             "end) before it is killed as HANG (default 8)")
    parser.add_argument("--moves", type=int, default=2,
                        help="keys pressed before ESC in the examples that move (default 2)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="runs in parallel (default 1: each example busy-polls a core "
                             "while it waits for a reply, starving the simulators)")
    parser.add_argument("--retries", type=int, default=2,
                        help="runs again a run that failed through a late status packet "
                             "(default 2)")
    parser.add_argument("--show-diff", action="store_true",
                        help="print the unified diff of each edited copy")
    parser.add_argument("--json", type=Path, help="write the results to this file")
    args = parser.parse_args(argv)
    tests = args.sdk / "python" / "tests"
    if not (tests / "protocol2_0").is_dir():
        print(f"robotis_examples: --sdk {args.sdk}: no python/tests/protocol2_0 there "
              f"(give a DynamixelSDK work tree)", file=sys.stderr)
        return 2
    unknown = [m for m in args.models if m not in MODELS]
    if unknown:
        print(f"robotis_examples: --models: unknown {', '.join(unknown)}; known: "
              f"{', '.join(MODELS)}", file=sys.stderr)
        return 2
    examples = find_examples(args.sdk)
    if args.only:
        examples = [e for e in examples if e.name in args.only or e.stem in args.only]
        if not examples:
            print(f"robotis_examples: --only {', '.join(args.only)}: no such example",
                  file=sys.stderr)
            return 2
    from importlib.metadata import version

    import dynamixel_sdk
    head = subprocess.run(["git", "-C", str(args.sdk), "log", "-1", "--format=%h %cs"],
                          capture_output=True, text=True).stdout.strip()
    print(f"DynamixelSDK examples of {args.sdk} ({head or 'not a git work tree'}); "
          f"dynamixel_sdk {version('dynamixel-sdk')} from "
          f"{Path(dynamixel_sdk.__file__).parent}")
    print(f"--moves {args.moves} --timeout {args.timeout:g} s --jobs {args.jobs} --retries "
          f"{args.retries}; machine: 10^7 additions in {common.additions_s():.2f} s, load "
          f"average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    bugs = known_sdk_bugs()
    jobs = [(e, m) for e in examples for m in args.models]
    t0 = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(max(1, args.jobs)) as pool:
        futures = [pool.submit(run_with_retries, e, m, MODELS[m], args, bugs)
                   for e, m in jobs]
        results = [f.result() for f in futures]
    if args.show_diff:
        for r in results:
            if r.diff:
                print(f"--- {r.example} on {r.model} ({', '.join(r.urls)})\n{r.diff}")
    print_table(results, args.models)
    print(f"wall time {time.monotonic() - t0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps([dataclasses.asdict(r) for r in results
                                         if r.reason != "-"], indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
