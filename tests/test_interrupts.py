"""Ctrl-C is never lost (``tracer.interrupts``): an interrupt whose ``KeyboardInterrupt`` a
finalizer drops still stops the render, which writes what it finished.

Python runs a signal's handler between two bytecodes of the main thread, wherever it is; when
that is inside a finalizer (``__del__``, a weakref callback, a generator closed by the garbage
collector), the handler's ``KeyboardInterrupt`` is printed as "Exception ignored" and dropped.
Once in 26 SIGINT trials of ``reference --resume`` the render went on until it was killed. The
tests below make that happen every time: a finalizer that sends SIGINT to its own process and
runs a few more bytecodes, so that the handler runs inside it.
"""

from __future__ import annotations

import os
import signal
import sys

import pytest

from tracer import interrupts, render_loop
from tracer import scene as scene_mod
from tracer.cli import main
from tracer.imagefiles import read_exr


class InterruptedFinalizer:
    """An object whose finalizer receives SIGINT: the handler runs inside ``__del__``, so the
    ``KeyboardInterrupt`` it raises is dropped by Python ("Exception ignored in ...")."""

    def __del__(self):
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):  # bytecodes, between which the handler runs: here, in the finalizer
            pass


def _finalize_interrupted() -> None:
    InterruptedFinalizer()  # dropped at once: its finalizer runs here


@pytest.fixture
def dropped(monkeypatch):
    """The KeyboardInterrupts that Python dropped ("Exception ignored"), in a list; SIGINT at
    Python's own handler, as in a shell, whatever the test runner set."""
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda report: seen.append(report.exc_type))
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield seen
    signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("threads", [1, 2])
def test_an_interrupt_dropped_by_a_finalizer_still_stops_the_render(tmp_path, monkeypatch, dropped,
                                                                    threads):
    """``tracer reference`` (in this process) with SIGINT landing in a finalizer while the render
    plans its third batch: Python drops the KeyboardInterrupt, but the handler recorded the
    signal and the render loop's next check stops the render: exit 130, and the EXR holds the
    finished batches, fewer than asked. Before the fix the render went on to the end (exit 0)."""
    planned = render_loop.plan_batches

    def plan_with_a_finalizer(*args, **kwargs):
        for index, batch in enumerate(planned(*args, **kwargs)):
            if index == 2:
                _finalize_interrupted()
            yield batch

    monkeypatch.setattr(render_loop, "plan_batches", plan_with_a_finalizer)
    out = tmp_path / "ref.exr"
    # 8x8 pixels take passes of 512 samples, one batch each: 64 batches.
    spp = 64 * 512
    code = main(["reference", str(scene_mod.default_scene_path()), "--width", "8", "--height", "8",
                 "--spp", str(spp), "--threads", str(threads), "--quiet", "--float", "-o", str(out)])
    assert KeyboardInterrupt in dropped, "the finalizer's interrupt was not dropped: the test tests nothing"
    assert code == 130
    film = read_exr(out)
    assert 0 < film.spp < spp
    assert not interrupts.pending()


def test_an_interrupt_dropped_after_the_last_check_ends_the_command_as_interrupted(tmp_path, monkeypatch,
                                                                                  dropped, capsys):
    """SIGINT dropped by a finalizer after the render's last batch (while the EXR is written):
    the render is whole and written, and the command still ends with the interrupted status and
    says so, instead of going on as if no signal had come."""
    from tracer import cli

    write = cli._write_outputs

    def write_then_finalize(*args, **kwargs):
        interrupted = write(*args, **kwargs)
        _finalize_interrupted()
        return interrupted

    monkeypatch.setattr(cli, "_write_outputs", write_then_finalize)
    out = tmp_path / "ref.exr"
    code = main(["reference", str(scene_mod.default_scene_path()), "--width", "8", "--height", "8",
                 "--spp", "16", "--threads", "1", "--float", "-o", str(out)])
    assert KeyboardInterrupt in dropped
    assert code == 130 and read_exr(out).spp == 16
    assert "interrupted (after the work was done and written)" in capsys.readouterr().err


def test_check_raises_while_a_signal_is_pending_and_watching_restores_the_handlers():
    """The handler records and raises; ``check`` raises again until ``clear``; leaving
    ``watching`` puts the previous handlers back and forgets what is pending."""
    before = signal.getsignal(signal.SIGINT)
    with interrupts.watching():
        interrupts.check()  # nothing pending
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
        assert interrupts.pending()
        with pytest.raises(KeyboardInterrupt):
            interrupts.check()
        interrupts.clear()
        interrupts.check()
        with interrupts.deferred() as arrived:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):
                pass
        assert arrived == [signal.SIGTERM] and not interrupts.pending()
        interrupts.leave_pending(arrived)
        assert interrupts.pending()
    assert signal.getsignal(signal.SIGINT) is before and not interrupts.pending()
