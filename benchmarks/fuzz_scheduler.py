"""The fuzzer's scheduler-address family (``benchmarks/fuzz.py`` holds the runner).

``tracer reference --scheduler ADDRESS`` must answer every address that is not a Dask scheduler
with one line and exit 2, within its connect timeout: malformed addresses, other schemes, and
servers that speak something else. The servers run in the fuzzer's own process (threads on
loopback, started once per run by :class:`Servers`), each misbehaving in one way:

- ``http``: answers any request with an HTTP 400 page (Dask read its first 8 bytes as a frame
  length and tried to allocate 3 EiB);
- ``silent``: accepts and never sends a byte (it blocked past 100 s);
- ``close``: accepts and closes at once;
- ``noise``: sends random bytes;
- ``huge frame``: sends a frame length of 2^40 and nothing after it;
- ``trickle``: sends one byte a second.
"""

from __future__ import annotations

import random
import socket
import struct
import threading
import time

SERVER_KINDS = ("http", "silent", "close", "noise", "huge frame", "trickle")

MALFORMED = ("", "tcp://", "://", "tcp://127.0.0.1", "tcp://127.0.0.1:0", "tcp://127.0.0.1:65536",
             "tcp://127.0.0.1:-1", "tcp://[::1", "tcp://" + "h" * 70000 + ":8786", "tcp://a\nb:8786",
             "tcp://\x1b[31m:8786", "tcp://ünïcode.invalid:8786", "ucx://127.0.0.1:8786",
             "inproc://127.0.0.1/1/1", "http://127.0.0.1:8786", "TCP://127.0.0.1:1", "gopher://x:1",
             "tls://127.0.0.1:1", "tcp://no-such-host.invalid:8786", "127.0.0.1:1")


class Servers:
    """Misbehaving TCP servers on loopback, one per kind, until :meth:`close`."""

    def __init__(self) -> None:
        self._sockets: list[socket.socket] = []
        self._stop = threading.Event()
        self.ports: dict[str, int] = {}
        for kind in SERVER_KINDS:
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listener.bind(("127.0.0.1", 0))
            listener.listen(16)
            listener.settimeout(0.2)
            self._sockets.append(listener)
            self.ports[kind] = listener.getsockname()[1]
            threading.Thread(target=self._accept, args=(listener, kind), daemon=True).start()

    def _accept(self, listener: socket.socket, kind: str) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = listener.accept()
            except (TimeoutError, OSError):
                continue
            threading.Thread(target=self._serve, args=(conn, kind), daemon=True).start()

    def _serve(self, conn: socket.socket, kind: str) -> None:
        try:
            with conn:
                if kind == "http":
                    conn.recv(4096)
                    conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 11\r\n\r\nbad request")
                elif kind == "close":
                    return
                elif kind == "noise":
                    conn.sendall(random.Random(1).randbytes(4096))
                elif kind == "huge frame":
                    conn.sendall(struct.pack("<Q", 2**40))
                if kind in ("silent", "huge frame", "trickle", "noise", "http"):
                    # Hold the connection open (a byte a second for trickle) until the client goes.
                    conn.settimeout(1.0)
                    while not self._stop.is_set():
                        if kind == "trickle":
                            conn.sendall(b"\x01")
                        try:
                            if conn.recv(4096) == b"":
                                return
                        except TimeoutError:
                            continue
        except OSError:
            return

    def address(self, kind: str) -> str:
        return f"tcp://127.0.0.1:{self.ports[kind]}"

    def close(self) -> None:
        self._stop.set()
        time.sleep(0.3)
        for listener in self._sockets:
            listener.close()


def choose(rng: random.Random, servers: Servers | None) -> tuple[str, str]:
    """(address, description) of one case: a server's address or a malformed one."""
    if servers is not None and rng.random() < 0.6:
        kind = rng.choice(SERVER_KINDS)
        scheme = rng.choice(("tcp", "tcp", "tls", "ws"))
        return servers.address(kind).replace("tcp://", f"{scheme}://"), f"{scheme} server that is {kind}"
    address = rng.choice(MALFORMED)
    return address, f"address {address[:40]!r}" + (f" ({len(address)} characters)" if len(address) > 40 else "")
