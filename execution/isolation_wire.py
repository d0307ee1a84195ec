"""The messages between :mod:`.isolation` and its helper process (:mod:`.isolation_helper`):
length-prefixed pickles on raw pipes, and the words for how a process ended.

A message is an 8-byte little-endian length (:data:`HEADER`) and that many bytes of a pickle;
:func:`send` writes one whole, :func:`recv` reads one (None once the other side is gone), with
an optional deadline.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import signal
import struct
import time
from typing import Any

__all__ = ["HEADER", "exit_text", "recv", "send"]

#: the length prefix of a message
HEADER = struct.Struct("<Q")


def send(fd: int, message: Any) -> None:
    """Write ``message`` as one length-prefixed pickle."""
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(HEADER.pack(len(data)) + data)
    while view:
        view = view[os.write(fd, view) :]


def _read_exactly(fd: int, n: int, deadline: float | None) -> bytes | None:
    """``n`` bytes; None at end of file; TimeoutError once ``deadline`` (monotonic) passes."""
    chunks: list[bytes] = []
    got = 0
    while got < n:
        wait = None if deadline is None else deadline - time.monotonic()
        if wait is not None and wait <= 0:
            raise TimeoutError
        ready, _, _ = select.select([fd], [], [], wait)
        if not ready:
            raise TimeoutError
        chunk = os.read(fd, min(n - got, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def recv(fd: int, deadline: float | None = None) -> Any:
    """One message; None at end of file (the other side is gone)."""
    header = _read_exactly(fd, HEADER.size, deadline)
    if header is None:
        return None
    data = _read_exactly(fd, HEADER.unpack(header)[0], deadline)
    return None if data is None else pickle.loads(data)


def exit_text(status: int) -> str:
    """``exit status 3`` or ``killed by SIGSEGV`` from a ``waitpid`` status."""
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        with contextlib.suppress(ValueError):
            return f"killed by {signal.Signals(sig).name}"
        return f"killed by signal {sig}"
    return f"exit status {os.waitstatus_to_exitcode(status)}"
