"""Failing disks: a write that fails (full disk, failing device) exits 2 with one line naming
the file the user asked for, keeps the file that was there, and leaves no temporary file.

Two ways to make the write fail: a real full file system (a small tmpfs, mounted only when the
tests run as root, skipped otherwise) and an injected failure of the final flush to disk
(``tracer.atomic._sync``), which runs everywhere."""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_cli import GOOD

from tracer import atomic
from tracer.cli import main
from tracer.errors import InputError


def _one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("tracer: error: "), err
    assert "Traceback" not in err
    return lines[0]


@pytest.fixture
def full_disk(tmp_path):
    """A 512 KiB tmpfs (root only), unmounted afterwards."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root")
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=512k", "tmpfs", str(mount)],
                          capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def _fill(folder: Path) -> None:
    """Take every free byte of ``folder``'s file system."""
    with open(folder / "filler", "wb", buffering=0) as fh:
        try:
            while True:
                fh.write(b"\0" * 4096)
        except OSError as exc:
            assert exc.errno == errno.ENOSPC


def test_full_disk_keeps_the_old_reference(full_disk, tmp_path):
    """A reference resumed onto a full disk: the write of the grown reference fails. Compared:
    the exit status (2), stderr (one line naming ref.exr and the full disk, not the temporary
    file), the old file's bytes (unchanged) and the folder (no temporary left). This failed when
    OpenImageIO's errors went unchecked (a torn file renamed over the good one, exit 0)."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    ref = full_disk / "ref.exr"
    command = [sys.executable, "-m", "tracer", "reference", str(scene), "-o", str(ref), "--quiet",
               "--width", "64", "--height", "48"]
    first = subprocess.run(command + ["--spp", "2"], capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    before = ref.read_bytes(), ref.with_suffix(".png").read_bytes()
    _fill(full_disk)
    again = subprocess.run(command + ["--spp", "2", "--resume"], capture_output=True, text=True,
                           timeout=600)
    assert again.returncode == 2, again.stderr
    line = _one_error_line(again.stderr)
    assert str(ref) in line and "no space left" in line and "/." not in line, line
    assert (ref.read_bytes(), ref.with_suffix(".png").read_bytes()) == before
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler", "ref.exr", "ref.png"]


@pytest.mark.parametrize("target", ["exr", "png", "metrics"])
def test_injected_write_failure_keeps_old_files(target, tmp_path, monkeypatch, capsys):
    """The flush of one output fails with ENOSPC (injected). Compared: exit 2, one line naming
    that output, the old content of every file that was not written, and no temporary left.
    For the PNG, the line also says that the EXR was written (it holds the render)."""
    scene = tmp_path / "s.toml"
    scene.write_text(GOOD)
    out = tmp_path / "r.exr"
    assert main(["render", str(scene), "-o", str(out), "--spp", "1", "--quiet"]) == 0
    old = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    real_sync = atomic._sync

    def failing_sync(path, directory=False):
        if not directory and str(path).endswith({"exr": ".exr", "png": ".png", "metrics": ".txt"}[target]):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_sync(path, directory)

    monkeypatch.setattr(atomic, "_sync", failing_sync)
    if target == "metrics":
        with pytest.raises(InputError) as info:
            atomic.write_text(tmp_path / "notes.txt", "numbers")
        assert str(info.value).startswith(str(tmp_path / "notes.txt")) and "No space left" in str(info.value)
        assert not (tmp_path / "notes.txt").exists()
    else:
        assert main(["render", str(scene), "-o", str(out), "--spp", "2", "--seed", "5", "--quiet",
                     "--force"]) == 2
        line = _one_error_line(capsys.readouterr().err)
        failed = out.with_suffix(f".{target}")
        assert line.startswith(f"tracer: error: {failed}: cannot write: ") and "No space left" in line, line
        if target == "png":
            assert f"({out} was written)" in line
            assert out.read_bytes() != old["r.exr"]  # the new render is kept
            assert out.with_suffix(".png").read_bytes() == old["r.png"]
        else:
            assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == old
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_stale_temporaries_are_removed_by_the_next_write(tmp_path):
    """A temporary left by a killed writer (.r.tracer-tmp-XXXXXXXX.exr beside the target, older
    than an hour) is removed by the next write to that target; a fresh one (a write under way)
    and a user's own hidden files of the same length (.r.original.exr, which the first version
    of this cleanup deleted) are kept."""
    target = tmp_path / "r.exr"
    stale, fresh = tmp_path / ".r.tracer-tmp-abcd1234.exr", tmp_path / ".r.tracer-tmp-efgh5678.exr"
    others = [tmp_path / ".r.original.exr", tmp_path / ".r.20241130.exr", tmp_path / ".r.backup_1.exr"]
    for path in (stale, fresh, *others):
        path.write_bytes(b"torn")
    old = time.time() - 2 * atomic.STALE_SECONDS
    for path in (stale, *others):
        os.utime(path, (old, old))
    atomic.write_text(target, "x")
    assert not stale.exists() and fresh.exists() and all(p.exists() for p in others)
    assert target.read_text() == "x"


@pytest.mark.parametrize("failing", ["metrics.json", "index.html", "mis.exr"])
def test_a_failed_report_leaves_the_old_one_whole(failing, tmp_path, monkeypatch, capsys):
    """Issue 38.5: a full disk while `compare` writes its report (injected: the flush of one of
    its files fails with ENOSPC) left new EXRs and PNGs beside the old index.html, metrics.json
    and viewer_data.js. The report is now written into a stage and moved in whole: compared are
    the exit status (2), the one error line (naming the report's file, not the stage's) and
    every file of the folder (byte for byte the first report's, no stage left)."""
    scene = str(Path(__file__).resolve().parent.parent / "tracer" / "scenes" / "cornell.toml")
    ref, out = tmp_path / "ref.exr", tmp_path / "cmp"
    # 256 spp: far less noise than the 2-spp renders', so compare warns of nothing.
    assert main(["reference", scene, "-o", str(ref), "--width", "8", "--height", "8", "--spp", "256",
                 "--quiet"]) == 0
    command = ["compare", scene, "--reference", str(ref), "--spp", "2", "--out", str(out), "--quiet",
               "--strategies", "light,mis"]
    assert main(command) == 0
    old = {p.name: p.read_bytes() for p in out.iterdir()}
    assert failing in old
    real_sync = atomic._sync

    def failing_sync(path, directory=False):
        if not directory and Path(path).name.startswith(f".{Path(failing).stem}.") \
                and str(path).endswith(Path(failing).suffix):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_sync(path, directory)

    monkeypatch.setattr(atomic, "_sync", failing_sync)
    capsys.readouterr()
    assert main(command + ["--seed", "9"]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert line.startswith(f"tracer: error: {out / failing}: cannot write: ") and "No space left" in line, line
    assert "nothing in the folder was changed" in line and atomic.STAGE_TAG not in line, line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == old


def test_a_report_without_a_viewer_removes_the_old_viewer_data(tmp_path):
    """A report whose viewer is left out (too big) moved in over one that had it takes the old
    viewer data away with it, so that the page and the data never disagree."""
    folder = tmp_path / "cmp"
    folder.mkdir()
    (folder / "viewer_data.js").write_text("old")
    (folder / "index.html").write_text("old")
    with atomic.staged_folder(folder) as stage:
        atomic.write_text(stage.path / "index.html", "new")
        stage.remove("viewer_data.js")
    assert sorted(p.name for p in folder.iterdir()) == ["index.html"]
    assert (folder / "index.html").read_text() == "new"
