"""Run a native library on bytes nobody has checked, in a child process that may die.

Python code fails with an exception; a C library handed a crafted buffer may read out of
bounds, divide by zero or loop (fpzip crashed the process on 43 of 75 damaged bodies). Codecs
that hand untrusted bytes to such a library (:attr:`Codec.native_decoder`) decode them through
:func:`call_isolated`: a forked child with an address-space limit and a timeout, whose crash,
exhaustion or hang becomes a :class:`~mocodec.errors.CorruptStreamError` here.
"""

from __future__ import annotations

import faulthandler
import multiprocessing
import os
import resource
import signal
from typing import Any

from mocodec.errors import CodecError, CorruptStreamError

#: Memory a child may allocate beyond what it inherits, and how long it may run.
CHILD_MEMORY_BYTES = 2 << 30
CHILD_TIMEOUT_S = 60.0


class NativeCrash(CorruptStreamError):
    """The child died (a signal or an exit code) before it answered: ``how``."""

    def __init__(self, message: str, how: str):
        super().__init__(message)
        self.how = how


def _mapped_bytes() -> int:
    """This process's virtual size (what RLIMIT_AS counts)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def _child(conn, func, args, memory_bytes: int) -> None:
    faulthandler.disable()  # a crash here is expected and reported by the parent
    limit = _mapped_bytes() + memory_bytes
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        result = ("ok", func(*args))
    except MemoryError:
        result = ("error", f"it asks for more than the child's {memory_bytes:,}-byte memory limit")
    except BaseException as e:  # noqa: BLE001 - every failure goes back to the parent as text
        result = ("codec" if isinstance(e, CodecError) else "error", f"{type(e).__name__}: {e}")
    try:
        conn.send(result)
    except MemoryError:
        conn.send(("error", "MemoryError: the result does not fit the child's memory limit"))
    conn.close()


def _exit_reason(code: int | None) -> str:
    if code is None or code >= 0:
        return f"exit {code}"
    try:
        return f"signal {signal.Signals(-code).name}"
    except ValueError:
        return f"signal {-code}"


def process_context() -> Any:
    """The multiprocessing context for children: fork where the platform has it (a child starts
    at once, with this process's imports and compiled kernels), else spawn."""
    return multiprocessing.get_context("fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn")


def call_isolated(func, *args, what: str, memory_bytes: int = CHILD_MEMORY_BYTES, timeout_s: float = CHILD_TIMEOUT_S):
    """``func(*args)`` in a child process; its result, or CorruptStreamError naming ``what``
    and how the child failed (a CodecError it raised is raised as such)."""
    ctx = process_context()
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, func, args, memory_bytes), daemon=True)
    proc.start()
    send.close()
    try:
        if not receive.poll(timeout_s):
            proc.kill()
            raise CorruptStreamError(f"{what}: the decoder ran for over {timeout_s:g} s")
        try:
            status, value = receive.recv()
        except (EOFError, OSError):
            proc.join(5.0)
            code = proc.exitcode
            how = _exit_reason(code)
            raise NativeCrash(f"{what}: the native decoder crashed ({how}): the data is damaged", how) from None
    finally:
        receive.close()
        proc.join(5.0)
        if proc.is_alive():
            proc.kill()
    if status == "ok":
        return value
    if status == "codec":
        raise CodecError(value)
    raise CorruptStreamError(f"{what}: does not decode ({value})")
