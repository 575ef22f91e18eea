#!/usr/bin/env python3
"""Seeded fuzzer for tracer's bad-input promise.

The promise (README "Rendering" and "Output files", docs/SCENE_FORMAT.md "Errors",
docs/DESIGN.md "The render file"): any bad input -- a scene file, a mesh, a render EXR, a noise
baseline, an option -- makes tracer print exactly one line on stderr naming the file and key
and exit with status 2, with no traceback and no hang; and whatever tracer accepts gives finite
outputs (no NaN or inf in an output EXR, JSON or CSV).

This script makes hostile inputs from a seed, runs tracer on each and sorts every outcome:

    ok          exit 0 (or 1, "check failed", for tracer check) and every output finite
    refused     exit 2 and exactly one non-empty stderr line, no traceback; in-process, a
                one-line ``tracer.InputError``
    -- failures --
    traceback   a Python traceback, an exit status the CLI does not define, or in-process an
                exception other than ``tracer.InputError``
    crash       the process died from a signal (segfault, abort, out-of-memory kill)
    hang        no answer within ``--timeout`` seconds
    nonfinite   accepted, but an output EXR/JSON/CSV holds NaN or inf, a promised output is
                missing or unreadable, or a loaded scene or image holds non-finite numbers
    multiline   exit 2 with more (or fewer) than one stderr line, or a multi-line InputError

Reported but not counted as failures: ``unnamed``, a one-line refusal that names none of the
input files (nor "command line"); ``nan-samples``, an accepted render whose summary says
samples came out NaN (set to 0 and counted, as the README promises); ``stderr-noise``, a
successful ``--quiet`` run that printed something else on stderr (a Python warning, say).

Four families of cases, each a folder holding its inputs:

- ``scene``: a shipped scene (``scenes/`` and ``tracer/study/cases/``) parsed and mutated
  structure-aware (deleted, duplicated and unknown keys, swapped types, special numbers, wrong
  vector lengths, long and unicode strings, deep nesting, unknown materials, degenerate
  cameras, zero-area and extreme geometry, very bright lights, damaged or missing meshes, meshes
  that are FIFOs, devices or folders, material values at and beyond the ends of their ranges,
  command-line options), written back as TOML, sometimes also damaged byte by byte. Checks:
  ``tracer.load_scene`` on the file and on the same tables as a dict (in-process), and
  ``tracer render --width 8 --height 8 --spp 2`` (subprocess).
- ``exr``: a render EXR made by tracer, damaged through OpenImageIO (``tracer:*`` header
  attributes, NaN/inf/negative/huge pixel values, sample-count channels, dropped, renamed or
  retyped channels, other sizes, tiles, compression, header fields that contradict each other or
  the pixels: spp against the counts, light samples past the bound, counts past float32) or byte
  by byte (truncated, flipped,
  zeroed). Checks: ``tracer.read_image`` (in-process), then one of ``tracer merge``,
  ``tracer reference --resume``, ``tracer compare --reference`` and ``tracer check`` (with the
  EXR as the baseline entry's reference), in turn.
- ``baseline``: a one-entry noise baseline (``renders/noise_baseline.json`` shape, 1 spp, two
  seeds, an 8 x 8 reference) mutated field by field or damaged as text. Checks:
  ``tracer.study.check.load_baseline`` (in-process) and ``tracer check --baseline`` (sometimes
  with ``--update``). ``tracer check`` renders every valid entry, so mutations keep spp, seeds
  and sample counts either invalid or small: a valid but huge baseline is slow, not broken. The
  baseline, or its entry's scene, is sometimes a FIFO.
- ``xml``: a small Mitsuba 3 scene with hostile changes (``benchmarks/fuzz_xml.py``: growing
  ``$name`` substitutions, include chains, diamonds and cycles, FIFOs and devices, huge strings
  in every slot, polygon meshes, camera matrices near Mitsuba's rigidity tolerance, BSDF
  reference graphs, material extremes). Checks: ``tracer.load_scene`` and ``tracer render``.
- ``scheduler``: ``tracer reference --scheduler ADDRESS`` at malformed addresses, other schemes
  and loopback servers that speak something else (``benchmarks/fuzz_scheduler.py``). Check: one
  line and exit 2 within the connect timeout.

How they run: CLI checks in subprocesses (``python -m tracer ...``, cwd = the case folder,
address space limited to ``--memory-gib``), ``--jobs`` at a time; in-process checks in one
long-lived worker process that imports tracer once and is restarted after a crash or a hang,
so that a segfault in OpenImageIO or a runaway loop is classified, not fatal to the fuzzer.
Subprocesses are faithful (real stderr, signals, exit status); the worker is fast and checks
the Python API's half of the promise (only ``InputError`` escapes).

Every case is a function of (seed, family, index): ``--only exr:17`` makes that one case
again (EXR cases damage renders made at the start of the run, so their bytes follow tracer's
header layout as it is edited). Each failure is copied to
``--keep DIR/<family>-<index>-<check>-<kind>/`` with its inputs, outputs and ``REPRO.txt`` (the
mutations, the command, stderr); ``DIR/failures.json`` lists them with their deduplication
signatures (exception type and tracer function, or the message with its particulars blanked),
``DIR/outcomes.jsonl`` every outcome, ``DIR/summary.txt`` the printed report.

Usage:
    python benchmarks/fuzz.py [--seed S] [--scenes N] [--exrs N] [--baselines N] [--xmls N] [--schedulers N]
                              [--keep DIR] [--jobs 2] [--timeout 120]
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import multiprocessing
import os
import random
import re
import resource
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parent.parent
SCENE_DIRS = (ROOT / "tracer" / "scenes", ROOT / "tracer" / "study" / "cases")
SHIPPED_MESH_DIR = ROOT / "tracer" / "scenes" / "meshes"
BASELINE_FILE = ROOT / "renders" / "noise_baseline.json"

FAMILIES = ("scene", "exr", "baseline", "xml", "scheduler")
# The connect timeout scheduler cases give tracer: every refusal must come within it.
SCHEDULER_TIMEOUT = 5
KINDS = ("ok", "refused", "traceback", "crash", "hang", "nonfinite", "multiline")
FAILURE_KINDS = ("traceback", "crash", "hang", "nonfinite", "multiline")
SEVERITY = {"crash": 0, "hang": 1, "nonfinite": 2, "traceback": 3, "multiline": 4}
NOTE_KINDS = ("unnamed", "nan-samples", "stderr-noise")

TINY_RENDER = ("--width", "8", "--height", "8", "--spp", "2", "--threads", "1", "--quiet")
STRATEGIES = ("uniform", "cosine", "bsdf", "light", "mis")
HEURISTICS = ("balance", "power", "max")


# =============================================================================================
# Cases, checks and outcomes


@dataclass
class Check:
    """One use of a case's inputs: a command line (``python -m tracer ARGV`` in a subprocess,
    cwd = the case folder) or an in-process API call (``probe = (kind, args)``, run by the
    probe worker).

    allowed : exit statuses that are not failures (2 is judged as a refusal).
    outputs : files or folders (relative) that must exist and be finite after a success.
    optional_outputs : files or folders checked for finiteness if they exist.
    inputs : names a refusal may mention to count as naming the file (else a note).
    timeout : seconds after which this check counts as a hang, if shorter than the run's.
    """

    name: str
    argv: list[str] | None = None
    probe: tuple[str, tuple] | None = None
    allowed: tuple[int, ...] = (0, 2)
    outputs: tuple[str, ...] = ()
    optional_outputs: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    timeout: float | None = None


@dataclass
class Case:
    """A folder of hostile inputs, what was done to make them, and the checks that use them."""

    family: str
    index: int
    folder: Path
    mutations: list[str] = field(default_factory=list)
    checks: list[Check] = field(default_factory=list)

    @property
    def label(self) -> str:
        return f"{self.family}:{self.index}"


@dataclass
class Outcome:
    """The class of one check of one case, with what decided it and a deduplication key."""

    case: Case
    check: Check
    kind: str
    detail: str
    signature: str = ""
    stderr: str = ""
    notes: tuple[str, ...] = ()
    seconds: float = 0.0


def normalize_message(text: str) -> str:
    """A message with its particulars (quoted values, numbers, paths) blanked, so that one
    kind of refusal or exception counts once however the fuzzer reached it."""
    text = text.strip().replace("\n", "⏎").removeprefix("tracer: error: ")
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "'…'", text)
    text = re.sub(r"[^\s:'(]*(\.toml|\.exr|\.json|\.ply)\b|<dict>", "FILE", text)
    text = re.sub(r"(/[^\s:,;)]+)+", "PATH", text)
    text = re.sub(r"\[[^\]]*\]", "[…]", text)
    text = re.sub(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", "N", text)
    return text[:160]


_FRAME = re.compile(r'File "([^"]+)", line (\d+), in (\S+)')


def traceback_summary(stderr: str) -> tuple[str, str]:
    """(exception line, innermost location inside tracer) of a printed traceback."""
    frames = _FRAME.findall(stderr)
    inside = [f for f in frames if "/tracer/" in f[0].replace("\\", "/")] or frames
    location = ""
    if inside:
        path, line, func = inside[-1]
        tail = path.replace("\\", "/").split("/tracer/")[-1]
        location = f"tracer/{tail}:{line} in {func}"
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    headlines = [ln for ln in lines if not ln[0].isspace() and ":" in ln]
    final = headlines[-1] if headlines else (lines[-1] if lines else "")
    return final.strip()[:300], location


def signature_of_exception(final: str, location: str) -> str:
    """Dedup key of a traceback: the exception type and where in tracer it was raised (the
    function, not the line number, which moves as tracer is edited)."""
    exc_type = final.split(":", 1)[0].strip()
    where = re.sub(r":\d+ in ", ":", location)
    return f"{exc_type} at {where or '?'}"


# =============================================================================================
# Output checks


def _strict_constant(name: str) -> Any:
    raise ValueError(f"non-finite JSON constant {name}")


def exr_problem(path: Path) -> str | None:
    """Why an output EXR is not a finite, readable image (None if it is)."""
    import numpy as np
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return f"{path.name}: unreadable ({oiio.geterror()[:100]})"
    try:
        spec = inp.spec()
        data = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    if data is None:
        return f"{path.name}: unreadable pixels"
    data = np.asarray(data).reshape(-1, spec.nchannels)
    for c, name in enumerate(spec.channelnames):
        bad = ~np.isfinite(data[:, c])
        if bad.any():
            value = data[np.argmax(bad), c]
            return f"{path.name}: channel {name} holds {value} in {int(bad.sum())} pixel(s)"
    for attribute in spec.extra_attribs:
        if isinstance(attribute.value, float) and not math.isfinite(attribute.value):
            return f"{path.name}: header {attribute.name} = {attribute.value}"
    return None


def json_problem(path: Path) -> str | None:
    """Why an output JSON is not strict, finite JSON (None if it is)."""
    try:
        json.loads(path.read_text(), parse_constant=_strict_constant)
    except (ValueError, UnicodeDecodeError) as exc:
        return f"{path.name}: {str(exc)[:120]}"
    return None


def csv_problem(path: Path) -> str | None:
    """Why an output CSV holds a non-finite number (None if it does not)."""
    for number, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        for cell in line.split(","):
            cell = cell.strip().strip('"')
            try:
                value = float(cell)
            except ValueError:
                continue
            if not math.isfinite(value):
                return f"{path.name}: line {number} holds {cell}"
    return None


def output_problem(folder: Path, required: tuple[str, ...], optional: tuple[str, ...]) -> str | None:
    """The first problem of a successful run's outputs: a required one missing, or an EXR,
    JSON or CSV among them (files, or every file in a folder) that is not finite."""
    files: list[Path] = []
    for name, must in [(n, True) for n in required] + [(n, False) for n in optional]:
        path = folder / name
        if not path.exists():
            if must:
                return f"{name}: missing after exit 0"
            continue
        files += sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    checkers: dict[str, Callable[[Path], str | None]] = {".exr": exr_problem, ".json": json_problem,
                                                         ".csv": csv_problem}
    for path in files:
        checker = checkers.get(path.suffix.lower())
        problem = checker(path) if checker else None
        if problem:
            return problem
    return None


# =============================================================================================
# Running: subprocesses for the CLI, one worker process for the API


def run_cli(case: Case, check: Check, timeout: float, memory_bytes: int) -> Outcome:
    """Run ``python -m tracer ARGV`` in the case folder and classify what it did."""
    timeout = min(timeout, check.timeout or timeout)
    command = [sys.executable, "-m", "tracer", *check.argv]
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", COLUMNS="80")
    start = time.monotonic()
    proc = subprocess.Popen(command, cwd=case.folder, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env, start_new_session=True)
    try:
        # The child is still starting Python when the limit lands: a runaway allocation then
        # ends in MemoryError (or a kill) instead of exhausting a shared machine.
        resource.prlimit(proc.pid, resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    except (OSError, ValueError):
        pass
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
        timed_out = False
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # its own session: this process and its children
        stdout, stderr = proc.communicate()
        timed_out = True
    seconds = time.monotonic() - start
    err = stderr.decode("utf-8", errors="replace")
    kind, detail, signature, notes = classify_cli(case, check, proc.returncode, err, timed_out, timeout)
    return Outcome(case, check, kind, detail, signature, err, notes, seconds)


def classify_cli(case: Case, check: Check, returncode: int, stderr: str, timed_out: bool,
                 timeout: float) -> tuple[str, str, str, tuple[str, ...]]:
    """(kind, detail, signature, notes) of a finished command."""
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if timed_out:
        return "hang", f"no exit within {timeout:g} s", f"{check.name}: hang", ()
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        last = lines[-1] if lines else ""
        return "crash", f"killed by {name}: {last[:200]}", f"{check.name}: {name}", ()
    if "Traceback (most recent call last)" in stderr:
        final, location = traceback_summary(stderr)
        return "traceback", f"{final} [{location}]", signature_of_exception(final, location), ()
    if returncode not in check.allowed and returncode != 2:
        last = lines[-1] if lines else "(no stderr)"
        return "traceback", f"exit status {returncode}: {last[:200]}", f"{check.name}: exit {returncode}", ()
    if returncode == 2:
        if len(lines) != 1:
            usage = any(ln.startswith("usage:") for ln in lines)
            what = "argparse usage + error" if usage else normalize_message(stderr)
            return "multiline", f"{len(lines)} lines: " + " | ".join(ln[:120] for ln in lines[:4]), \
                f"multi-line message: {what}", ()
        notes = () if names_an_input(lines[0], check.inputs) else ("unnamed",)
        return "refused", lines[0][:300], normalize_message(lines[0]), notes
    problem = output_problem(case.folder, check.outputs, check.optional_outputs)
    if problem:
        return "nonfinite", problem, f"{check.name}: {normalize_message(problem)}", ()
    nan_lines = [ln for ln in lines if "NaN or infinite" in ln]
    notes = ("nan-samples",) if nan_lines else ()
    noise = [ln for ln in lines if ln not in nan_lines]
    if noise and "--quiet" in check.argv:
        notes += ("stderr-noise",)  # a quiet run that succeeded says nothing else
        return "ok", noise[0][:200], normalize_message(noise[0]), notes
    return "ok", (lines[-1] if lines else "")[:200], "", notes


def names_an_input(line: str, inputs: tuple[str, ...]) -> bool:
    """Whether a refusal names one of the inputs (or the command line)."""
    return "command line" in line or "--" in line or any(name and name in line for name in inputs)


def _limit_memory(memory_bytes: int) -> None:
    try:
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    except (OSError, ValueError):
        pass


def probe_worker(conn, memory_bytes: int) -> None:
    """The in-process half: answer ``(kind, args)`` requests with outcome dicts until None."""
    _limit_memory(memory_bytes)
    sys.stdout = sys.stderr  # nothing tracer prints can reach the pipe
    while True:
        request = conn.recv()
        if request is None:
            return
        conn.send(run_probe(*request))


def run_probe(kind: str, args: tuple) -> dict[str, Any]:
    """One API call: ``tracer.InputError`` is a refusal (one line, or multiline), any other
    exception a traceback; a returned scene, image or baseline must hold finite numbers."""
    import tracer

    try:
        problem = PROBES[kind](*args)
    except tracer.InputError as exc:
        message = str(exc)
        lines = [ln for ln in message.splitlines() if ln.strip()]
        if len(lines) != 1:
            return {"kind": "multiline", "detail": f"InputError of {len(lines)} lines: {message[:300]!r}",
                    "signature": f"multi-line message: {normalize_message(message)}"}
        return {"kind": "refused", "detail": message[:300], "signature": normalize_message(message)}
    except BaseException as exc:  # noqa: BLE001 - every escape is the finding
        if isinstance(exc, KeyboardInterrupt):
            raise
        frames = traceback.extract_tb(exc.__traceback__)
        inside = [f for f in frames if "/tracer/" in f.filename.replace("\\", "/")] or frames
        location = ""
        if inside:
            tail = inside[-1].filename.replace("\\", "/").split("/tracer/")[-1]
            location = f"tracer/{tail}:{inside[-1].lineno} in {inside[-1].name}"
        final = f"{type(exc).__name__}: {exc}"
        return {"kind": "traceback", "detail": f"{final[:250]} [{location}]",
                "signature": signature_of_exception(final, location),
                "stderr": "".join(traceback.format_exception(exc))[-4000:]}
    if problem:
        return {"kind": "nonfinite", "detail": problem, "signature": f"{kind}: {normalize_message(problem)}"}
    return {"kind": "ok", "detail": "", "signature": ""}


def _nonfinite_fields(label: str, obj: Any) -> str | None:
    """The first attribute of ``obj`` (arrays and floats) that holds NaN or inf."""
    import numpy as np

    for name, value in vars(obj).items():
        if isinstance(value, np.ndarray) and value.dtype.kind == "f" and not np.all(np.isfinite(value)):
            return f"{label}.{name} holds non-finite values"
        if isinstance(value, float) and not math.isfinite(value):
            return f"{label}.{name} = {value}"
    return None


def _probe_load_scene(source: Any, base_dir: str | None = None) -> str | None:
    import tracer

    scene = tracer.load_scene(source, base_dir=base_dir)
    return (_nonfinite_fields("scene", scene) or _nonfinite_fields("scene.camera", scene.camera)
            or _nonfinite_fields("scene.materials", scene.materials))


def _probe_read_exr(path: str) -> str | None:
    import numpy as np

    import tracer
    from tracer.imagefiles import exr_is_half

    image = tracer.read_image(path)
    exr_is_half(path)
    for name in ("mean", "variance", "variance_of_mean"):
        if not np.all(np.isfinite(getattr(image, name))):
            return f"read_image(...).{name} holds non-finite values"
    return None


def _probe_load_baseline(path: str) -> str | None:
    from tracer.study.check import load_baseline

    load_baseline(path)
    return None


PROBES: dict[str, Callable[..., str | None]] = {
    "load_scene": _probe_load_scene,
    "read_image": _probe_read_exr,
    "load_baseline": _probe_load_baseline,
}


class ProbeWorker:
    """A process that imports tracer once and runs API probes; restarted after a crash or a
    timeout, which are classified instead of ending the fuzzer."""

    def __init__(self, timeout: float, memory_bytes: int):
        self.timeout = timeout
        self.memory_bytes = memory_bytes
        self.context = multiprocessing.get_context("spawn")
        self.process = None
        self.conn = None

    def _start(self) -> None:
        parent, child = self.context.Pipe()
        self.process = self.context.Process(target=probe_worker, args=(child, self.memory_bytes), daemon=True)
        self.process.start()
        child.close()
        self.conn = parent

    def _stop(self) -> None:
        if self.process is not None:
            self.process.kill()
            self.process.join()
        self.process = self.conn = None

    def close(self) -> None:
        if self.process is not None and self.process.is_alive():
            try:
                self.conn.send(None)
                self.process.join(timeout=10)
            except (OSError, EOFError):
                pass
        self._stop()

    def run(self, case: Case, check: Check) -> Outcome:
        if self.process is None:
            self._start()
        start = time.monotonic()
        try:
            self.conn.send(check.probe)
            # The first request also waits for the worker to import tracer.
            ready = self.conn.poll(self.timeout)
            answer = self.conn.recv() if ready else None
        except (EOFError, OSError, BrokenPipeError):
            ready, answer = True, None
        seconds = time.monotonic() - start
        if answer is None:
            code = self.process.exitcode if self.process is not None else None
            self._stop()
            if not ready:
                return Outcome(case, check, "hang", f"no answer within {self.timeout:g} s",
                               f"{check.name}: hang", seconds=seconds)
            return Outcome(case, check, "crash", f"worker died (exit code {code})",
                           f"{check.name}: worker died ({code})", seconds=seconds)
        notes = ()
        if answer["kind"] == "refused" and not names_an_input(answer["detail"], check.inputs):
            notes = ("unnamed",)
        return Outcome(case, check, answer["kind"], answer["detail"], answer["signature"],
                       answer.get("stderr", ""), notes, seconds)


# =============================================================================================
# TOML and JSON writing, with raw text for what Python values cannot say


@dataclass(frozen=True)
class Raw:
    """A value written verbatim into the TOML or JSON text (hex integers, datetimes, numbers
    past Python's limits, nesting deeper than a Python structure should go)."""

    text: str


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def toml_string(text: str) -> str:
    out = ['"']
    for ch in text:
        code = ord(ch)
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif code < 0x20 or code == 0x7F:
            out.append(f"\\u{code:04x}")
        elif 0xD800 <= code <= 0xDFFF:
            out.append("\\ufffd")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def toml_key(key: Any) -> str:
    key = str(key)
    return key if _BARE_KEY.fullmatch(key) else toml_string(key)


def toml_inline(value: Any) -> str:
    """A TOML value on one line (inline tables and arrays)."""
    if isinstance(value, Raw):
        return value.text
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_inline(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_inline(v)}" for k, v in value.items()) + "}"
    if hasattr(value, "isoformat"):
        return value.isoformat()
    return toml_string(repr(value))


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def toml_dumps(doc: dict[str, Any], inline: bool = False) -> str:
    """``doc`` as TOML: tables as ``[headers]`` and arrays of tables as ``[[headers]]`` (or all
    inline with ``inline``), deeper values inline."""
    lines: list[str] = []

    def emit(path: list[str], table: dict[str, Any]) -> None:
        nested = [] if inline else [k for k, v in table.items() if isinstance(v, dict) or _is_table_array(v)]
        if path:
            lines.append("[" + ".".join(toml_key(p) for p in path) + "]")
        for key, value in table.items():
            if key not in nested:
                lines.append(f"{toml_key(key)} = {toml_inline(value)}")
        for key in nested:
            value = table[key]
            if isinstance(value, dict):
                emit(path + [key], value)
                continue
            for item in value:
                lines.append("[[" + ".".join(toml_key(p) for p in path + [key]) + "]]")
                for k, v in item.items():
                    lines.append(f"{toml_key(k)} = {toml_inline(v)}")

    emit([], doc)
    return "\n".join(lines) + "\n"


def json_dumps(doc: Any) -> str:
    """``doc`` as JSON (NaN and Infinity as Python writes them), ``Raw`` values verbatim."""
    raws: dict[str, str] = {}

    def replace(value: Any) -> Any:
        if isinstance(value, Raw):
            key = f"@@raw{len(raws)}@@"
            raws[key] = value.text
            return key
        if isinstance(value, dict):
            return {k: replace(v) for k, v in value.items()}
        if isinstance(value, list):
            return [replace(v) for v in value]
        return value

    text = json.dumps(replace(doc), indent=1)
    for key, raw in raws.items():
        text = text.replace(json.dumps(key), raw)
    return text


def contains_raw(value: Any) -> bool:
    if isinstance(value, Raw):
        return True
    if isinstance(value, dict):
        return any(contains_raw(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(contains_raw(v) for v in value)
    return False


# =============================================================================================
# Paths into nested documents


def walk(node: Any, path: tuple = ()):
    """Every (path, value) of a nested dict/list document, the root first."""
    yield path, node
    if isinstance(node, dict):
        for key, value in list(node.items()):
            yield from walk(value, path + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from walk(value, path + (i,))


def get_at(doc: Any, path: tuple) -> Any:
    for part in path:
        doc = doc[part]
    return doc


def set_at(doc: Any, path: tuple, value: Any) -> None:
    get_at(doc, path[:-1])[path[-1]] = value


def del_at(doc: Any, path: tuple) -> None:
    del get_at(doc, path[:-1])[path[-1]]


def path_text(path: tuple) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "(root)"


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def is_vector(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(is_number(v) for v in value)


# =============================================================================================
# Hostile values

SPECIAL_NUMBERS: tuple[Any, ...] = (
    0, 0.0, -0.0, -1, 1, 0.5, 7.0, 1e-300, 5e-324, 1.4e-45, 1e-38, 1e-7, 179, 179.0000001, 180, 360,
    1e15, 1.0000001e15, -1e15, 1e18, 1.01e18, 3.4e38, 1e39, 1e308, 1.7976931348623157e308,
    math.inf, -math.inf, math.nan, 2**31 - 1, 2**31, 2**53 + 1, 2**63 - 1, -(2**63), 2**64,
    32768, 32769, Raw("0x7fffffff"), Raw("+inf"), Raw("-nan"), Raw("1_000"), Raw("1e400"),
    Raw("9" * 5000), Raw("0." + "0" * 400 + "1"),
)
ODD_STRINGS: tuple[str, ...] = (
    "", " ", "x", "mis", "MIS", "diffuse ", "quad\n", "a\nb", "tab\there", "nul\x00byte", "\u202ereversed",
    "émoji 🎨", "\ufeffbom", "ü" * 300, "x" * 10000, "../../../etc/passwd", "%s%s%n", "{}", "[[shapes]]",
)
OTHER_TYPES: tuple[Any, ...] = (
    "string", 1, 1.5, True, False, [], {}, [1, 2, 3], ["a", "b", "c"], [[1, 2, 3]], {"a": 1},
    {"x": [1, 2, 3]}, Raw("1979-05-27T07:32:00Z"), Raw("07:32:00"), Raw("1979-05-27"),
)


def special_number(rng: random.Random) -> Any:
    return rng.choice(SPECIAL_NUMBERS)


# =============================================================================================
# Scene mutations: each takes (rng, doc, context) and returns a description, or None when it
# does not apply to this document. They change the parsed TOML document in place.


@dataclass
class SceneContext:
    """What a scene mutation may touch besides the document: the case folder (for meshes)."""

    folder: Path
    text_damage: list[Callable[[random.Random, bytes], tuple[bytes, str]]] = field(default_factory=list)


def _pick(rng: random.Random, doc: Any, want: Callable[[tuple, Any], bool]) -> tuple | None:
    paths = [p for p, v in walk(doc) if p and want(p, v)]
    return rng.choice(paths) if paths else None


def mutate_delete_key(rng, doc, ctx):
    path = _pick(rng, doc, lambda p, v: isinstance(p[-1], str))
    if path is None:
        return None
    del_at(doc, path)
    return f"delete {path_text(path)}"


def mutate_duplicate(rng, doc, ctx):
    arrays = [p for p, v in walk(doc) if _is_table_array(v)]
    if arrays and rng.random() < 0.5:
        path = rng.choice(arrays)
        items = get_at(doc, path)
        copies = rng.choice((1, 2, 50))
        items.extend(copy.deepcopy(rng.choice(items)) for _ in range(copies))
        return f"duplicate an element of {path_text(path)} x{copies}"
    source = _pick(rng, doc, lambda p, v: isinstance(p[-1], str))
    target = _pick(rng, doc, lambda p, v: isinstance(v, dict))
    if source is None or target is None:
        return None
    get_at(doc, target)[source[-1]] = copy.deepcopy(get_at(doc, source))
    return f"copy {path_text(source)} into {path_text(target) if target else '(root)'}"


def mutate_swap_type(rng, doc, ctx):
    path = _pick(rng, doc, lambda p, v: True)
    if path is None:
        return None
    old = get_at(doc, path)
    choices = [t for t in OTHER_TYPES if type(t) is not type(old)]
    value = copy.deepcopy(rng.choice(choices))
    set_at(doc, path, value)
    return f"{path_text(path)}: {type(old).__name__} -> {toml_inline(value)[:40]}"


def mutate_special_number(rng, doc, ctx):
    path = _pick(rng, doc, lambda p, v: is_number(v))
    if path is None:
        return None
    value = special_number(rng)
    if rng.random() < 0.3:  # the whole vector, not one component
        parent = path[:-1]
        if parent and is_vector(get_at(doc, parent)):
            set_at(doc, parent, [value] * len(get_at(doc, parent)))
            return f"{path_text(parent)} = all {toml_inline(value)[:40]}"
    set_at(doc, path, value)
    return f"{path_text(path)} = {toml_inline(value)[:40]}"


# Values at the edge of what docs/SCENE_FORMAT.md accepts, by the key that holds them.
BOUNDARY_VALUES: dict[str, tuple[Any, ...]] = {
    "position": (1e15, -1e15, 9.99e14, 5e-324, -0.0, 1e-300, 1e-38),
    "emission": (1e18, 5e-324, 1e-45, 0.0, 3.4e38 / 1e21),
    "intensity": (1e18, 5e-324, 0.0),
    "reflectance": (0.0, 1.0, 5e-324),
    "alpha": (5e-324, 1e-300, 1e-12, 10.0, 9.999),
    "fov": (5e-324, 1e-300, 1e-6, 179.0, 178.9999),
    "radius": (1e15, 1e-6, 1e-29, 1e-30),
    "subdivisions": (0, 7),
}
VALUE_CLASS = {"origin": "position", "target": "position", "up": "position", "edge1": "position",
               "edge2": "position", "center": "position", "position": "position"}


def mutate_boundary_value(rng, doc, ctx):
    """A number (or a whole vector) at the edge of its accepted range: the scene stays valid."""
    def value_class(path: tuple) -> str | None:
        key = path[-1] if isinstance(path[-1], str) else (path[-2] if len(path) > 1 else None)
        key = VALUE_CLASS.get(key, key)
        return key if key in BOUNDARY_VALUES else None

    path = _pick(rng, doc, lambda p, v: (is_number(v) or is_vector(v)) and value_class(p) is not None)
    if path is None:
        return None
    value = rng.choice(BOUNDARY_VALUES[value_class(path)])
    old = get_at(doc, path)
    if is_vector(old):
        new = [value] * len(old) if rng.random() < 0.5 else old[:-1] + [value]
        set_at(doc, path, new)
        return f"{path_text(path)} = {new}"
    set_at(doc, path, value)
    return f"{path_text(path)} = {value!r}"


def mutate_vector_length(rng, doc, ctx):
    path = _pick(rng, doc, lambda p, v: is_vector(v))
    if path is None:
        return None
    vector = get_at(doc, path)
    how = rng.choice(("empty", "short", "long", "huge", "nested", "strings"))
    new = {"empty": [], "short": vector[:-1], "long": vector + [1.0], "huge": [0.5] * 100000,
           "nested": [vector], "strings": [str(x) for x in vector]}[how]
    set_at(doc, path, new)
    return f"{path_text(path)}: vector made {how}"


def mutate_long_string(rng, doc, ctx):
    path = _pick(rng, doc, lambda p, v: isinstance(v, str))
    if path is None:
        return None
    length = rng.choice((300, 5000, 1_000_000))
    set_at(doc, path, rng.choice("ab/é") * length)
    return f"{path_text(path)}: string of {length} characters"


def mutate_odd_text(rng, doc, ctx):
    """An odd string as a value or as a key (newlines, NUL, bidi, emoji, BOM)."""
    text = rng.choice(ODD_STRINGS[:-2])
    if rng.random() < 0.5:
        path = _pick(rng, doc, lambda p, v: isinstance(v, str))
        if path is not None:
            set_at(doc, path, text)
            return f"{path_text(path)} = {text!r}"
    path = _pick(rng, doc, lambda p, v: isinstance(v, dict) and bool(v))
    table = get_at(doc, path) if path is not None else doc
    if not table:
        return None
    key = rng.choice(list(table))
    table[text] = table.pop(key)
    return f"rename key {path_text((path or ()) + (key,))} to {text!r}"


def mutate_deep_nesting(rng, doc, ctx):
    path = _pick(rng, doc, lambda p, v: True)
    if path is None:
        return None
    depth = rng.choice((30, 300, 3000, 30000))
    if rng.random() < 0.5:
        value = Raw("{a = " * depth + "1" + "}" * depth)
    else:
        value = Raw("[" * depth + "1" + "]" * depth)
    set_at(doc, path, value)
    return f"{path_text(path)}: nested {depth} deep"


def mutate_unknown_key(rng, doc, ctx):
    path = _pick(rng, doc, lambda p, v: isinstance(v, dict))
    table = get_at(doc, path) if path is not None and rng.random() < 0.8 else doc
    key = rng.choice(("colour", "Type", "emision", "radius ", "materials", "1", "ключ", "a.b", "\n"))
    table[key] = rng.choice((1, "x", [1, 2, 3], {"y": 2}))
    return f"unknown key {key!r} in {path_text(path or ())}"


def mutate_unknown_material(rng, doc, ctx):
    shapes = _shapes(doc)
    how = rng.choice(("name", "drop_table", "empty_table", "rename"))
    if how == "drop_table" and "materials" in doc:
        del doc["materials"]
        return "delete the [materials] table"
    if how == "empty_table":
        doc["materials"] = {}
        return "empty [materials]"
    if how == "rename" and isinstance(doc.get("materials"), dict) and doc["materials"]:
        old = rng.choice(list(doc["materials"]))
        doc["materials"][old + "_renamed"] = doc["materials"].pop(old)
        return f"rename material {old!r}"
    if not shapes:
        return None
    name = rng.choice(("gold", "", "(none)", "White", "white ", "a\nb", "x" * 500))
    rng.choice(shapes)["material"] = name
    return f"a shape's material = {name!r}"


def mutate_fov(rng, doc, ctx):
    camera = doc.get("camera")
    if not isinstance(camera, dict):
        return None
    fov = rng.choice((0, 0.0, -1.0, 1e-300, 5e-324, 1e-7, 1e-3, 178.99999, 179, 179.0, 179.0000001, 180, 1000,
                      math.nan, math.inf))
    camera["fov"] = fov
    return f"camera.fov = {fov}"


def mutate_degenerate_camera(rng, doc, ctx):
    camera = doc.get("camera")
    if not isinstance(camera, dict) or not is_vector(camera.get("origin")) or len(camera["origin"]) != 3:
        return None
    origin = [float(x) for x in camera["origin"]]
    target = camera.get("target")
    target = list(target) if is_vector(target) and len(target) == 3 else [0.0, 0.0, 0.0]
    forward = [target[i] - origin[i] for i in range(3)]
    how = rng.choice(("target=origin", "target~origin", "target tiny", "up=0", "up=forward", "up~forward",
                      "up tiny", "up huge", "origin far", "inside-out", "origin 1e15"))
    if how == "target=origin":
        camera["target"] = list(origin)
    elif how == "target~origin":
        camera["target"] = [origin[0], origin[1], origin[2] + rng.choice((1e-13, 1e-11, 1e-9))]
    elif how == "target tiny":
        camera["origin"], camera["target"] = [0.0, 0.0, 1e-11], [0.0, 0.0, 0.0]
    elif how == "up=0":
        camera["up"] = [0.0, 0.0, 0.0]
    elif how == "up=forward":
        camera["up"] = [f * rng.choice((1.0, -3.0)) for f in forward]
    elif how == "up~forward":
        eps = rng.choice((1e-4, 1e-5, 1e-6))
        camera["up"] = [forward[0] + eps, forward[1], forward[2]]
    elif how == "up tiny":
        camera["up"] = [0.0, rng.choice((1e-300, 5e-324, 1e-30)), 0.0]
    elif how == "up huge":
        camera["up"] = [0.0, 1e15, 1e-3]
    elif how == "origin far":
        camera["origin"] = [origin[0], origin[1], 1e15]
    elif how == "inside-out":
        camera["origin"], camera["target"] = list(target), list(origin)
    else:
        camera["origin"] = [1e15, 1e15, 1e15]
        camera["target"] = [1e15, 1e15, 1e15 - 1.0]
    return f"camera: {how}"


def _shapes(doc: dict[str, Any], kind: str | None = None, emitting: bool | None = None) -> list[dict]:
    shapes = doc.get("shapes")
    if not isinstance(shapes, list):
        return []
    out = []
    for s in shapes:
        if not isinstance(s, dict) or (kind and s.get("type") != kind):
            continue
        emits = is_vector(s.get("emission")) and any(x > 0 for x in s["emission"])
        if emitting is None or emits == emitting:
            out.append(s)
    return out


def mutate_zero_area(rng, doc, ctx):
    quads = _shapes(doc, "quad")
    emitters = [q for q in quads if q in _shapes(doc, emitting=True)]
    pool = emitters if emitters and rng.random() < 0.7 else quads
    if pool and rng.random() < 0.7:
        quad = rng.choice(pool)
        e1 = quad.get("edge1") if is_vector(quad.get("edge1")) else [1.0, 0.0, 0.0]
        how = rng.choice(("edge1=0", "edge2=edge1", "edge2=-edge1", "edge2 tiny", "both tiny", "sliver"))
        if how == "edge1=0":
            quad["edge1"] = [0.0, 0.0, 0.0]
        elif how == "edge2=edge1":
            quad["edge2"] = list(e1)
        elif how == "edge2=-edge1":
            quad["edge2"] = [-x for x in e1]
        elif how == "edge2 tiny":
            quad["edge2"] = [x * 1e-9 for x in (quad.get("edge2") or e1)]
        elif how == "both tiny":
            quad["edge1"], quad["edge2"] = [1e-20, 0.0, 0.0], [0.0, 0.0, 1e-20]
        else:
            quad["edge2"] = [x + 1e-12 for x in e1]
        return f"{'emitting ' if quad in emitters else ''}quad: {how}"
    spheres = _shapes(doc, "sphere")
    if not spheres:
        return None
    sphere = rng.choice(spheres)
    radius = rng.choice((1e-30, 1e-29, 1e-20, 1e-12, 1e-6))
    sphere["center"] = [0.0, 0.0, 0.0] if radius < 1e-12 else sphere.get("center", [0.0, 0.0, 0.0])
    sphere["radius"] = radius
    return f"sphere radius {radius:g}"


def _quad_point(quad: dict[str, Any], offset: float) -> list[float] | None:
    """A point ``offset`` in front of a quad's centre (None if the quad is not well formed)."""
    try:
        o, e1, e2 = (list(map(float, quad[k])) for k in ("origin", "edge1", "edge2"))
    except (KeyError, TypeError, ValueError):
        return None
    if len(o) != 3 or len(e1) != 3 or len(e2) != 3:
        return None
    n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]]
    length = math.sqrt(sum(x * x for x in n)) or 1.0
    return [o[i] + 0.5 * e1[i] + 0.5 * e2[i] + offset * n[i] / length for i in range(3)]


def mutate_bright_light(rng, doc, ctx):
    """Radiance and intensity at the format's limit (1e18), near surfaces or tiny: squares and
    1/d^2 terms that float32 outputs may not hold."""
    how = rng.choice(("point near surface", "emission max", "emission max huge quad", "emission tiny",
                      "intensity max", "emitter near camera"))
    quads = [q for q in _shapes(doc, "quad") if _quad_point(q, 0.0)]
    if how == "point near surface" and quads:
        d = rng.choice((1e-2, 1e-4, 1e-7))
        position = _quad_point(rng.choice(quads), d)
        intensity = rng.choice((1e18, 1e12, 1.0))
        if not isinstance(doc.get("lights"), list):
            doc["lights"] = []
        doc["lights"].append({"type": "point", "position": position, "intensity": [intensity] * 3})
        return f"point light of intensity {intensity:g} at {d:g} from a quad"
    if how == "intensity max" and isinstance(doc.get("lights"), list) and doc["lights"]:
        light = rng.choice(doc["lights"])
        if isinstance(light, dict):
            light["intensity"] = [1e18, 1e18, 1e18]
            return "a point light's intensity = 1e18"
    emitters = _shapes(doc, emitting=True) or _shapes(doc)
    if not emitters:
        return None
    shape = rng.choice(emitters)
    if how == "emission tiny":
        value = rng.choice((1e-45, 1e-46, 1e-39, 5e-324))
        shape["emission"] = [value] * 3
        return f"emission = {value:g}"
    shape["emission"] = [1e18, 1e18, 1e18]
    if how == "emission max huge quad" and shape.get("type") == "quad":
        shape["origin"] = [-5e14, 1.0, -5e14]
        shape["edge1"], shape["edge2"] = [1e15, 0.0, 0.0], [0.0, 0.0, 1e15]
        return "emission 1e18 on a quad of side 1e15"
    if how == "emitter near camera" and isinstance(doc.get("camera"), dict):
        origin = doc["camera"].get("origin")
        if is_vector(origin) and len(origin) == 3 and shape.get("type") == "sphere":
            shape["center"], shape["radius"] = list(origin), 1e-3
            return "emission 1e18 on a sphere around the camera"
    return "emission = 1e18"


POSITION_KEYS = ("origin", "target", "edge1", "edge2", "center", "position")


def mutate_scale_scene(rng, doc, ctx):
    factor = rng.choice((1e-30, 1e-12, 1e-7, 1e7, 1e12, 1e14, 9.99e14))
    scaled = 0
    for path, value in list(walk(doc)):
        if path and path[-1] in POSITION_KEYS and is_vector(value):
            set_at(doc, path, [x * factor for x in value])
            scaled += 1
        elif path and path[-1] == "radius" and is_number(value):
            set_at(doc, path, value * factor)
    return f"every coordinate x {factor:g} ({scaled} vectors; meshes unscaled)" if scaled else None


def mutate_sphere(rng, doc, ctx):
    spheres = _shapes(doc, "sphere")
    if not spheres:
        if not isinstance(doc.get("shapes"), list):
            return None
        spheres = [{"type": "sphere", "center": [0.0, 1.0, 0.0], "radius": 0.2}]
        doc["shapes"].append(spheres[0])
    sphere = rng.choice(spheres)
    how = rng.choice(("subdivisions", "radius at limit", "huge", "far"))
    if how == "subdivisions":
        sphere["subdivisions"] = rng.choice((-1, 0, 7, 8, 2.0, 100))
        return f"sphere subdivisions = {sphere['subdivisions']}"
    if how == "radius at limit":
        sphere["center"], sphere["radius"] = [1e6, 0.0, 0.0], rng.choice((1.0, 0.999999, 1.000001))
        return f"sphere at 1e6 with radius {sphere['radius']} (the 1e-6 rule)"
    if how == "huge":
        sphere["radius"] = rng.choice((1e15, 1.0000001e15, 1e14))
        return f"sphere radius {sphere['radius']:g} (around the camera)"
    sphere["center"] = [1e15, 1e15, 1e15]
    sphere["radius"] = rng.choice((1e9, 1e10))
    return "sphere at 1e15"


def mutate_render_table(rng, doc, ctx):
    render = doc.setdefault("render", {}) if isinstance(doc.get("render", {}), dict) else None
    if render is None:
        return None
    key = rng.choice(("spp", "strategy", "seed"))
    value = rng.choice((0, -1, 2.0, "64", 2**63, "MIS", "light", "none", [1], True))
    render[key] = value
    return f"render.{key} = {value!r}"


def mutate_many_shapes(rng, doc, ctx):
    if not isinstance(doc.get("shapes"), list):
        return None
    count = rng.choice((100, 1000))
    for i in range(count):
        x, z = rng.uniform(-1, 1), rng.uniform(-1, 1)
        shape = {"type": "quad", "origin": [x, rng.uniform(0, 2), z], "edge1": [0.01, 0.0, 0.0],
                 "edge2": [0.0, 0.0, 0.01]}
        if i % 3 == 0:
            shape["emission"] = [rng.uniform(0, 5)] * 3
        doc["shapes"].append(shape)
    return f"{count} more small quads, a third emitting"


def mutate_empty(rng, doc, ctx):
    how = rng.choice(("no shapes", "no lights", "no shapes or lights", "camera only", "nothing",
                      "no emitters"))
    if how == "nothing":
        doc.clear()
        return "empty document"
    if how == "camera only":
        for key in [k for k in doc if k != "camera"]:
            del doc[key]
    if how in ("no shapes", "no shapes or lights"):
        doc.pop("shapes", None)
    if how in ("no lights", "no shapes or lights"):
        doc.pop("lights", None)
    if how == "no emitters":
        for shape in _shapes(doc, emitting=True):
            shape["emission"] = [0.0, 0.0, 0.0]
        doc.pop("lights", None)
    return how


MESH_SOURCES = ("meshes/tallbox.ply", "meshes/shortbox.ply")


def _mesh_shapes(doc: dict[str, Any], rng: random.Random) -> list[dict]:
    """The scene's mesh shapes; a mesh shape is added (the tall box) if it has none."""
    meshes = _shapes(doc, "mesh")
    if not meshes:
        if not isinstance(doc.get("shapes"), list):
            doc["shapes"] = []
        shape = {"type": "mesh", "file": "meshes/tallbox.ply"}
        if rng.random() < 0.5:
            shape["emission"] = [2.0, 2.0, 2.0]
        doc["shapes"].append(shape)
        meshes = [shape]
    return meshes


def mutate_mesh_reference(rng, doc, ctx):
    shape = rng.choice(_mesh_shapes(doc, rng))
    (ctx.folder / "a_folder.ply").mkdir(exist_ok=True)
    name = rng.choice(("", ".", "..", "meshes", "a_folder.ply", "/", "/etc/passwd", "/dev/null", "/dev/zero",
                       "/proc/self/status", "meshes/nothere.ply", "meshes/tallbox.ply\n", "x" * 300 + ".ply",
                       "a/" * 2100 + "b.ply", "~/x.ply", "meshes/../meshes/tallbox.ply", "scene.toml",
                       "meshes\\tallbox.ply", "meshes/TALLBOX.PLY", "nul\x00.ply"))
    shape["file"] = name
    return f"mesh file = {name[:60]!r}"


def _ply_damage(rng: random.Random, text: str) -> tuple[str, str]:
    """Damage an ASCII PLY's text: header counts, coordinates, face indices, format."""
    lines = text.split("\n")
    header_end = lines.index("end_header") if "end_header" in lines else len(lines)
    vertex_count = next((int(ln.split()[2]) for ln in lines if ln.startswith("element vertex")), 0)
    body = list(range(header_end + 1, len(lines)))
    vertex_lines = body[:vertex_count]
    face_lines = body[vertex_count:]
    how = rng.choice(("vertex count", "face count", "coordinate", "face index", "face size", "format",
                      "property type", "no end_header", "drop faces"))
    if how == "vertex count":
        value = rng.choice(("0", "1", "7", "9", "1000000000", "-1", "2147483648", "x"))
        lines = [f"element vertex {value}" if ln.startswith("element vertex") else ln for ln in lines]
    elif how == "face count":
        value = rng.choice(("0", "13", "1000000000", "-1"))
        lines = [f"element face {value}" if ln.startswith("element face") else ln for ln in lines]
    elif how == "coordinate" and vertex_lines:
        i = rng.choice(vertex_lines)
        parts = lines[i].split()
        value = rng.choice(("nan", "inf", "-inf", "1e39", "1e16", "1e15", "abc", "3.4e38"))
        parts[rng.randrange(len(parts))] = value
        lines[i] = " ".join(parts)
    elif how == "face index" and face_lines:
        i = rng.choice([j for j in face_lines if lines[j].strip()] or face_lines)
        parts = lines[i].split() or ["3", "0", "1", "2"]
        value = rng.choice(("8", "100", "-1", "2147483647", "1099511627776", "x", "1.5"))
        parts[rng.randrange(1, len(parts)) if len(parts) > 1 else 0] = value
        lines[i] = " ".join(parts)
    elif how == "face size" and face_lines:
        i = rng.choice([j for j in face_lines if lines[j].strip()] or face_lines)
        parts = lines[i].split() or ["3"]
        value = rng.choice(("0", "1", "2", "4", "255"))
        parts[0] = value
        lines[i] = " ".join(parts)
    elif how == "format":
        value = rng.choice(("binary_little_endian", "binary_big_endian", "ascii 2.0", "xml"))
        lines = [f"format {value} 1.0" if ln.startswith("format") else ln for ln in lines]
    elif how == "property type":
        value = rng.choice(("double", "uchar", "int8", "bogus"))
        lines = [ln.replace("property float x", f"property {value} x") for ln in lines]
    elif how == "no end_header":
        lines = [ln for ln in lines if ln != "end_header"]
        value = ""
    else:
        lines = lines[: header_end + 1 + vertex_count]
        value = ""
    return "\n".join(lines), f"ply {how} {value}".strip()


OTHER_MESHES: dict[str, tuple[str, bytes]] = {
    "obj nan vertex": (".obj", b"v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n"),
    "obj index out of range": (".obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
    "obj negative index": (".obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -3\n"),
    "obj zero index": (".obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"),
    "obj no faces": (".obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
    "obj quads and a point": (".obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\nf 1\n"),
    "obj two objects": (".obj", b"o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
                                b"o b\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf 4 5 6\n"),
    "obj huge coordinate": (".obj", b"v 0 0 0\nv 1e300 0 0\nv 0 1 0\nf 1 2 3\n"),
    "obj mtllib": (".obj", b"mtllib missing.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
    "stl ascii": (".stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                          b"vertex 0 1 0\nendloop\nendfacet\nendsolid s\n"),
    "stl binary count lies": (".stl", b"\0" * 80 + (2**31 - 1).to_bytes(4, "little") + b"\0" * 50),
    "stl binary nan": (".stl", b"\0" * 80 + (1).to_bytes(4, "little") + b"\0" * 12
                       + b"\x00\x00\xc0\x7f" * 9 + b"\0\0"),
    "off": (".off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
    "glb garbage": (".glb", b"glTF\x02\x00\x00\x00\xff\xff\xff\x7f" + b"\0" * 20),
    "gltf json": (".gltf", b'{"asset": {"version": "2.0"}, '
                           b'"meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}]}'),
    "empty ply": (".ply", b""),
    "random bytes": (".ply", bytes(range(256)) * 4),
    "unknown extension": (".xyz", b"0 0 0\n1 0 0\n0 1 0\n"),
    "no extension": ("", b"ply\nformat ascii 1.0\nend_header\n"),
    "ply point cloud": (".ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                b"property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n"),
}


def mutate_mesh_damage(rng, doc, ctx):
    """Damage the content of a mesh the scene uses (a damaged copy; the shipped file is safe)."""
    shape = rng.choice(_mesh_shapes(doc, rng))
    if rng.random() < 0.6:
        source = ROOT / "tracer" / "scenes" / rng.choice(MESH_SOURCES)
        text, how = _ply_damage(rng, source.read_text())
        name = "meshes/damaged.ply"
        (ctx.folder / name).write_text(text)
    else:
        how = rng.choice(sorted(OTHER_MESHES))
        suffix, data = OTHER_MESHES[how]
        name = f"meshes/other{suffix}"
        (ctx.folder / name).write_bytes(data)
    shape["file"] = name
    return f"mesh {name}: {how}"


def mutate_python_types(rng, doc, ctx):
    """Values only a dict can hold (``load_scene(dict)``): None, tuples, bytes, int keys,
    numpy scalars and arrays."""
    import numpy as np

    how = rng.choice(("None", "tuple", "bytes", "int key", "numpy scalar", "numpy array", "set", "complex"))
    if how == "int key":
        path = _pick(rng, doc, lambda p, v: isinstance(v, dict))
        table = get_at(doc, path) if path is not None else doc
        table[7] = 1
        return f"dict only: integer key 7 in {path_text(path or ())}"
    path = _pick(rng, doc, lambda p, v: True)
    if path is None:
        return None
    old = get_at(doc, path)
    value = {"None": None, "tuple": tuple(old) if isinstance(old, list) else (1.0, 2.0, 3.0),
             "bytes": b"diffuse",
             "numpy scalar": np.float64("nan") if rng.random() < 0.5 else np.float32(1.0),
             "numpy array": np.array(old if is_vector(old) else [1.0, 2.0, 3.0]), "set": {1, 2, 3},
             "complex": complex(1.0, 2.0)}[how]
    set_at(doc, path, value)
    return f"dict only: {path_text(path)} = {how}"


# Each mutation with its weight. About half of them keep the scene valid but extreme (boundary
# values, zero-area and bright lights, scaled scenes, near-degenerate cameras, odd meshes), so
# that renders, not only the reader, meet hostile numbers.
def mutate_material_extreme(rng, doc, ctx):
    """A material parameter at, just inside or beyond an end of its range, or at a value that
    divided by zero or overflowed before the ranges were bounded (issue 38.7)."""
    extremes = {"int_ior": ("plastic", (0.01, 100.0, 0.0099, 100.01, 1e-300, 1e-160, 5e-324)),
                "ext_ior": ("roughplastic", (0.01, 100.0, 1e-300, 1e300)),
                "eta": ("conductor", (0.0, 1000.0, 1000.5, 1e300)),
                "k": ("roughconductor", (0.0, 1000.0, 1e300)),
                "alpha": ("roughconductor", (1e-6, 10.0, 9.9e-7, 1e-300, 10.01))}
    name = rng.choice(sorted(extremes))
    kind, values = extremes[name]
    value = rng.choice(values)
    material = {"type": kind, name: value if name in ("int_ior", "ext_ior", "alpha") else [value] * 3}
    if kind == "roughconductor":
        material.setdefault("alpha", 0.1)
        material["reflectance"] = [0.5, 0.5, 0.5]
    if name == "eta" and rng.random() < 0.5:
        material["k"] = [0.0, 0.0, 0.0]  # eta = k = 0 divided by zero in the Fresnel term
    doc.setdefault("materials", {})["fuzz_extreme"] = material
    shapes = _shapes(doc)
    if shapes:
        rng.choice(shapes)["material"] = "fuzz_extreme"
    return f"material {kind} {name} = {value}{' (k = 0)' if material.get('k') == [0.0] * 3 else ''}"


def mutate_special_file(rng, doc, ctx):
    """A mesh the scene reads is a FIFO, /dev/zero or a folder (opening a FIFO blocks until
    something writes to it; a device never ends)."""
    shapes = _mesh_shapes(doc, rng)
    if not shapes:
        return None
    shape = rng.choice(shapes)
    what = rng.choice(("fifo", "device", "folder"))
    name = f"special_{what}.ply"
    target = ctx.folder / name
    if not target.exists() and not target.is_symlink():
        {"fifo": lambda: os.mkfifo(target), "device": lambda: os.symlink("/dev/zero", target),
         "folder": lambda: target.mkdir()}[what]()
    shape["file"] = name
    return f"mesh file is a {what}"


SCENE_MUTATIONS: list[tuple[Callable, float]] = [
    (mutate_delete_key, 2), (mutate_duplicate, 2), (mutate_swap_type, 2), (mutate_special_number, 4),
    (mutate_boundary_value, 6), (mutate_vector_length, 1), (mutate_long_string, 1), (mutate_odd_text, 2),
    (mutate_deep_nesting, 1), (mutate_unknown_key, 1), (mutate_unknown_material, 1), (mutate_fov, 2),
    (mutate_degenerate_camera, 3), (mutate_zero_area, 3), (mutate_bright_light, 5), (mutate_scale_scene, 3),
    (mutate_sphere, 2), (mutate_render_table, 1), (mutate_many_shapes, 0.5), (mutate_empty, 1),
    (mutate_mesh_reference, 1), (mutate_mesh_damage, 3), (mutate_material_extreme, 3), (mutate_special_file, 1),
]


# ---------------------------------------------------------------------------------------------
# Byte-level damage (scene TOML and baseline JSON text)


def damage_bytes(rng: random.Random, data: bytes) -> tuple[bytes, str]:
    """One byte-level change of a text file."""
    how = rng.choice(("truncate", "delete span", "duplicate line", "insert bytes", "flip byte", "digits",
                      "duplicate header", "bom", "crlf", "nul", "invalid utf-8", "deep headers", "pad"))
    n = len(data)
    at = rng.randrange(n + 1) if n else 0
    if how == "truncate":
        return data[:at], f"truncated at byte {at} of {n}"
    if how == "delete span":
        end = min(n, at + rng.randrange(1, 40))
        return data[:at] + data[end:], f"deleted bytes {at}..{end}"
    if how == "duplicate line":
        lines = data.split(b"\n")
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
        return b"\n".join(lines), f"duplicated line {i + 1}"
    if how == "insert bytes":
        junk = bytes(rng.choice(b"[]{}=\"'.,#\\\n\t 0123456789-+eE") for _ in range(rng.randrange(1, 8)))
        return data[:at] + junk + data[at:], f"inserted {junk!r} at byte {at}"
    if how == "flip byte" and n:
        i = rng.randrange(n)
        flipped = bytes([data[i] ^ (1 << rng.randrange(8))])
        return data[:i] + flipped + data[i + 1:], f"flipped a bit of byte {i}"
    if how == "digits":
        digit = rng.choice(b"0123456789")
        positions = [i for i, b in enumerate(data) if 48 <= b <= 57]
        if positions:
            i = rng.choice(positions)
            return data[:i] + bytes([digit]) * rng.choice((1, 30, 400)) + data[i + 1:], f"digits at byte {i}"
    if how == "duplicate header":
        for header in (b"[camera]", b"[render]", b'"entries"'):
            if header in data:
                return data + b"\n" + header + b"\n", f"second {header.decode()}"
    if how == "bom":
        return b"\xef\xbb\xbf" + data, "UTF-8 byte-order mark"
    if how == "crlf":
        crlf = data.replace(b"\n", b"\r\n").replace(b"\r\n", b"\r", rng.randrange(3))
        return crlf, "CRLF / bare CR line ends"
    if how == "nul":
        return data[:at] + b"\x00" + data[at:], f"NUL at byte {at}"
    if how == "invalid utf-8":
        return data[:at] + b"\xff\xfe\xc3" + data[at:], f"invalid UTF-8 at byte {at}"
    if how == "deep headers":
        parts = rng.choice((63, 64, 65, 3000))
        return data + b"\n[" + b".".join([b"a"] * parts) + b"]\n", f"table header of {parts} dotted parts"
    if how == "pad":
        return data + b"# " + b"x" * (2 << 20) + b"\n", "a 2 MiB comment line"
    return data[: n // 2], "truncated to half"


# =============================================================================================
# Scene cases


def scene_sources() -> list[Path]:
    return sorted(p for folder in SCENE_DIRS for p in folder.glob("*.toml"))


def copy_mesh_files(folder: Path) -> None:
    """The meshes the shipped scenes refer to, at the same relative paths."""
    shutil.copytree(SHIPPED_MESH_DIR, folder / "meshes")
    for ply in (ROOT / "tracer" / "study" / "cases").glob("*.ply"):
        shutil.copy(ply, folder / ply.name)


OPTION_VARIANTS: tuple[tuple[str, ...], ...] = tuple(
    [("--strategy", s) for s in STRATEGIES] + [("--heuristic", h) for h in HEURISTICS]
    + [("--light-samples", "0"), ("--bsdf-samples", "0"), ("--light-samples", "0", "--bsdf-samples", "0"),
       ("--light-samples", "4", "--bsdf-samples", "3"), ("--one-sample",),
       ("--one-sample", "--light-samples", "0"),
       ("--one-sample", "--strategy", "light"), ("--light-selection", "uniform"),
       ("--strategy", "light", "--light-samples", "0"), ("--sampler", "sobol"), ("--sampler", "stratified"),
       ("--sampler", "halton"), ("--sampler", "sobol", "--spp", "34359738369")]
    + [("--seed", v) for v in ("4294967296", "18446744073709551615", "18446744073709551616",
                                "99999999999999999999999999", "-1", "1e3")]
    + [("--exposure", v) for v in ("100", "-100", "100.0001", "nan", "inf", "1e309", "-0", "abc")]
    + [("--spp", v) for v in ("1", "0", "-1", "9007199254740993", "1.5")]
    + [("--width", "0"), ("--width", "32769"), ("--width", "1", "--height", "1"),
       ("--width", "20000", "--height", "20000"), ("--width", "3000", "--height", "1"),
       ("--threads", "0"), ("--threads", "64")]
    + [("-o", v) for v in ("out.png", "nodir/out.exr", ".", "out", "out.EXR", "x" * 300 + ".exr", "out.exr/",
                           "a_dir.exr", "/proc/out.exr", "-")]
)


def make_scene_case(seed: int, index: int, root: Path) -> Case:
    """Scene case ``index``: a mutated shipped scene, its meshes, and three checks."""
    import tomllib

    rng = random.Random(f"{seed}:scene:{index}")
    folder = root / f"scene-{index:04d}"
    folder.mkdir(parents=True)
    copy_mesh_files(folder)
    source = rng.choice(scene_sources())
    case = Case("scene", index, folder, [f"from {source.relative_to(ROOT)}"])
    doc = tomllib.loads(source.read_text())
    ctx = SceneContext(folder)
    functions = [f for f, _ in SCENE_MUTATIONS]
    weights = [w for _, w in SCENE_MUTATIONS]
    for _ in range(rng.choices((1, 2, 3), (6, 3, 1))[0]):
        for _attempt in range(10):
            description = rng.choices(functions, weights)[0](rng, doc, ctx)
            if description:
                case.mutations.append(description)
                break
    dict_doc = None if contains_raw(doc) else copy.deepcopy(doc)
    if dict_doc is not None and rng.random() < 0.25:
        case.mutations.append(mutate_python_types(rng, dict_doc, ctx) or "")
    text = toml_dumps(doc, inline=rng.random() < 0.1).encode("utf-8", errors="surrogatepass")
    if rng.random() < 0.2:
        text, description = damage_bytes(rng, text)
        case.mutations.append(f"text: {description}")
    (folder / "scene.toml").write_bytes(text)
    (folder / "a_dir.exr").mkdir()
    mesh_names = tuple(sorted({p.name for p in folder.rglob("*") if p.is_file() and p.suffix != ".toml"}
                              | {f"special_{what}.ply" for what in ("fifo", "device", "folder")}))
    inputs = ("scene.toml",) + mesh_names + ("<dict>",)
    scene_file = str(folder / "scene.toml")
    case.checks.append(Check("api-load-file", probe=("load_scene", (scene_file,)), inputs=inputs))
    if dict_doc is not None:
        dict_probe = ("load_scene", (dict_doc, str(folder)))
        case.checks.append(Check("api-load-dict", probe=dict_probe, inputs=inputs))
    argv = ["render", "scene.toml", "-o", "out.exr", *TINY_RENDER]
    if rng.random() < 0.15:
        option = rng.choice(OPTION_VARIANTS)
        argv += list(option)
        case.mutations.append(f"options: {' '.join(option)[:80]}")
    output = argv[len(argv) - 1 - argv[::-1].index("-o") + 1]
    png = str(Path(output).with_suffix(".png")) if Path(output).name else output
    case.checks.append(Check("cli-render", argv=argv, outputs=(output, png),
                             inputs=inputs + (output, "exposure")))
    return case


# =============================================================================================
# EXR cases


@dataclass
class RawExr:
    """A render EXR as OpenImageIO reads it: size, channels (name, format, (H, W) float32
    plane), the extra attributes (name, type, value) and the compression."""

    width: int
    height: int
    channels: list[list]  # [name, format, plane]
    attributes: list[list]  # [name, type, value]
    compression: str = "zip"
    tile: int = 0
    origin: tuple[int, int] = (0, 0)


def read_raw_exr(path: Path) -> RawExr:
    import numpy as np
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    pixels = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, "float")).reshape(spec.height, spec.width, -1)
    inp.close()
    formats = [str(f) for f in spec.channelformats] or [str(spec.format)] * spec.nchannels
    channels = [[name, formats[c], pixels[:, :, c].copy()] for c, name in enumerate(spec.channelnames)]
    attributes = [[a.name, str(a.type), a.value] for a in spec.extra_attribs if a.name.startswith("tracer:")]
    return RawExr(spec.width, spec.height, channels, attributes)


def write_raw_exr(path: Path, raw: RawExr) -> None:
    """Write ``raw`` as it is (OpenImageIO refusing a value type falls back to a string)."""
    import numpy as np
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(raw.width, raw.height, len(raw.channels), "float")
    spec.channelnames = tuple(c[0] for c in raw.channels)
    spec.channelformats = tuple(oiio.TypeDesc(c[1]) for c in raw.channels)
    spec.attribute("compression", raw.compression)
    spec.x, spec.y = raw.origin
    if raw.tile:
        spec.tile_width = spec.tile_height = raw.tile
    for name, kind, value in raw.attributes:
        try:
            if kind in ("int", "float", "string"):
                spec.attribute(name, kind, value)
            else:
                spec.attribute(name, oiio.TypeDesc(kind), value)
        except (RuntimeError, TypeError, ValueError):
            spec.attribute(name, str(value))
    pixels = np.ascontiguousarray(np.stack([c[2] for c in raw.channels], axis=-1), dtype=np.float32) \
        if raw.channels else np.zeros((raw.height, raw.width, 0), np.float32)
    out = oiio.ImageOutput.create(str(path))
    if not (out.open(str(path), spec) and out.write_image(pixels)):
        error = out.geterror()
        out.close()
        raise RuntimeError(f"OpenImageIO cannot write this damage: {error}")
    out.close()


ATTRIBUTE_VALUES: tuple[tuple[str, Any], ...] = (
    ("int", 0), ("int", -1), ("int", 1), ("int", 2**31 - 1), ("int", -(2**31)),
    ("float", 0.5), ("float", -1.0), ("float", math.nan), ("float", math.inf), ("float", -math.inf),
    ("float", 3.0), ("float", 1e30), ("string", ""), ("string", "abc"), ("string", "-5"),
    ("string", "2147483648"), ("string", "9007199254740993"),
    ("string", "18446744073709551616"), ("string", "99999999999999999999999999999"), ("string", "1e30"),
    ("string", "nan"), ("string", " 7 "), ("string", "a\nb"), ("string", "x" * 10000), ("string", "mis"),
    ("string", "light"), ("string", "bogus"), ("string", "0:0-7"), ("string", "0:0-3,0:4-7"),
    ("string", "1:0-3,0:0-3"), ("string", "0:7-0"), ("string", "0:0-9007199254740991"),
    ("string", "18446744073709551615:0-3"), ("string", "0:0-3,0:2-5"), ("string", "0" * 64),
    ("string", "g" * 64),
    ("vector", (1.0, 2.0, 3.0)), ("int[2]", (1, 2)), ("matrix", tuple(float(i) for i in range(16))),
)
RECORD_NAMES = ("tracer:spp", "tracer:strategy", "tracer:heuristic", "tracer:light_samples",
                "tracer:bsdf_samples", "tracer:one_sample", "tracer:light_selection", "tracer:sampler",
                "tracer:seed", "tracer:first_sample", "tracer:next_sample", "tracer:samples",
                "tracer:seconds", "tracer:scene", "tracer:scene_digest", "tracer:version")
PIXEL_VALUES = (math.nan, math.inf, -math.inf, -1.0, -1e-30, 0.0, 3.4e38, 1e38, 65504.0, 65520.0, 1e-45,
                float(2**53), float(2**53 + 2), 0.5, 1e30)


def _plane(raw: RawExr, name: str):
    return next((c for c in raw.channels if c[0] == name), None)


def damage_exr(rng: random.Random, raw: RawExr) -> str:
    """One structural damage of a render EXR (in place); returns what it did."""
    import numpy as np

    how = rng.choice(("attribute", "attribute", "attribute", "delete attribute", "pixel", "pixel",
                      "huge finite", "samples channel", "drop channel", "rename channel", "extra channel",
                      "channel type", "resize", "layout", "header lie", "header lie"))
    present = [a[0] for a in raw.attributes]
    if how == "header lie":
        return _header_lie(rng, raw)
    if how == "attribute":
        name = rng.choice(sorted(set(present) | set(RECORD_NAMES)))
        kind, value = rng.choice(ATTRIBUTE_VALUES)
        raw.attributes = [a for a in raw.attributes if a[0] != name] + [[name, kind, value]]
        return f"header {name} = {kind} {str(value)[:40]!r}"
    if how == "delete attribute" and present:
        names = rng.sample(present, rng.choice((1, 1, 2, len(present))))
        raw.attributes = [a for a in raw.attributes if a[0] not in names]
        return f"deleted header {', '.join(names)}"
    if how in ("pixel", "huge finite"):
        names = [c[0] for c in raw.channels]
        value = rng.choice(PIXEL_VALUES) if how == "pixel" else rng.choice((3.4e38, 1e38, 1e30, 6e4))
        chosen = [rng.choice(names)] if how == "pixel" else names
        where = rng.choice(("one pixel", "a row", "every pixel"))
        y, x = rng.randrange(raw.height), rng.randrange(raw.width)
        for channel in raw.channels:
            if channel[0] in chosen:
                plane = channel[2]
                if where == "one pixel":
                    plane[y, x] = value
                elif where == "a row":
                    plane[y, :] = value
                else:
                    plane[:, :] = value
        return f"{'/'.join(chosen) if len(chosen) < 3 else 'every channel'} = {value} at {where}"
    if how == "samples channel":
        spp = next((a[2] for a in raw.attributes if a[0] == "tracer:spp"), 4)
        counts = np.full((raw.height, raw.width), float(spp if isinstance(spp, int) else 4), np.float32)
        value = rng.choice((0.0, 1.0, float(spp) + 1 if isinstance(spp, int) else 5.0, float(2**53),
                            float(2**53 + 2), 2.5, -1.0, math.nan, 1e30, float(2**31), 3e9))
        where = rng.choice(("one pixel", "every pixel"))
        if where == "one pixel":
            counts[rng.randrange(raw.height), rng.randrange(raw.width)] = value
        else:
            counts[:, :] = value
        existing = _plane(raw, "samples")
        if existing is not None:
            existing[2] = counts
        else:
            raw.channels.append(["samples", "float", counts])
        if rng.random() < 0.5:
            header = rng.choice((0, 1, 2**31 - 1, "3000000000", "9007199254740992"))
            raw.attributes = [a for a in raw.attributes if a[0] != "tracer:spp"] + [
                ["tracer:spp", "int" if isinstance(header, int) else "string", header]]
            return f"samples channel = {value} at {where}, tracer:spp = {header!r}"
        return f"samples channel = {value} at {where}"
    if how == "drop channel":
        name = rng.choice([c[0] for c in raw.channels])
        raw.channels = [c for c in raw.channels if c[0] != name]
        return f"dropped channel {name}"
    if how == "rename channel":
        channel = rng.choice(raw.channels)
        old = channel[0]
        channel[0] = rng.choice(("r", "var.R", "variance.r", "A", "R ", "samples", "variance.R"))
        return f"renamed channel {old} to {channel[0]!r}"
    if how == "extra channel":
        name = rng.choice(("A", "Z", "variance.A", "extra"))
        raw.channels.append([name, "float", np.full((raw.height, raw.width), math.nan, np.float32)])
        return f"extra channel {name} full of NaN"
    if how == "channel type":
        target = rng.choice(("half", "uint", "float"))
        which = rng.choice(("every channel", "variances", "means"))
        for channel in raw.channels:
            if which == "every channel" or (which == "variances") == channel[0].startswith("variance"):
                channel[1] = target
        return f"{which} stored as {target}"
    if how == "resize":
        w, h = rng.choice(((1, 1), (1, 8), (8, 1), (3, 5), (2, 2), (16, 16), (5, 8)))
        for channel in raw.channels:
            plane = channel[2]
            channel[2] = np.ascontiguousarray(np.resize(plane, (h, w)))
        raw.width, raw.height = w, h
        return f"resized to {w}x{h}"
    how = rng.choice(("tiled", "origin", "compression"))
    if how == "tiled":
        raw.tile = rng.choice((1, 4, 16))
        return f"tiled {raw.tile}x{raw.tile}"
    if how == "origin":
        raw.origin = (rng.choice((-3, 5, 100000)), rng.choice((0, -2, 7)))
        return f"data window at {raw.origin}"
    raw.compression = rng.choice(("none", "piz", "dwaa", "b44", "pxr24", "rle"))
    return f"compression {raw.compression}"


def _set_attribute(raw: RawExr, name: str, kind: str, value: Any) -> None:
    raw.attributes = [a for a in raw.attributes if a[0] != name] + [[name, kind, value]]


def _header_lie(rng: random.Random, raw: RawExr) -> str:
    """Header fields that are each well formed but contradict each other or the pixels (issue
    38.4): a resume that trusted them allocated 24 GiB, or silently dropped samples."""
    import numpy as np

    how = rng.choice(("spp 0 over samples", "spp below the counts", "spp above the counts", "huge light samples",
                      "counts beyond the ranges", "zero-count pixel with data", "one sample with variance",
                      "counts past float32", "split counts"))
    spp = next((a[2] for a in raw.attributes if a[0] == "tracer:spp"), 4)
    spp = spp if isinstance(spp, int) else 4
    if how == "spp 0 over samples":
        _set_attribute(raw, "tracer:spp", "int", 0)
    elif how in ("spp below the counts", "spp above the counts"):
        _set_attribute(raw, "tracer:spp", "int", max(0, spp - 1) if how.endswith("below the counts") else spp + 3)
        if rng.random() < 0.5:
            raw.channels.append(["samples", "float", np.full((raw.height, raw.width), float(spp), np.float32)])
    elif how == "huge light samples":
        value = rng.choice((2**31 - 1, 1_000_001, 10**6, "4294967296"))
        _set_attribute(raw, rng.choice(("tracer:light_samples", "tracer:bsdf_samples")),
                       "int" if isinstance(value, int) else "string", value)
        return f"header lie: light/bsdf samples = {value}"
    elif how == "counts beyond the ranges":
        _set_attribute(raw, "tracer:samples", "string", rng.choice(("1:0-0", "1:0-1", "3:0-2,4:0-0")))
    elif how == "zero-count pixel with data":
        counts = np.full((raw.height, raw.width), float(spp), np.float32)
        counts[rng.randrange(raw.height), rng.randrange(raw.width)] = 0.0
        raw.channels = [c for c in raw.channels if c[0] != "samples"] + [["samples", "float", counts]]
    elif how == "one sample with variance":
        _set_attribute(raw, "tracer:spp", "int", 1)
    elif how == "counts past float32":
        counts = np.full((raw.height, raw.width), float(2**24 + 2), np.float32)
        counts[0, 0] = float(2**24 + rng.choice((1, 3, 8)))
        raw.channels = [c for c in raw.channels if c[0] != "samples"] + [["samples", "float", counts]]
    else:
        low = np.full((raw.height, raw.width), float(rng.choice((spp, 2**24, 2**24 - 1))), np.float32)
        high = np.full((raw.height, raw.width), float(rng.choice((0, 1, 2**24, 2**25, -1))), np.float32)
        raw.channels = [c for c in raw.channels if c[0] != "samples"] + [
            ["samples.low", "float", low]] + ([["samples.high", "float", high]] if rng.random() < 0.8 else [])
    return f"header lie: {how}"


def damage_exr_bytes(rng: random.Random, data: bytes, folder: Path, name: str) -> str:
    """Byte-level damage of the EXR file ``folder/name`` (written here)."""
    path = folder / name
    how = rng.choice(("truncate", "flip header", "flip data", "zero span", "append", "empty", "magic only",
                      "png", "text", "directory", "dangling symlink"))
    n = len(data)
    if how == "truncate":
        at = rng.randrange(n)
        path.write_bytes(data[:at])
        return f"truncated at byte {at} of {n}"
    if how in ("flip header", "flip data"):
        lo, hi = (0, min(n, 600)) if how == "flip header" else (min(n - 1, 600), n)
        out = bytearray(data)
        flips = rng.choice((1, 2, 8))
        for _ in range(flips):
            i = rng.randrange(lo, hi)
            out[i] ^= 1 << rng.randrange(8)
        path.write_bytes(bytes(out))
        return f"{flips} bit flip(s) in the {'header' if how == 'flip header' else 'pixel data'}"
    if how == "zero span":
        at = rng.randrange(n)
        end = min(n, at + rng.choice((4, 64, 1024)))
        path.write_bytes(data[:at] + b"\0" * (end - at) + data[end:])
        return f"zeroed bytes {at}..{end}"
    if how == "append":
        path.write_bytes(data + bytes(rng.randrange(256) for _ in range(100)))
        return "100 random bytes appended"
    if how == "empty":
        path.write_bytes(b"")
        return "empty file"
    if how == "magic only":
        path.write_bytes(data[:4])
        return "only the 4-byte magic number"
    if how == "png":
        png = folder / "partner.png"
        path.write_bytes(png.read_bytes() if png.exists() else b"\x89PNG\r\n\x1a\n")
        return "a PNG named .exr"
    if how == "text":
        path.write_text("not an image\n")
        return "a text file named .exr"
    if how == "directory":
        path.mkdir()
        return "a directory named .exr"
    path.symlink_to(folder / "missing.exr")
    return "a symlink to a missing file"


EXR_CONSUMERS = ("merge", "resume", "compare", "merge", "resume", "check")


def make_exr_case(seed: int, index: int, root: Path, base: Path) -> Case:
    """EXR case ``index``: a damaged render EXR, its good partner, and two checks."""
    rng = random.Random(f"{seed}:exr:{index}")
    folder = root / f"exr-{index:04d}"
    folder.mkdir(parents=True)
    copy_mesh_files(folder)
    shutil.copy(ROOT / "tracer" / "scenes" / "cornell.toml", folder / "cornell.toml")
    kind = rng.choice(("render", "reference", "sobol"))
    source, partner = (base / f"{kind}_a.exr", base / f"{kind}_b.exr")
    if rng.random() < 0.5:
        source, partner = partner, source
    shutil.copy(partner, folder / "partner.exr")
    shutil.copy(partner.with_suffix(".png"), folder / "partner.png")
    case = Case("exr", index, folder, [f"from a tracer {kind} ({source.name})"])
    if rng.random() < 0.25:
        case.mutations.append(damage_exr_bytes(rng, source.read_bytes(), folder, "damaged.exr"))
    else:
        raw = read_raw_exr(source)
        for _ in range(rng.choices((1, 2, 3), (6, 3, 1))[0]):
            case.mutations.append(damage_exr(rng, raw))
        try:
            write_raw_exr(folder / "damaged.exr", raw)
        except RuntimeError as exc:
            case.mutations.append(f"({exc}; the source written as is)")
            shutil.copy(source, folder / "damaged.exr")
    inputs = ("damaged.exr", "partner.exr", "resume.exr", "baseline.json", "cornell.toml")
    read_probe = ("read_image", (str(folder / "damaged.exr"),))
    case.checks.append(Check("api-read-image", probe=read_probe, inputs=inputs))
    consumer = EXR_CONSUMERS[index % len(EXR_CONSUMERS)]
    if consumer == "merge":
        first, second = ("damaged.exr", "partner.exr")
        if rng.random() < 0.3:
            first, second = second, first
        case.checks.append(Check("cli-merge", ["merge", first, second, "-o", "merged.exr", "--quiet"],
                                 outputs=("merged.exr", "merged.png"), inputs=inputs))
    elif consumer == "resume":
        if (folder / "damaged.exr").is_symlink() or (folder / "damaged.exr").is_dir():
            (folder / "resume.exr").symlink_to("damaged.exr")
        else:
            shutil.copy(folder / "damaged.exr", folder / "resume.exr")
        argv = ["reference", "cornell.toml", "-o", "resume.exr", "--resume", "--spp", "1", "--width", "8",
                "--height", "8", "--threads", "1", "--quiet"]
        case.checks.append(Check("cli-resume", argv, outputs=("resume.exr", "resume.png"), inputs=inputs))
    elif consumer == "compare":
        argv = ["compare", "cornell.toml", "--reference", "damaged.exr", "--spp", "1", "--strategies",
                "mis,light", "--out", "compare", "--threads", "1", "--quiet"]
        case.checks.append(Check("cli-compare", argv, outputs=("compare",), inputs=inputs))
    else:
        doc = base_baseline_doc()
        doc["entries"][0]["reference"] = "damaged.exr"
        (folder / "baseline.json").write_text(json_dumps(doc))
        argv = ["check", "--baseline", "baseline.json", "--out", "check_failures", "--threads", "1"]
        case.checks.append(Check("cli-check", argv, allowed=(0, 1, 2), optional_outputs=("check_failures",),
                                 inputs=inputs))
    return case


# =============================================================================================
# Baseline cases


def base_baseline_doc() -> dict[str, Any]:
    """A one-entry baseline in the shape of renders/noise_baseline.json: cornell, MIS, 1 spp,
    two seeds, against the 8 x 8 reference ``ref.exr`` of the case folder."""
    return {"about": "fuzz baseline", "entries": [{
        "scene": "cornell", "strategy": "mis", "heuristic": "power", "spp": 1, "seeds": [1, 2],
        "light_samples": 1, "bsdf_samples": 1, "downsample": 1, "pixel_test": True, "reference": "ref.exr",
        "relmse": 0.5, "variance": 0.1, "relmse_seeds": [0.5, 0.6], "variance_seeds": [0.1, 0.2],
        "note": "fuzz"}]}


# Values each field may take: invalid ones, and valid ones that stay cheap to render.
BASELINE_VALUES: dict[str, tuple[Any, ...]] = {
    "scene": ("cornell", "veach_mis", "point_light", "nonexistent", "../../../etc/passwd", "/", "",
              "cornell\n", "x" * 5000, "ref.exr", "baseline.json", "meshes", "nul\x00", "cornell.toml",
              "meshes/tallbox.ply"),
    "strategy": STRATEGIES + ("MIS", " mis", "mis\n", "none", ""),
    "heuristic": HEURISTICS + ("none", "balance\u00a0", ""),
    "spp": (1, 2, 0, -1, 1.0, 2**31 + 1, True, "1"),
    "seeds": ([], [1, 1], [-1], [1.0], [2**64], [True], ["1"], [[1]], [1] * 1000, [0, 2**63], [3]),
    "light_samples": (0, 1, 2, 2**20 + 1, -1, 1.5, None),
    "bsdf_samples": (0, 1, 2, 2**20 + 1, -1, 1.5, None),
    "downsample": (1, 2, 4, 8, 3, 16, 0, 2**15, 2**15 + 1, 2**40, 1.0),
    "pixel_test": (True, False, 0, 1, "false", None),
    "reference": ("ref.exr", "missing.exr", "", ".", "meshes", "baseline.json", "ref.png", "/dev/zero",
                  "../ref.exr", "a\nb.exr", None),
    "relmse": (0, -0.0, 1e308, math.nan, math.inf, -1, "0.1", None, Raw("1e400")),
    "variance": (0, 1e308, math.nan, -math.inf, -1e-300, None),
    "relmse_seeds": ([], [0.1], [0.1, 0.2, 0.3], [math.nan, 0.1], [1e308, 1e308], [-1, 1], None, [0, 0]),
    "variance_seeds": ([], [0.1], [math.inf, 0.1], [0.0, 0.0], None),
    "note": (5, "", "\n", None),
}
GENERIC_JSON_VALUES: tuple[Any, ...] = (
    None, True, False, "", "x", "\n", [], {}, [1], {"a": 1}, 0, -1, 1.5, math.nan, math.inf, -math.inf, 2**63,
    2**64, 1e308, Raw("1e400"), Raw("9" * 5000), Raw("-0"), Raw("[" * 100000 + "]" * 100000),
)


HOSTILE_JSON = (Raw("[" * 100000 + "]" * 100000), Raw('{"a": ' * 50000 + "1" + "}" * 50000),
                Raw("9" * 5000), Raw("-" + "1" * 4301), Raw("1" + "0" * 400 + ".5"), Raw("1e999999"))


def mutate_baseline(rng: random.Random, doc: dict[str, Any]) -> str:
    """One structure-aware change of a baseline document (in place)."""
    entries = doc.get("entries")
    entry = entries[0] if isinstance(entries, list) and entries and isinstance(entries[0], dict) else None
    how = rng.choice(("field", "field", "field", "field", "generic", "hostile", "delete", "unknown", "top",
                      "entries"))
    if how == "field" and entry is not None:
        name = rng.choice(sorted(BASELINE_VALUES))
        entry[name] = copy.deepcopy(rng.choice(BASELINE_VALUES[name]))
        return f"entries[0].{name} = {json_dumps(entry[name])[:60]}"
    if how == "generic" and entry is not None:
        name = rng.choice(sorted(entry))
        entry[name] = copy.deepcopy(rng.choice(GENERIC_JSON_VALUES))
        return f"entries[0].{name} = {json_dumps(entry[name])[:60]}"
    if how == "hostile" and entry is not None:  # JSON that Python's parser itself chokes on
        name = rng.choice(sorted(entry))
        entry[name] = rng.choice(HOSTILE_JSON)
        return f"entries[0].{name} = {entry[name].text[:20]}... ({len(entry[name].text)} characters)"
    if how == "delete" and entry is not None and entry:
        name = rng.choice(sorted(entry))
        del entry[name]
        return f"deleted entries[0].{name}"
    if how == "unknown" and entry is not None:
        name = rng.choice(("relMSE", "seed", "", "\n", "scene "))
        entry[name] = 1
        return f"unknown key {name!r} in entries[0]"
    if how == "top":
        what = rng.choice(("list", "string", "number", "null", "no entries", "entries object"))
        if what == "no entries":
            doc.pop("entries", None)
        elif what == "entries object":
            doc["entries"] = {"0": entry}
        else:
            doc.clear()
            doc["__replace__"] = {"list": [], "string": "x", "number": 1, "null": None}[what]
        return f"top level: {what}"
    what = rng.choice(("empty", "three copies", "non-object", "nested list"))
    doc["entries"] = {"empty": [], "three copies": [copy.deepcopy(entry)] * 3, "non-object": [1],
                      "nested list": [[entry]]}[what]
    return f"entries: {what}"


def make_baseline_case(seed: int, index: int, root: Path, base: Path) -> Case:
    """Baseline case ``index``: a damaged baseline beside an 8 x 8 reference; two checks."""
    rng = random.Random(f"{seed}:baseline:{index}")
    folder = root / f"baseline-{index:04d}"
    folder.mkdir(parents=True)
    copy_mesh_files(folder)
    shutil.copy(base / "reference_a.exr", folder / "ref.exr")
    shutil.copy(base / "reference_a.png", folder / "ref.png")
    case = Case("baseline", index, folder)
    doc = base_baseline_doc()
    for _ in range(rng.choices((1, 2, 3), (6, 3, 1))[0]):
        case.mutations.append(mutate_baseline(rng, doc))
    document = doc["__replace__"] if "__replace__" in doc else doc
    text = json_dumps(document).encode("utf-8", errors="surrogatepass")
    baseline = "baseline.json"
    roll = rng.random()
    if roll < 0.25:
        text, description = damage_bytes(rng, text)
        case.mutations.append(f"text: {description}")
    elif roll < 0.28:
        baseline = rng.choice(("/dev/zero", "missing.json", "meshes", "ref.exr", "fifo.json"))
        case.mutations.append(f"--baseline {baseline}")
    elif roll < 0.31 and isinstance(doc.get("entries"), list) and doc["entries"] \
            and isinstance(doc["entries"][0], dict):
        doc["entries"][0]["scene"] = "fifo.toml"  # an entry whose scene is a FIFO (issue 38.8)
        text = json_dumps(doc).encode("utf-8", errors="surrogatepass")
        case.mutations.append("entries[0].scene is a FIFO")
    for fifo in ("fifo.json", "fifo.toml"):
        os.mkfifo(folder / fifo)
    (folder / "baseline.json").write_bytes(text)
    update = rng.random() < 0.25
    inputs = ("baseline.json", "ref.exr", "missing.json", "meshes", "/dev/zero", "cornell", "tallbox",
              "fifo.json", "fifo.toml")
    case.checks.append(Check("api-load-baseline", probe=("load_baseline", (str(folder / baseline),)),
                             inputs=inputs))
    argv = ["check", "--baseline", baseline, "--out", "check_failures", "--threads", "1"]
    if update:
        argv.append("--update")
        case.mutations.append("check --update")
    case.checks.append(Check("cli-check-update" if update else "cli-check", argv, allowed=(0, 1, 2),
                             outputs=("baseline.json",) if update else (),
                             optional_outputs=("check_failures",), inputs=inputs))
    return case


# =============================================================================================
# The run


# =============================================================================================
# Mitsuba XML cases (the generators: benchmarks/fuzz_xml.py)


def make_xml_case(seed: int, index: int, root: Path) -> Case:
    """XML case ``index``: a small Mitsuba scene with hostile changes (``fuzz_xml``); two checks."""
    import fuzz_xml

    rng = random.Random(f"{seed}:xml:{index}")
    folder = root / f"xml-{index:04d}"
    folder.mkdir(parents=True)
    mutations, inputs = fuzz_xml.build(rng, folder)
    case = Case("xml", index, folder, mutations)
    case.checks.append(Check("api-load-xml", probe=("load_scene", (str(folder / "scene.xml"),)), inputs=inputs))
    case.checks.append(Check("cli-render-xml", argv=["render", "scene.xml", "-o", "out.exr", *TINY_RENDER],
                             outputs=("out.exr", "out.png"), inputs=inputs + ("out.exr",)))
    return case


# =============================================================================================
# Scheduler-address cases (the addresses and servers: benchmarks/fuzz_scheduler.py)


def make_scheduler_case(seed: int, index: int, root: Path, servers) -> Case:
    """Scheduler case ``index``: ``reference --scheduler`` at an address that is no Dask scheduler."""
    import fuzz_scheduler

    rng = random.Random(f"{seed}:scheduler:{index}")
    folder = root / f"scheduler-{index:04d}"
    folder.mkdir(parents=True)
    address, description = fuzz_scheduler.choose(rng, servers)
    case = Case("scheduler", index, folder, [description])
    scene = str(ROOT / "tracer" / "scenes" / "cornell.toml")
    argv = ["reference", scene, "-o", "ref.exr", "--spp", "1", "--width", "8", "--height", "8", "--quiet",
            "--scheduler", address, "--connect-timeout", str(SCHEDULER_TIMEOUT)]
    # No exit 0 is possible (nothing there is a scheduler): allowed only the refusal.
    # It must end within its connect timeout; 55 s more for starting Python and importing Dask
    # on a loaded machine.
    case.checks.append(Check("cli-scheduler", argv=argv, allowed=(), timeout=SCHEDULER_TIMEOUT + 55,
                             inputs=("command line", "scheduler", address[:40] or "address")))
    return case


# =============================================================================================
# The run


def make_base_renders(base: Path, timeout: float) -> None:
    """Good render EXRs (two seeds), MIS references (two seeds) and Sobol renders (two seeds,
    with their replicate layers) of cornell at 8 x 8: the material EXR cases damage. Also warms
    numba's cache (compiling after an edit takes ~100 s)."""
    base.mkdir(parents=True, exist_ok=True)
    scene = str(ROOT / "tracer" / "scenes" / "cornell.toml")
    small = ["--width", "8", "--height", "8", "--threads", "1", "--quiet"]
    commands = [["render", scene, "-o", "render_a.exr", "--spp", "4", "--seed", "1", *small],
                ["render", scene, "-o", "render_b.exr", "--spp", "4", "--seed", "2", *small],
                ["reference", scene, "-o", "reference_a.exr", "--spp", "8", "--seed", "3", *small],
                ["reference", scene, "-o", "reference_b.exr", "--spp", "8", "--seed", "4", *small],
                *(["render", scene, "-o", f"sobol_{part}.exr", "--spp", "16", "--seed", seed,
                   "--sampler", "sobol", *small] for part, seed in (("a", "5"), ("b", "6")))]

    def make(argv: list[str]) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "tracer", *argv], cwd=base, capture_output=True,
                              text=True, timeout=max(timeout, 300))

    first = make(commands[0])  # alone: after an edit of tracer it compiles the kernels for the rest
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = [first] + list(pool.map(make, commands[1:]))
    for argv, proc in zip(commands, results, strict=True):
        if proc.returncode != 0:
            raise SystemExit(f"fuzz: cannot make the base renders ({' '.join(argv[:2])}): "
                             f"{proc.stderr.strip()[-2000:]}")


def build_cases(seed: int, counts: dict[str, int], root: Path, base: Path,
                only: tuple[str, int] | None = None, servers=None) -> list[Case]:
    makers = {"scene": lambda i: make_scene_case(seed, i, root),
              "exr": lambda i: make_exr_case(seed, i, root, base),
              "baseline": lambda i: make_baseline_case(seed, i, root, base),
              "xml": lambda i: make_xml_case(seed, i, root),
              "scheduler": lambda i: make_scheduler_case(seed, i, root, servers)}
    if only is not None:
        cases = [makers[only[0]](only[1])]
    else:
        cases = [makers[family](i) for family in FAMILIES for i in range(counts.get(family, 0))]
    for case in cases:  # a 10000-character key is a mutation; its description need not be
        case.mutations = [m if len(m) <= 200 else m[:197] + "..." for m in case.mutations]
    return cases


@dataclass
class Report:
    """All outcomes of a run, and the failures grouped by signature."""

    outcomes: list[Outcome]
    seconds: float

    @property
    def failures(self) -> list[Outcome]:
        return [o for o in self.outcomes if o.kind in FAILURE_KINDS]

    def counts(self) -> dict[str, Counter]:
        table: dict[str, Counter] = {}
        for o in self.outcomes:
            table.setdefault(o.check.name, Counter())[o.kind] += 1
            for note in o.notes:
                table[o.check.name][note] += 1
        return table

    def distinct_failures(self) -> list[tuple[str, str, list[Outcome]]]:
        """(kind, signature, outcomes) per distinct failure, most severe first; each group's
        outcomes sorted with the simplest reproducer (fewest mutations) first."""
        groups: dict[tuple[str, str], list[Outcome]] = {}
        for o in self.failures:
            groups.setdefault((o.kind, o.signature), []).append(o)
        out = [(k, s, sorted(v, key=lambda o: (len(o.case.mutations), o.case.family, o.case.index)))
               for (k, s), v in groups.items()]
        return sorted(out, key=lambda g: (SEVERITY[g[0]], -len(g[2]), g[1]))

    def distinct_notes(self, note: str) -> list[tuple[str, list[Outcome]]]:
        groups: dict[str, list[Outcome]] = {}
        for o in self.outcomes:
            if note in o.notes:
                groups.setdefault(f"{o.check.name}: {o.signature}", []).append(o)
        return sorted(groups.items(), key=lambda g: -len(g[1]))


def reproduce_command(outcome: Outcome) -> str:
    """The shell command that repeats a check in its kept folder."""
    check = outcome.check
    if check.argv is not None:
        return "python -m tracer " + shlex.join(check.argv)
    kind, args = check.probe
    folder = str(outcome.case.folder)
    shown = [a.replace(folder, ".") if isinstance(a, str) else a for a in args]
    if kind == "load_scene" and len(args) == 2:
        return ("python -c \"import pickle, tracer; "
                "tracer.load_scene(pickle.load(open('dict_doc.pickle', 'rb')), base_dir='.')\""
                "  # the dict is also shown in dict_doc.txt")
    call = {"load_scene": "tracer.load_scene", "read_image": "tracer.read_image",
            "load_baseline": "tracer.study.check.load_baseline"}[kind]
    module = "tracer.study.check" if kind == "load_baseline" else "tracer"
    return f"python -c \"import {module}; {call}({shown[0]!r})\""


def kept_name(outcome: Outcome) -> str:
    """The folder name of a failure's reproducer under --keep."""
    return f"{outcome.case.family}-{outcome.case.index:04d}-{outcome.check.name}-{outcome.kind}"


def _copy_keeping_fifos(source: str, target: str) -> None:
    """copytree's copy: a FIFO is made anew (copying one would wait for a writer)."""
    import stat

    if stat.S_ISFIFO(os.lstat(source).st_mode):
        os.mkfifo(target)
    else:
        shutil.copy2(source, target)


def keep_failure(outcome: Outcome, keep: Path) -> Path:
    """Copy a failing case's folder to ``keep`` with REPRO.txt; returns the copy's path."""
    import pickle

    target = keep / kept_name(outcome)
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(outcome.case.folder, target, symlinks=True, copy_function=_copy_keeping_fifos)
    probe = outcome.check.probe
    if probe is not None and probe[0] == "load_scene" and len(probe[1]) == 2:
        doc = probe[1][0]
        (target / "dict_doc.txt").write_text(repr(doc)[:200000])
        try:
            (target / "dict_doc.pickle").write_bytes(pickle.dumps(doc))
        except Exception as exc:  # noqa: BLE001 - whatever pickle refuses, say so beside the repr
            (target / "dict_doc.txt").write_text(repr(doc)[:200000] + f"\n(not picklable: {exc})")
    lines = [f"kind: {outcome.kind}", f"check: {outcome.check.name}", f"signature: {outcome.signature}",
             f"detail: {outcome.detail}", "mutations:"] + [f"  - {m}" for m in outcome.case.mutations] + [
        f"regenerate: python benchmarks/fuzz.py --only {outcome.case.label} (same --seed)",
        f"command (in this folder): {reproduce_command(outcome)}", "", "stderr:", outcome.stderr[-6000:]]
    (target / "REPRO.txt").write_text("\n".join(lines) + "\n")
    return target


def run(seed: int = 0, scenes: int = 300, exrs: int = 100, baselines: int = 60, jobs: int = 2,
        timeout: float = 120.0, keep: Path | None = None, memory_gib: float = 4.0,
        only: tuple[str, int] | None = None, progress: bool = True, workdir: Path | None = None,
        xmls: int = 0, schedulers: int = 0) -> Report:
    """Generate the cases, run every check, keep the failures' reproducers; returns the report."""
    start = time.monotonic()
    memory_bytes = int(memory_gib * (1 << 30))
    root = Path(tempfile.mkdtemp(prefix="tracer-fuzz-", dir=workdir))
    try:
        base = root / "base"
        make_base_renders(base, timeout)
        counts = {"scene": scenes, "exr": exrs, "baseline": baselines, "xml": xmls, "scheduler": schedulers}
        servers = None
        if schedulers or (only is not None and only[0] == "scheduler"):
            import fuzz_scheduler

            servers = fuzz_scheduler.Servers()
        cases = build_cases(seed, counts, root / "cases", base, only, servers)
        probe = ProbeWorker(timeout, memory_bytes)
        outcomes: list[Outcome] = []
        done = 0
        total = sum(len(c.checks) for c in cases)

        def tick(outcome: Outcome) -> None:
            nonlocal done
            done += 1
            outcomes.append(outcome)
            if progress and (outcome.kind in FAILURE_KINDS or done % 50 == 0 or done == total):
                mark = ""
                if outcome.kind in FAILURE_KINDS:
                    mark = f"  {outcome.kind.upper()} {outcome.case.label} {outcome.check.name}: " \
                        f"{outcome.detail[:120]}"
                print(f"fuzz: {done}/{total} checks, {time.monotonic() - start:.0f} s{mark}", file=sys.stderr)

        try:
            with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
                futures = [pool.submit(run_cli, case, check, timeout, memory_bytes)
                           for case in cases for check in case.checks if check.argv is not None]
                for case in cases:
                    for check in case.checks:
                        if check.probe is not None:
                            tick(probe.run(case, check))
                for future in futures:
                    tick(future.result())
        finally:
            probe.close()
            if servers is not None:
                servers.close()
        report = Report(outcomes, time.monotonic() - start)
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
            listing = []
            for o in report.failures:
                where = keep_failure(o, keep)
                listing.append({"kind": o.kind, "signature": o.signature, "check": o.check.name,
                                "case": o.case.label, "detail": o.detail, "mutations": o.case.mutations,
                                "folder": str(where)})
            (keep / "failures.json").write_text(json.dumps(listing, indent=1, ensure_ascii=False) + "\n")
            with open(keep / "outcomes.jsonl", "w") as fh:  # every outcome, for tuning the mutations
                for o in report.outcomes:
                    row = {"case": o.case.label, "check": o.check.name, "kind": o.kind,
                           "notes": list(o.notes), "detail": o.detail, "mutations": o.case.mutations,
                           "seconds": round(o.seconds, 2)}
                    fh.write(json.dumps(row, ensure_ascii=False) + "\n")
            (keep / "summary.txt").write_text(format_report(report, keep))
        return report
    finally:
        shutil.rmtree(root, ignore_errors=True)


def format_report(report: Report, keep: Path | None = None) -> str:
    """Counts per check and class, then every distinct failure with its simplest reproducer."""
    lines = []
    counts = report.counts()
    columns = KINDS + NOTE_KINDS
    lines.append(f"{'check':<20}" + "".join(f"{k:>13}" for k in columns))
    total: Counter = Counter()
    for name in sorted(counts):
        total.update(counts[name])
        lines.append(f"{name:<20}" + "".join(f"{counts[name][k]:>13}" for k in columns))
    lines.append(f"{'all':<20}" + "".join(f"{total[k]:>13}" for k in columns))
    cases = len({o.case.label for o in report.outcomes})
    lines.append(f"\n{cases} cases, {len(report.outcomes)} checks, {len(report.failures)} failures, "
                 f"{report.seconds:.0f} s")
    groups = report.distinct_failures()
    if groups:
        lines.append(f"\n{len(groups)} distinct failures (most severe first):")
    for kind, signature, outcomes in groups:
        first = outcomes[0]
        lines.append(f"\n[{kind}] {signature}  ({len(outcomes)}x)")
        lines.append(f"  detail:    {first.detail[:300]}")
        lines.append(f"  case:      {first.case.label}: {'; '.join(first.case.mutations)[:300]}")
        lines.append(f"  command:   {reproduce_command(first)}")
        if keep is not None:
            lines.append(f"  kept in:   {keep / kept_name(first)}")
    for note, what in (("unnamed", "one-line refusals that name no input file"),
                       ("stderr-noise", "successful --quiet runs that printed on stderr")):
        groups = report.distinct_notes(note)
        if groups:
            lines.append(f"\nNote: {len(groups)} kinds of {what}:")
        for _signature, outcomes in groups:
            first = outcomes[0]
            mutations = "; ".join(first.case.mutations)[:200]
            lines.append(f"  ({len(outcomes)}x) {first.check.name}: {first.detail[:200]}")
            lines.append(f"        e.g. {first.case.label}: {mutations}")
    return "\n".join(lines) + "\n"


def parse_only(text: str) -> tuple[str, int]:
    family, _, index = text.partition(":")
    if family not in FAMILIES or not index.isdigit():
        raise argparse.ArgumentTypeError("expected FAMILY:INDEX, e.g. exr:17")
    return family, int(index)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0, help="seed of every case (default 0)")
    parser.add_argument("--scenes", type=int, default=300, help="scene cases (default 300)")
    parser.add_argument("--exrs", type=int, default=100, help="EXR cases (default 100)")
    parser.add_argument("--baselines", type=int, default=60, help="baseline cases (default 60)")
    parser.add_argument("--xmls", type=int, default=100, help="Mitsuba XML cases (default 100)")
    parser.add_argument("--schedulers", type=int, default=30,
                        help="--scheduler addresses that are no Dask scheduler (default 30)")
    parser.add_argument("--jobs", type=int, default=2, help="subprocesses at a time (default 2)")
    parser.add_argument("--timeout", type=float, default=120.0,
                        help="seconds per check before it counts as a hang (default 120: the first run "
                        "after an edit of tracer compiles its kernels, ~20 s)")
    parser.add_argument("--memory-gib", type=float, default=4.0, help="address-space limit per process")
    parser.add_argument("--keep", type=Path, help="folder for the failures' reproducers")
    parser.add_argument("--only", type=parse_only, help="run one case, FAMILY:INDEX (e.g. scene:12)")
    args = parser.parse_args(argv)
    report = run(args.seed, args.scenes, args.exrs, args.baselines, args.jobs, args.timeout, args.keep,
                 args.memory_gib, args.only, xmls=args.xmls, schedulers=args.schedulers)
    print(format_report(report, args.keep))
    return 1 if report.failures else 0


if __name__ == "__main__":
    sys.exit(main())
