"""Every core of one machine: ``mocodec serve --workers N`` runs N relay processes behind one
port (the kernel spreads connections over them with SO_REUSEPORT) that share their rooms
through NATS, as relays on several machines do (:mod:`mocodec.stream.bus`). Without a bus
given, it starts a NATS server of its own on a free loopback port (``nats-server``, Debian's
package of that name) and stops it when it stops. A viewer on any worker sees every avatar of
its room; each worker takes in every sender's packets (its own senders', and the others'
from the bus) and serves its own viewers."""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import queue
import shutil
import signal
import socket
import subprocess
import threading
from collections.abc import Callable, Iterator

from mocodec.errors import MocodecError
from mocodec.stream.relay.limits import TICK_HZ, Limits

NATS_PATHS = "/usr/sbin:/usr/bin:/usr/local/bin"
WORKER_POLL_S = 0.5  # how often serve looks for a worker that died before it listened


@contextlib.contextmanager
def nats_server() -> Iterator[str]:
    """A NATS server on a free loopback port for as long as the block runs: its address."""
    binary = shutil.which("nats-server") or shutil.which("nats-server", path=NATS_PATHS)
    if binary is None:
        raise MocodecError("--workers needs a NATS server: install nats-server, or give one with --bus")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([binary, "-a", "127.0.0.1", "-p", str(port)], stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr is not None
        for line in proc.stderr:  # its log says when it is ready
            if "Server is ready" in line:
                break
        else:
            raise MocodecError(f"nats-server did not start (exit code {proc.wait()})")
        threading.Thread(target=proc.stderr.read, daemon=True).start()  # the rest of its log, unread
        yield f"nats://127.0.0.1:{port}"
    finally:
        proc.terminate()
        proc.wait(10)


def _worker(host: str, port: int, secret: str, limits: Limits, bus_url: str, tick_hz: float, ready) -> None:
    """One relay; it puts None on ``ready`` once it listens, or the one line of what stopped it
    before (a port in use, a NATS server out of reach)."""
    from mocodec.stream.bus import NatsBus
    from mocodec.stream.relay.server import run

    listening = False

    def mark() -> None:
        nonlocal listening
        listening = True
        ready.put(None)

    try:
        run(host, port, secret, limits, NatsBus(bus_url), tick_hz, reuse_port=True, listening=mark)
    except (MocodecError, OSError) as e:
        if listening:
            raise
        ready.put(str(e))


def _await_workers(procs: list, ready) -> None:
    """Until every worker listens; MocodecError with the first one's failure, or with its exit
    code if one died without a word (the others are stopped by the caller)."""
    waiting = len(procs)
    while waiting:
        try:
            failure = ready.get(timeout=WORKER_POLL_S)
        except queue.Empty:
            dead = next((p for p in procs if p.exitcode is not None), None)
            if dead is not None:
                raise MocodecError(f"a relay worker stopped before it listened (exit code {dead.exitcode})") from None
            continue
        if failure is not None:
            raise MocodecError(failure)
        waiting -= 1


def _stop(signum, frame) -> None:
    raise SystemExit(0)


def serve_workers(
    host: str,
    port: int,
    secret: str,
    workers: int,
    limits: Limits,
    bus_url: str | None,
    tick_hz: float = TICK_HZ,
    listening: Callable[[], None] | None = None,
) -> None:
    """Run ``workers`` relays on ``host:port`` until interrupted, sharing rooms over the NATS
    server at ``bus_url`` (or one started here); ``listening`` is called once every worker
    takes connections."""
    if workers < 1:
        raise MocodecError(f"--workers must be at least 1, got {workers}")
    signal.signal(signal.SIGTERM, _stop)  # a terminated serve stops its workers and NATS server too
    with contextlib.ExitStack() as stack:
        url = bus_url or stack.enter_context(nats_server())
        context = mp.get_context("spawn")  # a fresh interpreter each: no state of this one shared
        ready = context.Queue()
        procs = [
            context.Process(target=_worker, args=(host, port, secret, limits, url, tick_hz, ready), daemon=True)
            for _ in range(workers)
        ]
        for proc in procs:
            proc.start()
        try:
            _await_workers(procs, ready)
            if listening is not None:
                listening()
            for proc in procs:
                proc.join()
        except (KeyboardInterrupt, SystemExit):
            pass
        finally:
            for proc in procs:
                proc.terminate()
            for proc in procs:
                proc.join(10)
