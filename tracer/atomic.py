"""Atomic file writes: a temporary file in the target's folder, then a rename.

Every file tracer writes (EXR, PNG, JSON, CSV, HTML, charts) goes through here, so an
interrupted run never leaves a torn file: readers see the old file or the new one. A set of
files that only make sense together (a comparison report: its page, tables and images) is
written into a stage folder first and moved in only when every file is written
(:func:`staged_folder`), so a full disk leaves the old set, not a mixture.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from .errors import InputError


def atomic_write(path: str | os.PathLike[str], write: Callable[[str], None]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path`` (same extension, so image and
    chart libraries pick the right format), then rename it over ``path``."""
    atomic_write_many([(path, write)])


def atomic_write_many(files: list[tuple[str | os.PathLike[str], Callable[[str], None]]]) -> None:
    """Write several files atomically, as :func:`atomic_write` writes one, at the cost of one:
    every ``write(tmp)`` first, then each file synced and renamed into place, then each folder
    synced and tidied once. (File by file, ``tracer convert`` of 5,000 shapes took 150 s: each
    file synced the folder and listed it for stale temporaries, which grew with every file.)
    If a write fails, no file is renamed and every temporary file is removed."""
    targets = [Path(path) for path, _ in files]
    temporaries: list[str] = []
    try:
        for target, (_, write) in zip(targets, files):
            tmp = _temporary_beside(target)
            temporaries.append(tmp)
            try:
                write(tmp)
            except (OSError, InputError) as exc:
                raise InputError(_write_failure(exc, tmp, _folder(target)), str(target)) from None
        # mkstemp makes files private (0600); give them the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        for target, tmp in zip(targets, temporaries):
            try:
                _sync(tmp)  # the bytes reach the disk before the name does: no empty file after a crash
                os.chmod(tmp, 0o666 & ~umask)
            except OSError as exc:
                raise InputError(_write_failure(exc, tmp, _folder(target)), str(target)) from None
        for index, (target, tmp) in enumerate(zip(targets, temporaries)):
            try:
                os.replace(tmp, target)
            except OSError as exc:
                raise InputError(_write_failure(exc, tmp, _folder(target)), str(target)) from None
            temporaries[index] = ""  # renamed: nothing left to remove
    except BaseException:
        # A full disk, a failing device, a refused rename or an interrupt: the temporaries go.
        for tmp in temporaries:
            if tmp and os.path.exists(tmp):
                os.unlink(tmp)
        raise
    folders = {_folder(target) for target in targets}
    for folder in folders:
        _sync(folder, directory=True)
        _remove_stale_temporaries(folder, [t for t in targets if _folder(t) == folder])


def _folder(target: Path) -> Path:
    return target.parent if str(target.parent) else Path(".")


def _temporary_beside(target: Path) -> str:
    """A new empty temporary file in ``target``'s folder, named after it (module constants)."""
    folder = _folder(target)
    if not folder.is_dir():
        raise InputError("output folder does not exist", str(folder))
    if target.is_dir():
        raise InputError("is a folder, not a file that can be written", str(target))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.{TEMPORARY_TAG}", suffix=target.suffix, dir=folder)
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", str(target)) from None
    os.close(fd)
    return tmp


def _write_failure(exc: BaseException, tmp: str, folder: Path) -> str:
    """The one-line reason a write failed, without the temporary file's name, saying when the
    disk is full (OpenImageIO reports no errno, so the free space is looked at)."""
    if isinstance(exc, OSError):
        reason = exc.strerror or str(exc)
    else:
        reason = str(exc).replace(f"{tmp}: ", "").removeprefix("cannot write: ")
    reason = reason.replace(f'"{tmp}"', "the temporary file").replace(tmp, "the temporary file")
    try:
        free = os.statvfs(folder)
        if free.f_bavail * free.f_frsize < 1 << 20:
            reason = f"no space left on the device ({free.f_bavail * free.f_frsize} bytes free); {reason}"
    except OSError:
        pass
    return f"cannot write: {reason}{UNCHANGED}"


UNCHANGED = "; the existing file, if any, is unchanged"


# A temporary file left by a process that was killed (SIGKILL cannot be caught) while writing:
# ``.STEM.tracer-tmp-XXXXXXXX.SUFFIX`` (mkstemp's eight characters), untouched for longer than
# any write takes. The tag keeps a user's own hidden files (``.ref.backup_1.exr``) out of it.
TEMPORARY_TAG = "tracer-tmp-"
STALE_SECONDS = 3600.0


def _remove_stale_temporaries(folder: Path, targets: list[Path]) -> None:
    """Delete ``.STEM.tracer-tmp-XXXXXXXX.SUFFIX`` files of any of ``targets`` (all in
    ``folder``) older than STALE_SECONDS: one listing of the folder for all of them."""
    patterns = [re.compile(re.escape(f".{stem}.{TEMPORARY_TAG}") + r"[a-z0-9_]{8}" + re.escape(suffix))
                for stem, suffix in {(t.stem, t.suffix) for t in targets}]
    try:
        # Few names hold the tag (none, unless a process was killed while writing): the patterns
        # are tried on those only.
        candidates = [folder / name for name in os.listdir(folder) if TEMPORARY_TAG in name
                      and any(pattern.fullmatch(name) for pattern in patterns)]
        now = time.time()
        for path in candidates:
            if now - path.stat().st_mtime > STALE_SECONDS:
                path.unlink()
    except OSError:
        pass  # tidying up is a courtesy; the write itself has succeeded


def _sync(path: str | Path, directory: bool = False) -> None:
    """fsync a file (or a folder, so that a rename in it is durable); errors on a folder are
    ignored (some file systems refuse to sync one), errors on a file propagate."""
    try:
        fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    except OSError:
        if directory:
            return
        raise
    try:
        os.fsync(fd)
    except OSError:
        if not directory:
            raise
    finally:
        os.close(fd)


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write a text file atomically, in UTF-8 whatever the locale (pages and scripts hold
    characters such as † and ←, which a locale's encoding may not)."""
    atomic_write(path, text_writer(text))


def text_writer(text: str) -> Callable[[str], None]:
    """A ``write(tmp)`` for :func:`atomic_write_many` that writes ``text`` in UTF-8."""

    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)

    return write


def bytes_writer(data: bytes) -> Callable[[str], None]:
    """A ``write(tmp)`` for :func:`atomic_write_many` that writes ``data``."""

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(data)

    return write


def save_figure(fig, path: str | os.PathLike[str], dpi: int = 100) -> None:
    """Save a matplotlib figure atomically."""
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi))


class Stage:
    """The folder a :func:`staged_folder` block writes into (``path``), and the names of files
    of the target folder that the new set no longer has and that go when it is moved in."""

    def __init__(self, path: Path):
        self.path = path
        self.obsolete: set[str] = set()
        # The file moved in last: a set's entry point (a report's page), which names the others.
        self.entry: str | None = None

    def remove(self, name: str) -> None:
        """Remove the file ``name`` from the target folder when the stage is moved in."""
        self.obsolete.add(name)


STAGE_TAG = f".{TEMPORARY_TAG}stage-"


@contextlib.contextmanager
def staged_folder(folder: str | os.PathLike[str]) -> Iterator[Stage]:
    """Write a set of files into ``folder`` all at once: the block writes them into a hidden
    stage folder inside ``folder`` (``Stage.path``); when it ends normally, each file is moved
    over its namesake in ``folder`` (renames within one folder: no space needed, nothing torn)
    and the files the block named with ``Stage.remove`` are deleted. If the block fails (a full
    disk, an interrupt), the stage is deleted and ``folder`` is as it was; an InputError then
    names ``folder``'s file rather than the stage's. Stages left by a killed process are
    deleted once older than STALE_SECONDS."""
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    _remove_stale_stages(target)
    try:
        stage = Stage(Path(tempfile.mkdtemp(prefix=STAGE_TAG, dir=target)))
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", str(target)) from None
    try:
        try:
            yield stage
        except InputError as exc:
            message = str(exc).replace(str(stage.path), str(target)).replace(UNCHANGED, "")
            raise InputError(f"{message}; nothing in the folder was changed") from None
        names = sorted(os.listdir(stage.path), key=lambda name: (name == stage.entry, name))
        for name in names:
            if (stage.path / name).is_dir():
                raise InputError("a stage holds files only, not folders", str(stage.path / name))
        for name in names:
            try:
                os.replace(stage.path / name, target / name)
            except OSError as exc:
                raise InputError(f"cannot move the new file in: {exc.strerror or exc}", str(target / name)) from None
        for name in sorted(stage.obsolete - set(names)):
            with contextlib.suppress(FileNotFoundError):
                (target / name).unlink()
        _sync(target, directory=True)
    finally:
        shutil.rmtree(stage.path, ignore_errors=True)


def _remove_stale_stages(folder: Path) -> None:
    """Delete stage folders in ``folder`` untouched for longer than STALE_SECONDS (a process
    killed while writing a report leaves one)."""
    try:
        now = time.time()
        for entry in os.scandir(folder):
            if entry.name.startswith(STAGE_TAG) and entry.is_dir(follow_symlinks=False) \
                    and now - entry.stat(follow_symlinks=False).st_mtime > STALE_SECONDS:
                shutil.rmtree(entry.path, ignore_errors=True)
    except OSError:
        pass  # tidying up is a courtesy
