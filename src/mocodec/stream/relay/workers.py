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
import shutil
import signal
import socket
import subprocess
import threading
from collections.abc import Callable, Iterator

from mocodec.errors import MocodecError
from mocodec.stream.relay.limits import TICK_HZ, Limits

NATS_PATHS = "/usr/sbin:/usr/bin:/usr/local/bin"


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
    from mocodec.stream.bus import NatsBus
    from mocodec.stream.relay.server import run

    run(host, port, secret, limits, NatsBus(bus_url), tick_hz, reuse_port=True, listening=lambda: ready.put(True))


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
            for _ in procs:
                ready.get()
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
