"""The command line: bad input gives exit status 2 and one clear line; renders write the EXR
contract; the image does not depend on the thread count."""

from __future__ import annotations

import codecs
import errno
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from tracer.cli import main
from tracer.film import Film
from tracer.imagefiles import CHANNELS, read_exr, write_exr
from tracer.record import RenderRecord
from tracer.render_loop import SAMPLES_PER_PASS, RenderSettings, pass_samples, plan_batches, render
from tracer.scene import load_scene
from tracer.strategy import Strategy

GOOD = """
[camera]
origin = [0.0, 1.0, 3.0]
target = [0.0, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov = 40.0
width = 16
height = 12

[materials.white]
type = "diffuse"
reflectance = [0.7, 0.7, 0.7]

[materials.metal]
type = "roughconductor"
alpha = 0.1
reflectance = [0.9, 0.9, 0.9]

[[shapes]]
type = "quad"
origin = [-1.0, 0.0, -1.0]
edge1 = [0.0, 0.0, 2.0]
edge2 = [2.0, 0.0, 0.0]
material = "white"

[[shapes]]
type = "quad"
origin = [-0.2, 1.5, -0.2]
edge1 = [0.4, 0.0, 0.0]
edge2 = [0.0, 0.0, 0.4]
emission = [5.0, 5.0, 5.0]

[[shapes]]
type = "sphere"
center = [0.3, 0.3, 0.0]
radius = 0.3
subdivisions = 1
material = "metal"
"""


# GOOD with nothing emitting: a scene without lights.
DARK = GOOD.replace("emission = [5.0, 5.0, 5.0]", "")


def _mutate(old: str, new: str) -> str:
    assert old in GOOD, old
    return GOOD.replace(old, new, 1)


PLY_NAN = """ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
element face 1
property list uchar int vertex_indices
end_header
0 0 0
1 nan 0
0 1 0
3 0 1 2
"""

# (scene text, extra files, fragments the message must contain)
BAD_SCENES = {
    "bad toml": ("[camera\norigin = 1", {}, ["not valid TOML"]),
    "unknown top-level key": (GOOD + "\n[fog]\ndensity = 1\n", {}, ["fog", "unknown key"]),
    "unknown camera key": (_mutate("fov = 40.0", "fov = 40.0\nfocal = 3"), {}, ["camera.focal"]),
    "unknown shape type": (_mutate('type = "sphere"', 'type = "cylinder"'), {},
                           ["shapes[2].type", "cylinder"]),
    "unknown material type": (_mutate('type = "diffuse"', 'type = "velvet"'), {},
                              ["materials.white.type", "velvet"]),
    "unknown light type": (GOOD + '\n[[lights]]\ntype = "laser"\nposition = [0,1,0]\nintensity = [1,1,1]\n',
                           {}, ["lights[0].type", "laser"]),
    "wrong length": (_mutate("origin = [0.0, 1.0, 3.0]", "origin = [0.0, 1.0]"), {},
                     ["camera.origin", "3 numbers"]),
    "wrong type": (_mutate("fov = 40.0", 'fov = "wide"'), {}, ["camera.fov", "a number"]),
    "negative emission": (_mutate("emission = [5.0, 5.0, 5.0]", "emission = [5.0, -1.0, 5.0]"), {},
                          ["shapes[1].emission", ">= 0"]),
    "emission beyond float32": (_mutate("emission = [5.0, 5.0, 5.0]", "emission = [5.0, 1e39, 5.0]"), {},
                                ["shapes[1].emission", "<= 1e+18"]),
    # Numbers that pass float64 checks but not the renderer's float32 (the variance channel
    # squares radiance; Embree multiplies coordinate differences).
    "emission whose square overflows float32": (
        _mutate("emission = [5.0, 5.0, 5.0]", "emission = [5.0, 1e30, 5.0]"), {},
        ["shapes[1].emission", "<= 1e+18"]),
    "coordinate beyond float32": (_mutate("origin = [-1.0, 0.0, -1.0]", "origin = [-1.0, 1e300, -1.0]"), {},
                                  ["shapes[0].origin", "<= 1e+15"]),
    "camera target far away": (_mutate("target = [0.0, 0.5, 0.0]", "target = [0.0, 1e200, 0.0]"), {},
                               ["camera.target", "<= 1e+15"]),
    "sphere too small for float32": (_mutate("radius = 0.3", "radius = 1e-35"), {},
                                     ["shapes[2].radius", "float32"]),
    "non-finite number": (_mutate("fov = 40.0", "fov = nan"), {}, ["camera.fov", "finite"]),
    "infinite vertex": (_mutate("origin = [-1.0, 0.0, -1.0]", "origin = [-1.0, inf, -1.0]"), {},
                        ["shapes[0].origin", "finite"]),
    "negative radius": (_mutate("radius = 0.3", "radius = -0.3"), {}, ["shapes[2].radius"]),
    "reflectance above one": (_mutate("reflectance = [0.7, 0.7, 0.7]", "reflectance = [1.7, 0.7, 0.7]"),
                              {}, ["materials.white.reflectance", "<= 1"]),
    "zero alpha": (_mutate("alpha = 0.1", "alpha = 0.0"), {}, ["materials.metal.alpha"]),
    "unknown material": (_mutate('material = "white"', 'material = "snow"'), {},
                         ["shapes[0].material", "snow"]),
    "missing mesh": (GOOD + '\n[[shapes]]\ntype = "mesh"\nfile = "nowhere.ply"\n', {},
                     ["shapes[3].file", "not found"]),
    "unreadable mesh": (GOOD + '\n[[shapes]]\ntype = "mesh"\nfile = "junk.ply"\n',
                        {"junk.ply": "this is not a mesh\n"}, ["shapes[3].file", "junk.ply"]),
    "mesh with NaN vertex": (GOOD + '\n[[shapes]]\ntype = "mesh"\nfile = "nan.ply"\n',
                             {"nan.ply": PLY_NAN}, ["shapes[3].file", "non-finite vertex"]),
    "camera target at origin": (_mutate("target = [0.0, 0.5, 0.0]", "target = [0.0, 1.0, 3.0]"), {},
                                ["camera.target", "degenerate"]),
    "camera up along view": (_mutate("up = [0.0, 1.0, 0.0]", "up = [0.0, -0.5, -3.0]"), {},
                             ["camera.up", "parallel"]),
    "absurd resolution": (_mutate("width = 16", "width = 30000").replace("height = 12", "height = 30000"),
                          {}, ["camera.width/height", "GiB"]),
    "zero width": (_mutate("width = 16", "width = 0"), {}, ["camera.width"]),
    "missing camera": ("[materials.a]\ntype = 'mirror'\nreflectance = [1, 1, 1]\n", {},
                       ["camera", "missing"]),
    # Hostile files: each refused quickly with one line, no RecursionError or MemoryError.
    "nesting 1000 deep": ("a = " + "[" * 1000 + "]" * 1000 + "\n", {}, ["nested too deeply"]),
    "integer of 5000 digits": ("x = " + "9" * 5000 + "\n", {}, ["not valid TOML", "digits"]),
    "dotted key 50000 deep": ("a" + ".a" * 50000 + " = 1\n", {}, ["line 1", "dotted parts"]),
    "mesh name too long": (GOOD + '\n[[shapes]]\ntype = "mesh"\nfile = "' + "x" * 300 + '.ply"\n', {},
                           ["shapes[3].file", "cannot look up mesh"]),
    "shapes not an array": (GOOD.replace("[[shapes]]", "[shapesx]", 1).replace("[[shapes]]", "[[shapesy]]")
                            .replace("[shapesx]", "[shapes]"), {}, ["shapes"]),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_exits_2_with_one_clear_line(case, tmp_path, capsys):
    """Each way of breaking SCENE_FORMAT.md gives status 2 and one stderr line naming the file
    and the key, with no traceback, and writes no output file."""
    text, files, fragments = BAD_SCENES[case]
    scene = tmp_path / "broken.toml"
    scene.write_text(text)
    for name, content in files.items():
        (tmp_path / name).write_text(content)
    out = tmp_path / "out.exr"
    status = main(["render", str(scene), "-o", str(out), "--spp", "1", "--quiet"])
    err = capsys.readouterr().err
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "broken.toml" in lines[0] and "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert list(tmp_path.glob("out*")) == []


def test_missing_scene_file(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope.toml"), "--quiet"]) == 2
    assert "nope.toml: no such scene file" in capsys.readouterr().err


def test_bad_option_and_process_exit_status(tmp_path):
    """The installed entry point exits 2 on a bad option and on a broken file, with no traceback."""
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\n")
    for args in (["render", "--spp", "0"], ["render", str(bad)]):
        proc = subprocess.run([sys.executable, "-m", "tracer", *args], capture_output=True, text=True,
                              cwd=tmp_path, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("option, value, words", [
    ("--spp", str(2**53 + 1), "1 .. 9007199254740992"),
    ("--spp", "1e9", "expected a whole number"),
    ("--seed", str(2**64), "0 .. 18446744073709551615"),
    ("--threads", "100000", "1 .. 1024"),
    ("--light-samples", str(10**9), "0 .. 1000000"),
    ("--width", str(2**40), "1 .. 2147483647"),
])
def test_absurd_numbers_are_refused_in_one_line(option, value, words, capsys):
    """Numbers past what they can mean (sample indices past 2^53, seeds past 64 bits, a million
    threads each keeping two batches in flight) are refused by the parser: exit 2, one line
    naming the option and its range, not argparse's usage block (nine lines before)."""
    with pytest.raises(SystemExit) as info:
        main(["render", option, value])
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"argument {option}: " in err and words in err, err


def test_render_writes_exr_contract_and_png(tmp_path, capsys):
    """A CLI render writes the six channels, the header attributes and a PNG of the same stem."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "r.exr"
    assert main(["render", str(scene), "-o", str(out), "--spp", "3", "--strategy", "light",
                 "--seed", "9", "--threads", "2"]) == 0
    assert "16x12, 3 spp, light" in capsys.readouterr().err
    spec = oiio.ImageInput.open(str(out)).spec()
    assert tuple(spec.channelnames) == CHANNELS
    assert spec.getattribute("compression") == "zip"
    expected = {"tracer:spp": 3, "tracer:strategy": "light", "tracer:heuristic": "none", "tracer:seed": 9,
                "tracer:scene": str(scene)}
    for key, value in expected.items():
        assert spec.getattribute(key) == value, key
    assert spec.getattribute("tracer:seconds") > 0.0
    assert spec.getattribute("tracer:version")
    png = oiio.ImageBuf(str(tmp_path / "r.png"))
    assert (png.spec().width, png.spec().height) == (16, 12)


def test_default_scene_renders_from_any_directory(tmp_path):
    """Without SCENE, the veach_mis scene shipped in the package renders (here tiny and fast)."""
    proc = subprocess.run([sys.executable, "-m", "tracer", "render", "--spp", "1", "--width", "8",
                           "--height", "8", "--quiet"], capture_output=True, text=True, cwd=tmp_path,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "veach_mis_mis.exr").is_file() and (tmp_path / "veach_mis_mis.png").is_file()


def test_shipped_scenes_by_name_in_every_command(tmp_path, monkeypatch, capsys):
    """`tracer render cornell` in a folder of one's own said "cornell: no such scene file": now
    `tracer scenes` lists each shipped scene on one line (name and description), and render,
    reference, compare and convert take those names (outputs named after the scene); a name
    that matches nothing is exit 2 with one line listing the names."""
    from tracer.scene import shipped_scenes

    monkeypatch.chdir(tmp_path)
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    shipped = shipped_scenes()
    assert len(lines) == len(shipped)
    for line, s in zip(lines, shipped, strict=True):
        assert line.split()[0] == s.name and line.endswith(s.description)
    small = ["--width", "8", "--height", "8", "--quiet"]  # cornell is square
    assert main(["render", "cornell", "--spp", "1", *small]) == 0
    assert read_exr(tmp_path / "cornell_mis.exr").record.scene_digest == load_scene("cornell").digest
    assert main(["reference", "cornell", "--spp", "8", *small]) == 0
    assert (tmp_path / "cornell_reference.exr").is_file()
    assert main(["compare", "cornell", "--reference", "cornell_reference.exr", "--strategies", "light",
                 "--spp", "2", "--out", "cmp", "--quiet"]) == 0
    assert (tmp_path / "cmp" / "index.html").is_file()
    assert main(["convert", "cornell", "--quiet"]) == 0
    assert load_scene(tmp_path / "cornell.toml").digest == load_scene("cornell").digest
    capsys.readouterr()
    assert main(["render", "cornel", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tracer: error: cornel: no such scene file, nor a shipped")
    assert "cornell, " in err[0] and "mitsuba/veach_mis" in err[0]


def test_render_never_replaces_an_existing_output_unless_forced(tmp_path, monkeypatch, capsys):
    """The Mitsuba veach_mis silently replaced the quick start's veach_mis_mis.exr (both scenes
    are named veach_mis). Now a render onto an existing EXR, or onto a file where its PNG
    preview goes, is exit 2 with one line naming the file and the ways on (--force, -o), before
    any rendering, and leaves both files as they were; --force replaces them and -o writes
    elsewhere. A fresh folder's plain `tracer render` (the quick start) is not affected."""
    import os

    monkeypatch.chdir(tmp_path)
    small = ["--spp", "1", "--width", "8", "--height", "6", "--quiet"]
    assert main(["render", *small]) == 0
    exr, png = tmp_path / "veach_mis_mis.exr", tmp_path / "veach_mis_mis.png"
    before = {p: (p.read_bytes(), os.stat(p).st_mtime_ns) for p in (exr, png)}
    capsys.readouterr()
    for argv in (["render", "mitsuba/veach_mis", *small], ["render", "veach_mis", "--seed", "0", *small]):
        assert main(argv) == 2
        errors = [line for line in capsys.readouterr().err.splitlines() if "note:" not in line]
        assert errors == [f"tracer: error: {exr.name}: a render exists here: --force replaces it, or -o "
                          "OUT.exr writes another file"], errors
    assert {p: (p.read_bytes(), os.stat(p).st_mtime_ns) for p in (exr, png)} == before
    assert main(["render", "mitsuba/veach_mis", "-o", "xml.exr", *small]) == 0
    assert read_exr(tmp_path / "xml.exr").record.scene_digest == load_scene("mitsuba/veach_mis").digest
    assert main(["render", "mitsuba/veach_mis", "--force", *small]) == 0
    assert read_exr(exr).record.scene_digest == load_scene("mitsuba/veach_mis").digest
    exr.unlink()  # a preview left alone is still somebody's image
    capsys.readouterr()
    assert main(["render", "veach_mis", *small]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"tracer: error: {png.name}: a file exists where this render's PNG preview goes: "
                   "--force replaces it, or -o OUT.exr writes another file"], err
    assert not exr.exists()


@pytest.mark.parametrize("strategy", [Strategy("mis"), Strategy("light"),
                                      Strategy("mis", "balance", 2, 2, one_sample=True)])
def test_same_seed_same_image_whatever_threads_and_batch_size(tmp_path, strategy):
    """Bit-identical films for 1 and 2 threads and for three batch sizes (from 7 lanes, smaller
    than a pass, to all 192 pixels in one batch): every random number is a function of (seed,
    pixel, sample index, dimension), passes do not depend on the batch size, and batches merge
    in a fixed order. Exact equality: any dependence on the batch layout changes the bits."""
    scene_path = tmp_path / "s.toml"
    scene_path.write_text(GOOD)
    scene = load_scene(scene_path)
    films = []
    for threads, lanes in [(1, 100), (2, 100), (2, 7), (1, 1 << 15)]:
        settings = RenderSettings(spp=13, seed=11, threads=threads, batch_lanes=lanes)
        films.append(render(scene, strategy, settings).film)
    for film in films[1:]:
        assert np.array_equal(films[0].mean, film.mean)
        assert np.array_equal(films[0].m2, film.m2)
    other_seed = render(scene, strategy, RenderSettings(spp=13, seed=12, threads=2, batch_lanes=100)).film
    assert not np.array_equal(films[0].mean, other_seed.mean)


def test_resumed_samples_are_fresh(tmp_path):
    """first_sample shifts the random streams: a second run with first_sample = spp gives
    different samples, and merging both equals one film with the pooled samples' count."""
    scene_path = tmp_path / "s.toml"
    scene_path.write_text(GOOD)
    scene = load_scene(scene_path)
    a = render(scene, Strategy("mis"), RenderSettings(spp=4, seed=1, threads=1)).film
    b = render(scene, Strategy("mis"), RenderSettings(spp=4, seed=1, threads=1, first_sample=4)).film
    assert not np.array_equal(a.mean, b.mean)
    a.merge(b)
    assert a.spp == 8 and isinstance(a, Film)


# How long a test waits for a tracer subprocess to say what it waits for, before it fails with
# what was said: only a child that hangs or is broken should reach it. Far beyond a first
# compilation of the suite's kernels on a loaded machine (53 s on 2 idle cores, with a second
# process compiling alongside; at load 5-10 tracer compiles in one process and gets a fraction
# of a core).
SAID_DEADLINE = 600.0

# tqdm's counter of the samples done, "| 97.9k/384k [" (unit_scale: k, M, G, ... by 1000).
_SAMPLES_DONE = re.compile(r"\| (\d+(?:\.\d+)?)([kMGTPEZY]?)/\d")


def _samples_done(text: str) -> float:
    """The samples the last progress bar drawn in ``text`` counts as done (0 before any)."""
    counts = _SAMPLES_DONE.findall(text)
    if not counts:
        return 0.0
    number, prefix = counts[-1]
    return float(number) * 1000.0 ** " kMGTPEZY".index(prefix or " ")


def _as_shown(text: str) -> str:
    """``text`` as a terminal shows it: "\r\n" ends a line, and after a "\r" (tqdm redraws
    its bar with one, and clears it with spaces) what follows overwrites the line from its start."""
    lines = []
    for raw in text.replace("\r\n", "\n").split("\n"):
        line = ""
        for part in raw.split("\r"):
            line = part + line[len(part):]
        lines.append(line.rstrip())
    return "\n".join(lines)


class _Tracer:
    """A ``python -m tracer ARGV`` subprocess whose stderr a thread collects until EOF, so that
    a test waits for what tracer says (:meth:`wait_for`), never for a number of seconds: at load
    5-10 a fixed sleep ran out while tracer was still importing or compiling, and the signal
    meant for a render in progress landed before it.

    With ``tty`` stderr is a pseudo-terminal, as at a shell: tracer draws its progress bar only
    on a terminal (``render_loop.progress_bar``; on a pipe a render says nothing until it ends),
    and the bar's count of samples done is what says the render is under way
    (:meth:`wait_for_samples`). Each of three things about a pty hangs a test that gets it wrong:
    the parent must close its copy of the slave end, or reading never reaches EOF; on Linux EOF
    on the master is an ``EIO`` error, not an empty read; and the master must be read until
    then, also after the signal, or the child blocks writing its bar (redrawn every 0.1 s) once
    the pty's few kilobytes of buffer are full, and never gets to stop. The terminal turns "\n"
    into "\r\n" and tqdm redraws with "\r": :attr:`err` is the text as the terminal shows it.

    SIGINT is at its default in the child: a non-interactive shell may start us with SIGINT
    ignored, and Python then keeps it ignored. A test that fails leaves no child running."""

    def __init__(self, argv: list[str], env: dict | None = None, tty: bool = False):
        import fcntl
        import pty
        import struct
        import termios

        if tty:
            read_fd, write_fd = pty.openpty()
            # Wide, so that tqdm draws its whole bar, counter included, on one line.
            fcntl.ioctl(write_fd, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 200, 0, 0))
        else:
            read_fd, write_fd = os.pipe()
        try:
            self.proc = subprocess.Popen([sys.executable, "-m", "tracer", *argv], stderr=write_fd, env=env,
                                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        except BaseException:
            os.close(read_fd)
            raise
        finally:
            os.close(write_fd)  # the child has its own copy: EOF comes when it exits
        self._text = ""
        self._eof = False
        self._changed = threading.Condition()
        self._reader = threading.Thread(target=self._read, args=(read_fd,), daemon=True)
        self._reader.start()

    def _read(self, fd: int) -> None:
        decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
        try:
            while True:
                try:
                    chunk = os.read(fd, 65536)
                except OSError as exc:
                    if exc.errno != errno.EIO:  # EIO: EOF on a pty's master
                        raise
                    chunk = b""
                with self._changed:
                    self._text += decoder.decode(chunk, final=not chunk)
                    self._changed.notify_all()
                if not chunk:
                    return
        finally:
            os.close(fd)
            with self._changed:
                self._eof = True
                self._changed.notify_all()

    @property
    def err(self) -> str:
        """What tracer wrote to stderr so far, as a terminal (or a file, for a pipe) shows it."""
        with self._changed:
            return _as_shown(self._text)

    def wait_for(self, condition, what: str):
        """Wait until ``condition(the raw text said so far)`` is true and return its value;
        fail, with what was said, if tracer closes stderr (ends) first or SAID_DEADLINE passes."""
        deadline = time.monotonic() + SAID_DEADLINE
        with self._changed:
            while not (found := condition(self._text)):
                left = deadline - time.monotonic()
                assert not self._eof, f"tracer ended before {what}; it said:\n{self.err}"
                assert left > 0, f"no {what} in {SAID_DEADLINE:.0f} s; tracer said:\n{self.err}"
                self._changed.wait(left)
            return found

    def wait_for_samples(self, more_than: float) -> float:
        """Wait until the progress bar counts more than ``more_than`` samples done (tqdm rounds
        the count to 3 digits); returns the count."""
        def past(text: str) -> float | None:
            done = _samples_done(text)
            return done if done > more_than else None

        return self.wait_for(past, f"progress bar past {more_than:.0f} samples")

    def finish(self, timeout: float = SAID_DEADLINE) -> tuple[int, str]:
        """Wait for tracer to end and for the rest of its stderr: (exit status, :attr:`err`).
        As long by default as any wait: a render interrupted while compiling ends only once
        compiled, which at load 6 took more than the 120 s the tests once allowed."""
        code = self.proc.wait(timeout=timeout)
        self._reader.join(timeout)
        assert not self._reader.is_alive(), f"stderr still open after tracer ended; it said:\n{self.err}"
        return code, self.err

    def __enter__(self) -> "_Tracer":
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:  # the test failed: leave no render running
            self.proc.kill()
            self.proc.wait()
        self._reader.join(30)


def _render_argv(scene, out, spp: int, *options: str) -> list[str]:
    return ["render", str(scene), "-o", str(out), "--spp", str(spp), "--threads", "2", *options]


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_interrupt_writes_what_was_rendered(tmp_path, signum):
    """Ctrl-C (or kill) mid-render: exit status 130, the EXR holds every finished sample with its
    true spp (fewer than asked), and no temporary file is left behind. The signal is sent once
    the progress bar counts more than two passes of samples done, so that it lands while
    rendering (not while tracer still loads or compiles), whatever the machine's load."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "r.exr"
    spp, pixels = 10_000_000, 16 * 12
    one_pass = pixels * pass_samples(spp, pixels, Strategy("mis").samples_per_lane)
    with _Tracer(_render_argv(scene, out, spp), tty=True) as child:
        child.wait_for_samples(2 * one_pass)
        child.proc.send_signal(getattr(signal, signum))
        code, err = child.finish()
    assert code == 130, err
    assert "interrupted" in err and "Traceback" not in err
    film = read_exr(out)
    assert 0 < film.spp < 10_000_000
    # The record lists the indices drawn (each pixel holds a prefix), not the spp asked for.
    assert film.record.samples == ((0, 0, int(film.count.max())),)
    # The summary states the file's counts (it once gave an average that disagreed with them).
    assert f"every pixel holds {film.spp} spp or more, up to {int(film.count.max())}" in err, err
    assert film.record.strategy == "mis" and film.record.seed == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.exr", "r.png", "s.toml"]


@pytest.mark.slow  # one whole compilation of the kernels in a child process: 92 s of the 14-minute CI run
def test_interrupt_while_compiling_leaves_files_alone(tmp_path):
    """Ctrl-C during the first compilation (an empty kernel cache, so compiling takes seconds),
    sent once tracer's line says it is compiling: the render stops once the kernels are compiled
    (an interrupt inside numba's compiler would break it), exit 130 with no traceback, and
    besides the compile line (on a pipe every ten seconds, and once more when done) only a line
    saying it stops after compiling and one saying nothing was written; an existing output file
    is left as it was (nothing was rendered, so nothing is written over it)."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "r.exr"
    out.write_bytes(b"an earlier render")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    compiling = "tracer: compiling the kernels"
    # The compile line's messages: "...: 1 s", ..., "...: done in 52.6 s".
    progress = re.compile(re.escape(compiling) + r".*?: (?:\d+ s|done in \d+\.\d s)")
    with _Tracer(_render_argv(scene, out, 4, "--force"), env=env) as child:  # --force: out exists
        # The whole line: print() writes its newline apart, and a note printed from another
        # thread (as the signal's is) can land between the two.
        child.wait_for(lambda text: re.search(progress.pattern + "\n", text), "compile line")
        child.proc.send_signal(signal.SIGINT)
        code, err = child.finish()
    assert code == 130, err
    assert "Traceback" not in err and "nothing written" in err.strip().splitlines()[-1], err
    assert "done in" in progress.findall(err)[-1], err
    said = [line for line in progress.sub("", err).splitlines() if line]
    assert said[:1] == ["tracer: interrupted; stopping as soon as the kernels are compiled"], err
    assert len(said) <= 2, err
    assert out.read_bytes() == b"an earlier render"


def test_primer_command_writes_five_figures(tmp_path, capsys):
    """`tracer primer --out DIR` prints the five tables and writes one figure per exercise."""
    assert main(["primer", "--out", str(tmp_path)]) == 0
    assert len(list(tmp_path.glob("primer_*.png"))) == 5
    out = capsys.readouterr().out
    assert all(f"{k}. " in out for k in range(1, 6))


@pytest.mark.parametrize("lanes", [1, 3, 8, 100, 32768])
def test_batches_cover_every_sample_once_within_the_lane_bound(lanes):
    """plan_batches gives every (pixel, sample index) exactly one lane, passes of the same k
    samples whatever the batch size (so the film folds the same groups), and never more than
    batch_lanes lanes to a batch, or one pixel's pass if that is more."""
    batches = list(plan_batches(10, 7, 13, first_sample=5, batch_lanes=lanes, k=SAMPLES_PER_PASS))
    assert max(b.lanes for b in batches) <= max(lanes, SAMPLES_PER_PASS)
    assert {b.k for b in batches} == {SAMPLES_PER_PASS, 13 - SAMPLES_PER_PASS}
    covered = sorted((b.first_sample + j, p) for b in batches
                     for p in range(b.first_pixel, b.first_pixel + b.npix) for j in range(b.k))
    assert covered == [(s, p) for s in range(5, 18) for p in range(70)]


def test_render_refuses_to_add_samples_the_record_cannot_describe(tmp_path):
    """A film that holds samples takes more only from the same estimator, sampler and scene at
    sample indices it does not hold: repeated indices, another heuristic or another scene raise
    InputError naming what differs, and the film is left as it was; another seed is taken and
    the record then lists both ranges. A film interrupted in its first pass (some pixels without
    samples) still counts as holding samples."""
    from tracer.errors import InputError

    scene_path = tmp_path / "s.toml"
    scene_path.write_text(GOOD)
    scene = load_scene(scene_path)
    (tmp_path / "other").mkdir()
    brighter = _mutate("emission = [5.0, 5.0, 5.0]", "emission = [5.0, 5.0, 6.0]")
    (tmp_path / "other" / "s.toml").write_text(brighter)
    other_scene = load_scene(tmp_path / "other" / "s.toml")  # same file name, other content
    film = render(scene, Strategy("mis"), RenderSettings(spp=4, seed=1, threads=1)).film
    before = film.mean.copy()
    for settings, strategy, where, words in [
        (RenderSettings(spp=4, seed=1, threads=1, first_sample=2), Strategy("mis"), scene,
         "sample indices 0-3 and 2-5 overlap"),
        (RenderSettings(spp=4, seed=1, threads=1, first_sample=4), Strategy("mis", "balance"), scene,
         "tracer:heuristic"),
        (RenderSettings(spp=4, seed=1, threads=1, first_sample=4), Strategy("mis"), other_scene,
         "tracer:scene_digest"),
    ]:
        with pytest.raises(InputError, match=words):
            render(where, strategy, settings, film=film)
        assert np.array_equal(film.mean, before)
    two_seeds = render(scene, Strategy("mis"), RenderSettings(spp=2, seed=7, threads=1),
                       film=film.copy()).film
    assert two_seeds.record.samples == ((1, 0, 4), (7, 0, 2)) and two_seeds.record.seed is None
    partial = Film(film.width, film.height)
    partial.add_block(0, np.ones((3, 1, 3)))  # three pixels of a first pass, the rest empty
    partial.record = film.record
    result = render(scene, Strategy("mis"), RenderSettings(spp=2, seed=1, threads=1, first_sample=4),
                    film=partial)
    assert result.film.record.first_sample == 0 and result.film.record.next_sample == 6


def test_reference_resume_refuses_other_settings(tmp_path, capsys):
    """`reference --resume` with another heuristic than the file's: exit 2, one line naming the
    field, the reference unchanged."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "ref.exr"
    assert main(["reference", str(scene), "-o", str(out), "--spp", "2", "--quiet"]) == 0
    data = out.read_bytes()
    capsys.readouterr()
    assert main(["reference", str(scene), "-o", str(out), "--spp", "2", "--resume", "--heuristic", "balance",
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "tracer:heuristic" in err and len(err.strip().splitlines()) == 1
    assert out.read_bytes() == data


def test_batch_plan_is_lazy_and_sample_indices_are_bounded(tmp_path):
    """Planning a billion-billion samples costs nothing until batches are taken (the plan is a
    generator: memory flat in spp), and sample indices past 2^53, where counts stop being exact
    in float64, are refused before any work."""
    import itertools

    from tracer.errors import InputError

    first = list(itertools.islice(plan_batches(64, 64, 10**18), 3))
    assert [(b.first_sample, b.first_pixel, b.npix, b.k) for b in first] == [
        (0, 0, 4096, 8), (8, 0, 4096, 8), (16, 0, 4096, 8)]
    scene_path = tmp_path / "s.toml"
    scene_path.write_text(GOOD)
    with pytest.raises(InputError, match="sample indices must lie in"):
        render(load_scene(scene_path), Strategy("mis"), RenderSettings(spp=2**53, first_sample=1, threads=1))


def test_output_problems_are_found_before_rendering(tmp_path, capsys):
    """-o naming a folder, or a PNG preview path that is a folder, and an absurd exposure: exit 2
    with one line before any rendering (no compile message, no summary)."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    (tmp_path / "out.exr").mkdir()
    (tmp_path / "other.png").mkdir()
    for out in ("out.exr", "other.exr"):
        assert main(["render", str(scene), "-o", str(tmp_path / out), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert "is a folder" in err and len(err.strip().splitlines()) == 1, err
    with pytest.raises(SystemExit) as exit_info:
        main(["render", str(scene), "--exposure", "2000"])
    assert exit_info.value.code == 2
    assert "-100 .. 100" in capsys.readouterr().err


def test_a_signal_during_the_final_write_keeps_the_files(tmp_path, monkeypatch, capsys):
    """Ctrl-C arriving while the finished render is written (injected: the EXR writer signals
    the process itself half-way) is held until the EXR and the PNG are complete; then exit
    130 with a line saying so. Without the deferral the KeyboardInterrupt would abort the
    writes and lose the render."""
    import os
    import signal

    from tracer import imagefiles

    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "r.exr"
    real_write = imagefiles.write_exr

    def interrupted_write(path, film, half=False):
        os.kill(os.getpid(), signal.SIGINT)
        real_write(path, film, half=half)

    monkeypatch.setattr(imagefiles, "write_exr", interrupted_write)
    assert main(["render", str(scene), "-o", str(out), "--spp", "2", "--quiet", "--threads", "1"]) == 130
    assert "interrupted while writing" in capsys.readouterr().err
    assert read_exr(out).spp == 2 and out.with_suffix(".png").stat().st_size > 0


def test_seeds_and_sample_indices_past_32_bits_round_trip(tmp_path):
    """EXR integer attributes are 32-bit: a seed and sample indices >= 2^31 are stored so that
    they read back exactly, and such a render writes and resumes."""
    scene_path = tmp_path / "s.toml"
    scene_path.write_text(GOOD)
    out = tmp_path / "r.exr"
    seed = 2**40 + 3
    assert main(["reference", str(scene_path), "-o", str(out), "--spp", "1", "--seed", str(seed),
                 "--quiet"]) == 0
    assert main(["reference", str(scene_path), "-o", str(out), "--spp", "1", "--resume", "--quiet"]) == 0
    film = read_exr(out)
    assert film.record.samples == ((seed, 0, 2),) and film.spp == 2


@pytest.mark.slow  # 12 s: slow since tracer 0.8, for the CI budget (Ctrl-C is tested in every run above)
def test_a_billion_spp_render_has_flat_memory_and_stops_on_ctrl_c(tmp_path):
    """`--spp 1000000000` at 64x64: resident memory grows by less than 40 MiB while the render
    draws 20 M samples, from when its progress bar counts two passes done (the batch plan is
    lazy and the film fixed-size), and Ctrl-C then writes what was rendered (exit 130). Counted
    in samples, not seconds, so that a loaded machine measures the same stretch of the render.
    A plan built up front grew by about 40 MB/s before the first batch: the bar would not start,
    and the test fails at the wait's deadline (SAID_DEADLINE) saying so."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "r.exr"
    spp, pixels = 1_000_000_000, 64 * 64
    one_pass = pixels * pass_samples(spp, pixels, Strategy("mis").samples_per_lane)

    def rss_mib(pid: int) -> float:
        status = Path(f"/proc/{pid}/status").read_text()
        return int(re.search(r"VmRSS:\s+(\d+) kB", status).group(1)) / 1024

    with _Tracer(_render_argv(scene, out, spp, "--width", "64", "--height", "64"), tty=True) as child:
        started = child.wait_for_samples(2 * one_pass)
        early = rss_mib(child.proc.pid)
        child.wait_for_samples(started + 20_000_000)
        late = rss_mib(child.proc.pid)
        child.proc.send_signal(signal.SIGINT)
        code, err = child.finish()
    assert late - early < 40.0, (early, late)
    assert code == 130, err
    assert 0 < read_exr(out).spp < 1_000_000_000


def test_a_reference_is_replaced_only_when_asked_and_resumes_with_its_own_settings(tmp_path, capsys):
    """`reference` onto an existing file: refused (it silently replaced a 512-spp reference with
    16 spp) unless --force. --resume takes the file's resolution and estimator settings when
    they are not given (it failed unless --width/--height were repeated), and refuses them when
    given otherwise."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "ref.exr"
    base = ["reference", str(scene), "-o", str(out), "--quiet"]
    assert main(base + ["--spp", "2", "--width", "8", "--heuristic", "balance"]) == 0
    before = out.read_bytes()
    assert main(base + ["--spp", "2"]) == 2
    refusal = "a reference exists here: --resume adds samples to it, --force replaces it"
    assert refusal in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main(base + ["--spp", "2", "--resume"]) == 0  # 8x6 and balance, from the file
    grown = read_exr(out)
    assert (grown.width, grown.height, grown.spp, grown.record.heuristic) == (8, 6, 4, "balance")
    assert main(base + ["--spp", "2", "--resume", "--heuristic", "power"]) == 2
    assert "tracer:heuristic" in capsys.readouterr().err
    assert main(base + ["--spp", "1", "--force"]) == 0
    assert read_exr(out).spp == 1 and read_exr(out).width == 16


def test_one_side_keeps_the_aspect_ratio():
    """--width alone on a 16x12 camera gives 32x24, --height alone 8x6 (it gave a 32x12
    sliver); both given are taken as they are."""
    tables = tomllib.loads(GOOD)
    assert (load_scene(tables, width=32).camera.width, load_scene(tables, width=32).camera.height) == (32, 24)
    assert (load_scene(tables, height=6).camera.width, load_scene(tables, height=6).camera.height) == (8, 6)
    assert (load_scene(tables, 5, 40).camera.width, load_scene(tables, 5, 40).camera.height) == (5, 40)


def test_default_names_tell_settings_apart_and_the_summary_says_them(tmp_path, monkeypatch, capsys):
    """Renders with other settings get other default names (balance and max wrote the same
    veach_mis_mis.exr over each other); the summary names the light selection; a scene without
    lights gets a warning instead of a silent black image."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    monkeypatch.chdir(tmp_path)
    for options in ([], ["--heuristic", "max"], ["--light-samples", "2", "--one-sample"],
                    ["--strategy", "light", "--light-selection", "uniform", "--seed", "5"]):
        assert main(["render", str(scene), "--spp", "1", *options]) == 0
    names = sorted(p.name for p in tmp_path.glob("*.exr"))
    assert names == ["s_light_uniform-lights_seed5.exr", "s_mis.exr", "s_mis_l2_b1_one-sample.exr",
                     "s_mis_max.exr"]
    assert "light (lights picked uniformly)" in capsys.readouterr().err
    dark = tmp_path / "dark.toml"
    dark.write_text(DARK)
    assert main(["render", str(dark), "--spp", "1", "--quiet"]) == 0
    assert "has no lights" in capsys.readouterr().err


def scene_and_default(tmp_path, monkeypatch, render_line: str) -> tuple[Path, Path]:
    """s.toml (GOOD) and d.toml (GOOD with ``render_line`` in its [render] table) in tmp_path,
    which becomes the current folder."""
    scene, with_default = tmp_path / "s.toml", tmp_path / "d.toml"
    scene.write_text(GOOD)
    with_default.write_text(f"[render]\n{render_line}\n" + GOOD)
    monkeypatch.chdir(tmp_path)
    return scene, with_default


def test_light_sampling_from_the_command_line_and_the_scene(tmp_path, monkeypatch, capsys):
    """--light-sampling reaches the render (its record and default name say it), a scene's
    [render] light_sampling is the default that the flag overrides, strategies without light
    samples record none, and a bad name is one line with exit status 2."""
    scene, with_default = scene_and_default(tmp_path, monkeypatch, 'light_sampling = "solid-angle-cos"')
    assert main(["render", str(scene), "--spp", "1", "--quiet", "--light-sampling", "solid-angle"]) == 0
    assert read_exr(tmp_path / "s_mis_solid-angle.exr").record.light_sampling == "solid-angle"
    assert main(["render", str(with_default), "--spp", "1", "--quiet"]) == 0
    assert read_exr(tmp_path / "d_mis_solid-angle-cos.exr").record.light_sampling == "solid-angle-cos"
    assert main(["render", str(with_default), "--spp", "1", "--quiet", "--light-sampling", "area"]) == 0
    assert read_exr(tmp_path / "d_mis.exr").record.light_sampling == "area"
    assert main(["render", str(scene), "--spp", "1", "--quiet", "--strategy", "bsdf"]) == 0
    assert read_exr(tmp_path / "s_bsdf.exr").record.light_sampling == "none"
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(["render", str(scene), "--light-sampling", "cone"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--light-sampling" in err[0] and "cone" in err[0]


def test_files_without_light_sampling_pool_as_area_sampled(tmp_path):
    """A render of tracer 0.2 has no tracer:light_sampling; it sampled lights by area, so it
    pools with an area render of this version and is refused with a solid-angle one, naming
    the field."""
    import dataclasses

    from tracer.errors import InputError
    from tracer.record import check_mergeable

    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    assert main(["render", str(scene), "--spp", "1", "--quiet", "-o", str(tmp_path / "a.exr")]) == 0
    assert main(["render", str(scene), "--spp", "1", "--quiet", "--seed", "1", "--light-sampling",
                 "solid-angle", "-o", str(tmp_path / "b.exr")]) == 0
    area, solid = read_exr(tmp_path / "a.exr").record, read_exr(tmp_path / "b.exr").record
    old = dataclasses.replace(area, light_sampling=None, samples=((7, 0, 1),))
    check_mergeable(old, area)
    with pytest.raises(InputError, match="light_sampling"):
        check_mergeable(old, solid)


def test_sampler_from_the_command_line_and_the_scene(tmp_path, monkeypatch, capsys):
    """--sampler reaches the render (its record, its replicate layers and its default name say
    it), a scene's [render] sampler is the default that the flag overrides, a reference resumes
    with its own sampler and refuses another, and a bad name is one line with exit status 2."""
    scene, with_default = scene_and_default(tmp_path, monkeypatch, 'sampler = "sobol"')
    assert main(["render", str(scene), "--spp", "8", "--quiet", "--sampler", "stratified"]) == 0
    film = read_exr(tmp_path / "s_mis_stratified.exr")
    assert film.record.sampler == "stratified" and film.replicates == 8
    assert np.all(film.rep_count == 1)  # 8 samples: one in each replicate
    assert main(["render", str(with_default), "--spp", "2", "--quiet"]) == 0
    assert read_exr(tmp_path / "d_mis_sobol.exr").record.sampler == "sobol"
    assert main(["render", str(with_default), "--spp", "2", "--quiet", "--sampler", "independent"]) == 0
    assert read_exr(tmp_path / "d_mis.exr").replicates == 0
    ref = tmp_path / "ref.exr"
    assert main(["reference", str(scene), "--spp", "16", "--sampler", "sobol", "-o", str(ref),
                 "--quiet"]) == 0
    assert main(["reference", str(scene), "--spp", "16", "--resume", "-o", str(ref), "--quiet"]) == 0
    grown = read_exr(ref)
    assert grown.record.sampler == "sobol" and grown.record.samples == ((0, 0, 32),)
    assert np.all(grown.rep_count == 4)
    capsys.readouterr()
    assert main(["reference", str(scene), "--spp", "8", "--resume", "--sampler", "stratified", "-o", str(ref),
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sobol sampler, not stratified" in err[0] and "ref.exr" in err[0]
    with pytest.raises(SystemExit) as exit_info:
        main(["render", str(scene), "--sampler", "halton"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--sampler" in err[0] and "halton" in err[0]
    bad = tmp_path / "bad.toml"
    bad.write_text('[render]\nsampler = "halton"\n' + GOOD)
    assert main(["render", str(bad), "--spp", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.toml" in err[0] and "sampler" in err[0] and "halton" in err[0]


def _rewrite_header(path: Path, changes: dict) -> None:
    """Rewrite the EXR at ``path`` with its pixels as they are and ``changes`` made to its
    header: what a damaged or edited file holds, which tracer's writer never writes."""
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    spec.set_format(oiio.FLOAT)
    for key, value in changes.items():
        spec.attribute(key, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels)
    out.close()


@pytest.mark.parametrize("changes, words", [
    ({"tracer:light_samples": 2147483647}, "tracer:light_samples = 2147483647 is not a valid light_samples"),
    ({"tracer:spp": 0}, "holds no samples but a mean or variance that is not 0"),
], ids=["light samples past the bound", "spp 0 over 8 real samples"])
def test_a_resume_trusts_no_header_field_it_cannot_check(tmp_path, capsys, changes, words):
    """Issue 38.4: `reference --resume` of a file whose header says 2^31 - 1 light samples
    allocated 24 GiB and died in a numpy traceback; one whose header says 0 spp over pixels
    that hold 8 samples kept only the new samples, silently. Both are refused before any
    rendering, with one line naming the file, and the file is left as it was."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "ref.exr"
    film = Film(4, 3)
    film.add_block(0, np.random.default_rng(5).uniform(0.0, 1.0, size=(12, 8, 3)))
    film.record = RenderRecord(strategy="mis", heuristic="power", light_samples=1, bsdf_samples=1,
                               one_sample=False, light_selection="power", light_sampling="area",
                               allocation="fixed", sampler="independent", samples=((0, 0, 8),),
                               seconds=1.0, scene=str(scene), scene_digest=load_scene(scene).digest)
    write_exr(out, film)
    _rewrite_header(out, changes)
    before = out.read_bytes()
    capsys.readouterr()
    assert main(["reference", str(scene), "-o", str(out), "--spp", "4", "--resume", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert words in err and str(out) in err and len(err.strip().splitlines()) == 1, err
    assert out.read_bytes() == before
