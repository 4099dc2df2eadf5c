"""The process supervisor of ``skyfix serve``: N workers on one socket, restarted when they die.

The parent binds the socket, then starts ``workers`` processes (``spawn``), each a
``DrainingServer`` on that socket. It does no request work itself. Every 0.2 s it checks its
workers: one that died (a crash, the OOM killer, SIGKILL) is replaced at once; the counts it
served stay in the Prometheus totals. A worker that dies before it ever became ready three
times in a row stops the server (the app cannot start: no restart loop).

Signals to the parent:

- ``SIGTERM`` / ``SIGINT``: every worker drains (streams answer what they have read and close
  with 1001; REST in flight completes), then the parent exits.
- ``SIGHUP``: rolling restart, one worker at a time: start a new worker, wait until it serves,
  then drain the old one. New workers open the database path again, so after ``skyfix db
  build --out PATH`` (which swaps the PATH symlink atomically) ``SIGHUP`` moves every worker
  to the new database with no request refused. Workers never re-open a database by themselves.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import shutil
import signal
import socket
import tempfile
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import uvicorn

log = logging.getLogger("skyfix.supervisor")
_spawn = multiprocessing.get_context("spawn")
READY_TIMEOUT_S = 180.0
MAX_START_FAILURES = 3


def _worker_main(config: uvicorn.Config, sockets: list[socket.socket], ready: Connection,
                 drain_timeout_s: float, access_log_level: str) -> None:
    """A worker process: serve on ``sockets``; say so on ``ready`` once started."""
    from ..api import logs
    from ..api.lifecycle import DrainingServer

    config.configure_logging()
    logs.configure(access_log_level)
    server = DrainingServer(config, drain_timeout_s=drain_timeout_s)
    parent = os.getppid()

    def watch() -> None:
        while not server.started and not server.should_exit:
            time.sleep(0.05)
        try:
            ready.send(server.started)
        except OSError:
            pass
        while True:  # the supervisor was killed: drain and stop rather than serve unsupervised
            time.sleep(1.0)
            if os.getppid() != parent:
                os.kill(os.getpid(), signal.SIGTERM)
                return

    threading.Thread(target=watch, daemon=True).start()
    server.run(sockets=sockets)


@dataclass
class Worker:
    """One worker process and the pipe on which it says it is ready."""

    process: Any
    ready_conn: Connection
    ready: bool = False

    @property
    def pid(self) -> int | None:
        return self.process.pid  # type: ignore[no-any-return]

    def poll_ready(self, timeout: float = 0.0) -> bool:
        if not self.ready and self.ready_conn.poll(timeout):
            try:
                self.ready = bool(self.ready_conn.recv())
            except (EOFError, OSError):
                pass
        return self.ready


class Supervisor:
    """Run ``workers`` copies of the app on ``config``'s socket until SIGTERM/SIGINT."""

    def __init__(self, config: uvicorn.Config, workers: int, *, drain_timeout_s: float,
                 access_log_level: str = "info") -> None:
        self.config = config
        self.n = workers
        self.drain_timeout_s = drain_timeout_s
        self.access_log_level = access_log_level
        self.workers: list[Worker] = []
        self.signals: list[int] = []
        self.should_exit = False
        self.start_failures = 0
        self.restarts = 0
        self.sockets: list[socket.socket] = []

    def _spawn(self) -> Worker:
        parent_conn, child_conn = _spawn.Pipe(duplex=False)
        proc = _spawn.Process(target=_worker_main, args=(self.config, self.sockets, child_conn,
                                                         self.drain_timeout_s, self.access_log_level),
                              name="skyfix-worker")
        proc.start()
        child_conn.close()
        log.info("started worker %s", proc.pid)
        return Worker(proc, parent_conn)

    def run(self) -> int:
        """Serve; returns the exit status (0 after a clean stop)."""
        own_dir = not os.environ.get("PROMETHEUS_MULTIPROC_DIR")
        metrics_dir = tempfile.mkdtemp(prefix="skyfix-metrics-") if own_dir else \
            os.environ["PROMETHEUS_MULTIPROC_DIR"]
        os.environ["PROMETHEUS_MULTIPROC_DIR"] = metrics_dir  # inherited by the spawned workers
        # spawn re-imports ``python -m service.cli.serve`` in each worker, and runpy warns about it
        os.environ["PYTHONWARNINGS"] = ",".join(filter(None, (os.environ.get("PYTHONWARNINGS"),
                                                              "ignore::RuntimeWarning:runpy")))
        handled = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
        previous = {sig: signal.signal(sig, lambda s, _f: self.signals.append(s)) for sig in handled}
        self.sockets = [self.config.bind_socket()]
        try:
            self.workers = [self._spawn() for _ in range(self.n)]
            while not self.should_exit:
                time.sleep(0.2)
                self._handle_signals()
                self._replace_dead()
            return 1 if self.start_failures >= MAX_START_FAILURES else 0
        finally:
            self._stop_all()
            for sock in self.sockets:
                sock.close()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            if own_dir:
                shutil.rmtree(metrics_dir, ignore_errors=True)

    def _handle_signals(self) -> None:
        while self.signals:
            sig = self.signals.pop(0)
            if sig == signal.SIGHUP:
                log.info("SIGHUP: rolling restart of %d workers", len(self.workers))
                self.rolling_restart()
            else:
                self.should_exit = True

    def _replace_dead(self) -> None:
        for i, w in enumerate(self.workers):
            w.poll_ready()
            if w.process.is_alive() or self.should_exit:
                continue
            w.process.join()
            _forget(w.pid)
            if not w.ready:
                self.start_failures += 1
                if self.start_failures >= MAX_START_FAILURES:
                    log.error("workers fail to start (exit code %s); stopping", w.process.exitcode)
                    self.should_exit = True
                    return
            else:
                self.start_failures = 0
            log.warning("worker %s died (exit code %s); restarting it", w.pid, w.process.exitcode)
            self.restarts += 1
            self.workers[i] = self._spawn()

    def rolling_restart(self) -> None:
        """Replace each worker: start the new one, wait until it serves, then drain the old one."""
        for i, old in enumerate(list(self.workers)):
            new = self._spawn()
            deadline = time.monotonic() + READY_TIMEOUT_S
            while not new.poll_ready(0.1):
                self._take_exit_signals()
                if self.should_exit or not new.process.is_alive() or time.monotonic() > deadline:
                    log.error("new worker %s did not start; keeping the old ones", new.pid)
                    _stop([new], 5.0)
                    return
            self.workers[i] = new
            _stop([old], self.drain_timeout_s + (self.config.timeout_graceful_shutdown or 10) + 5)

    def _take_exit_signals(self) -> None:
        if any(s != signal.SIGHUP for s in self.signals):
            self.should_exit = True

    def _stop_all(self) -> None:
        _stop(self.workers, self.drain_timeout_s + (self.config.timeout_graceful_shutdown or 10) + 5)


def _stop(workers: list[Worker], timeout_s: float) -> None:
    """SIGTERM (drain) each live worker, wait up to ``timeout_s``, then SIGKILL what is left."""
    for w in workers:
        if w.process.is_alive():
            try:
                os.kill(w.pid, signal.SIGTERM)
            except ProcessLookupError:  # it died just now
                pass
    deadline = time.monotonic() + timeout_s
    for w in workers:
        w.process.join(max(0.0, deadline - time.monotonic()))
        if w.process.is_alive():
            w.process.kill()
            w.process.join()
        _forget(w.pid)
        w.ready_conn.close()


def _forget(pid: int | None) -> None:
    """Drop a dead worker's live gauges (its counters stay in the totals)."""
    if pid is None or not os.environ.get("PROMETHEUS_MULTIPROC_DIR"):
        return
    from prometheus_client import multiprocess

    multiprocess.mark_process_dead(pid)
