"""Reading a user's input file whole: a regular file of bounded size, or one clear line.

A scene, a baseline or any file tracer reads into memory at once goes through
:func:`read_regular_file`. Opening a FIFO blocks until something writes to it (``tracer check``
waited forever on a baseline entry whose scene was one), and a device such as ``/dev/zero``
never ends (it read until memory ran out): both are refused before a byte is read, by
``fstat`` on a descriptor opened without blocking, as is a file larger than the caller's limit.
"""

from __future__ import annotations

import os
import stat

from .errors import InputError


def read_regular_file(path: str | os.PathLike[str], limit: int, what: str, missing: str | None = None,
                      label: str | None = None) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them. ``what`` names the
    kind of file in messages (``scene file``); ``missing`` is the message for a file that does
    not exist (default ``no such WHAT``). Raises InputError naming ``label`` (default: the
    path)."""
    path = os.fspath(path)
    name = label or path
    try:
        # O_NONBLOCK: opening a FIFO without a writer returns at once instead of waiting.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise InputError(missing or f"no such {what}", name) from None
    except IsADirectoryError:
        raise InputError(f"is a directory, not a {what}", name) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", name) from None
    with os.fdopen(fd, "rb") as fh:
        try:
            info = os.fstat(fd)
            if stat.S_ISDIR(info.st_mode):
                raise InputError(f"is a directory, not a {what}", name)
            if not stat.S_ISREG(info.st_mode):
                raise InputError(f"is not a regular file (a FIFO, socket or device), not a {what}", name)
            if info.st_size > limit:
                raise InputError(f"larger than {_size(limit)}: not a {what}", name)
            os.set_blocking(fd, True)
            data = _read_at_most(fh, limit + 1)
        except OSError as exc:
            raise InputError(f"cannot read: {exc.strerror or exc}", name) from None
    if len(data) > limit:  # it grew while being read
        raise InputError(f"larger than {_size(limit)}: not a {what}", name)
    return data


def _read_at_most(fh, limit: int) -> bytes:
    """The first ``limit`` bytes of ``fh``, read a megabyte at a time: ``fh.read(limit)`` would
    take ``limit`` bytes of memory for any file, however small."""
    chunks, size = [], 0
    while size < limit and (chunk := fh.read(min(1 << 20, limit - size))):
        chunks.append(chunk)
        size += len(chunk)
    return b"".join(chunks)


def _size(limit: int) -> str:
    return f"{limit >> 20} MiB" if limit >= 1 << 20 and limit % (1 << 20) == 0 else f"{limit} bytes"
