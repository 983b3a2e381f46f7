"""Shared test helpers: free loopback ports and fake-robot addresses, the ``urdaemon`` command run
in-process, waiting on a subprocess's log lines, a robot's command lease taken over raw Zenoh."""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import io
import json
import logging
import math
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Generator, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Generic, TextIO, TypeVar

T = TypeVar("T")

__all__ = [
    "UR_PORTS",
    "CliRun",
    "LeaseGrant",
    "Stepped",
    "acquire_lease",
    "client_lease",
    "drain_in_background",
    "fake_address",
    "free_tcp_port",
    "in_thread",
    "load_benchmark",
    "run_captured",
    "run_cli",
    "run_cli_in_thread",
    "run_script",
    "wait_for_line",
    "zenoh_ask",
]


_HANDED_OUT: set[int] = set()
"""Ports this test process was already given: the kernel may offer a released port again at once,
and two of a cell's callback ports must never be the same."""


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port on ``host`` that was free a moment ago and not handed out before in this process."""
    for _ in range(1000):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            sock.bind((host, 0))
            port: int = sock.getsockname()[1]
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port
    raise RuntimeError("no fresh free TCP port in 1000 attempts")


UR_PORTS = (29999, 30001, 30002, 30003, 30004)
"""The controller's fixed ports (dashboard, primary, secondary, real-time, RTDE) a fake robot listens on."""


def _addresses() -> Iterator[str]:
    """This process's fake-robot addresses: 127.a.b.1 to .254 of a /24 chosen at random (1 <= a, b <= 254,
    so never 127.0.0.x), then on through the next /24s. Chosen by the OS (not ``random``, which
    pytest-randomly seeds alike in every run), so two runs side by side almost never meet, and
    ``fake_address`` checks the ports anyway."""
    first = secrets.randbelow(254 * 254)
    for index in range(254 * 254):
        a, b = divmod((first + index) % (254 * 254), 254)
        for c in range(1, 255):
            yield f"127.{a + 1}.{b + 1}.{c}"


_ADDRESSES = _addresses()


def _ur_ports_free(address: str) -> bool:
    """Whether a fake robot could listen on all of UR's ports at ``address`` right now."""
    with contextlib.ExitStack() as stack:
        for port in UR_PORTS:
            sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            # As asyncio's servers do: a lingering TIME_WAIT does not block, a listener does.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((address, port))
            except OSError:
                return False
    return True


def fake_address() -> str:
    """A loopback address for one fake robot, never handed out before in this process.

    It lies in this run's own 127.a.b.0/24 (never 127.0.0.x) and UR's fixed ports (``UR_PORTS``)
    were free on it a moment ago: pass it as ``FakeController(address=...)`` and as the robot's
    ``address`` in the cell, so two runs of the suite on one machine never meet on a port.
    """
    for _, address in zip(range(10_000), _ADDRESSES, strict=False):
        if _ur_ports_free(address):
            return address
    raise RuntimeError("no free fake-robot address in 10000 tries")


@dataclass(frozen=True)
class CliRun:
    """What one ``urdaemon`` command did: its exit code and what it wrote."""

    code: int
    stdout: str
    stderr: str


class _PerThreadStream(io.TextIOBase):
    """Stands in for ``sys.stdout``/``sys.stderr``: what a thread running a command writes goes to that
    command's buffer, everything else to the stream that was there before (pytest's capture)."""

    def __init__(self, fallback: TextIO, attribute: str) -> None:
        super().__init__()
        self.fallback = fallback
        self._attribute = attribute

    def _target(self) -> TextIO:
        target: TextIO | None = getattr(_CAPTURE, self._attribute, None)
        return self.fallback if target is None else target

    def write(self, text: str) -> int:
        return self._target().write(text)

    def flush(self) -> None:
        self._target().flush()

    def isatty(self) -> bool:
        return False


_CAPTURE = threading.local()
_CAPTURE_LOCK = threading.Lock()
_CAPTURE_USERS = 0


@contextlib.contextmanager
def _captured() -> Iterator[tuple[io.StringIO, io.StringIO]]:
    """Route this thread's writes to ``sys.stdout``/``sys.stderr`` (and its log records, formatted as
    ``urdaemon.cli.main`` configures them) into two buffers; other threads write where they did."""
    global _CAPTURE_USERS
    out, err = io.StringIO(), io.StringIO()
    with _CAPTURE_LOCK:
        if _CAPTURE_USERS == 0:
            sys.stdout = _PerThreadStream(sys.stdout, "stdout")
            sys.stderr = _PerThreadStream(sys.stderr, "stderr")
        _CAPTURE_USERS += 1
    _CAPTURE.stdout, _CAPTURE.stderr = out, err
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    thread = threading.get_ident()
    handler = logging.StreamHandler(err)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    handler.addFilter(lambda record: record.thread == thread)
    root.addHandler(handler)
    root.setLevel(min(level, logging.INFO))  # what the command's logging.basicConfig would set
    try:
        yield out, err
    finally:
        root.handlers[:] = handlers  # whatever the command installed goes with it
        root.setLevel(level)
        _CAPTURE.stdout = _CAPTURE.stderr = None
        with _CAPTURE_LOCK:
            _CAPTURE_USERS -= 1
            if _CAPTURE_USERS == 0:
                for name in ("stdout", "stderr"):
                    stream = getattr(sys, name)
                    if isinstance(stream, _PerThreadStream):
                        setattr(sys, name, stream.fallback)


@contextlib.contextmanager
def _signal_handlers_kept() -> Iterator[None]:
    """Put back the process's signal handlers afterwards: a command run in the main thread may install
    its own (``serve`` keeps them past its loop, as a process that is about to exit may)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    kept = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, handler in kept.items():
            if handler is not None:
                signal.signal(sig, handler)


def run_cli(*args: str) -> CliRun:
    """Run ``urdaemon ARGS`` in this thread, as ``urdaemon.cli.main`` (no new interpreter).

    For commands that start their own event loop call it where no loop runs, or use
    ``run_cli_in_thread`` from a test's loop.
    """
    from urdaemon.cli import main

    return run_captured(lambda: main(list(args)))


def run_captured(entry: Callable[[], int | None]) -> CliRun:
    """Call a command's entry point in this thread; what it returned or exited with, and wrote."""
    with _captured() as (out, err), _signal_handlers_kept():
        try:
            code = entry() or 0
        except SystemExit as exit_:  # argparse's usage errors and --version, a script's exit
            if isinstance(exit_.code, str):
                print(exit_.code, file=sys.stderr)
                code = 1
            else:
                code = exit_.code or 0
    return CliRun(code, out.getvalue(), err.getvalue())


def run_script(path: Path, *args: str) -> CliRun:
    """Run the Python script ``path ARGS`` as ``__main__`` in this thread, as ``python path ARGS`` would."""
    import runpy

    def entry() -> None:
        saved = sys.argv
        sys.argv = [str(path), *args]
        try:
            runpy.run_path(str(path), run_name="__main__")
        finally:
            sys.argv = saved

    return run_captured(entry)


async def run_cli_in_thread(*args: str, timeout: float = 60.0) -> CliRun:
    """``run_cli`` in a thread of its own, so the test's loop (and a daemon in it) keeps running.

    The thread is a daemon thread: a command that hangs fails the test after ``timeout`` seconds
    and cannot hold up the interpreter's exit.
    """
    return await in_thread(lambda: run_cli(*args), f"urdaemon {' '.join(args)}", timeout)


async def in_thread(call: Callable[[], CliRun], name: str, timeout: float) -> CliRun:
    """Run ``call`` in a daemon thread of its own and wait (on this loop) at most ``timeout`` s for it."""
    done = _thread_future(call, name)
    try:
        return await asyncio.wait_for(asyncio.shield(done), timeout)
    except TimeoutError:
        raise AssertionError(f"{name} did not finish within {timeout} s") from None


def _thread_future(call: Callable[[], T], name: str) -> asyncio.Future[T]:
    """``call()`` in a daemon thread of its own; what it returns or raises, as a future of the running
    loop (the test raises its error)."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[T] = loop.create_future()

    def work() -> None:
        try:
            result = call()
        except BaseException as err:  # handed to the test, which raises it
            with contextlib.suppress(RuntimeError):  # the loop has closed: nobody waits
                loop.call_soon_threadsafe(_fail, future, err)
            return
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(_succeed, future, result)

    threading.Thread(target=work, name=name, daemon=True).start()
    return future


def _succeed(future: asyncio.Future[T], result: T) -> None:
    if not future.done():
        future.set_result(result)


def _fail(future: asyncio.Future[Any], err: BaseException) -> None:
    if not future.done():
        future.set_exception(err)


async def wait_for_line(proc: subprocess.Popen[str], text: str, *, timeout: float) -> list[str]:
    """Read the process's stderr until a line contains ``text``; returns the lines read.

    Each line is read on a thread of its own, not on the loop's default executor: there, reads
    queued behind other blocking work (another test's, a client's query) could return a line long
    after it was printed, and a test would act on a process that had already moved on."""
    assert proc.stderr is not None
    stream = proc.stderr
    deadline = time.monotonic() + timeout
    lines: list[str] = []
    while time.monotonic() < deadline:
        line = await asyncio.wait_for(
            _thread_future(stream.readline, "wait-for-line"), deadline - time.monotonic()
        )
        if not line:
            raise AssertionError(
                f"process exited ({proc.poll()}) before printing {text!r}:\n{''.join(lines)}"
            )
        lines.append(line)
        if text in line:
            return lines
    raise AssertionError(f"{text!r} not printed within {timeout} s:\n{''.join(lines)}")


def drain_in_background(proc: subprocess.Popen[str], sink: list[str]) -> threading.Thread:
    """Keep reading the process's stderr into ``sink`` so its pipe never fills up; the reading thread,
    which ends at the stream's end (join it after the process exited to have every line: on a busy
    machine the last lines can reach ``sink`` well after the exit)."""
    assert proc.stderr is not None
    stream = proc.stderr

    def pump() -> None:
        for line in stream:
            sink.append(line)

    reader = threading.Thread(target=pump, name="stderr-drain", daemon=True)
    reader.start()
    return reader


def swing_trajectory(
    points: int, home: Sequence[float], *, passthrough: bool = False, last_segment: float = 1.0
) -> dict[str, Any]:
    """A valid trajectory goal of ``points`` points with velocities and accelerations, 10 ms apart: a
    slow swing of 0.05 rad from ``home``, its last point at rest ``last_segment`` s after the one
    before (benchmarks/input_stalls.py, a script of its own, builds the same goal)."""
    body: list[dict[str, Any]] = []
    for k in range(points - 1):
        t = 0.5 + k * 0.01
        body.append(
            {
                "positions": [round(h + 0.05 * (1 - math.cos(t)), 6) for h in home],
                "velocities": [round(0.05 * math.sin(t), 6)] * 6,
                "accelerations": [round(0.05 * math.cos(t), 6)] * 6,
                "time_from_start": round(t, 6),
            }
        )
    end = round(0.5 + (points - 2) * 0.01 + last_segment, 6)
    rest = body[-1]["positions"] if body else list(home)
    body.append(
        {"positions": rest, "velocities": [0.0] * 6, "accelerations": [0.0] * 6, "time_from_start": end}
    )
    goal: dict[str, Any] = {"points": body}
    if passthrough:
        goal["passthrough"] = True
    return goal


async def rtde_sample(address: str, names: Sequence[str]) -> dict[str, Any]:
    """One RTDE output sample of ``names`` read with our own codec: a second, independent reader of a
    fake controller at ``address`` (bounded: 5 s per read, 100 events)."""
    from urdaemon.protocols import rtde
    from urdaemon.protocols._buffer import Side

    reader, writer = await asyncio.open_connection(address, 30004)
    conn = rtde.RtdeConnection(Side.DAEMON)
    pending: list[object] = []

    async def next_event() -> object:
        while not pending:
            data = await asyncio.wait_for(reader.read(65536), 5.0)
            assert data, "the fake closed the RTDE connection"
            pending.extend(conn.receive_data(data))
        return pending.pop(0)

    try:
        for request in (rtde.RequestProtocolVersion(2), rtde.SetupOutputs(125.0, tuple(names)), rtde.Start()):
            conn.send(request)
            writer.write(conn.data_to_send())
            await next_event()
        for _ in range(100):
            event = await next_event()
            if isinstance(event, rtde.DataPackage):
                return dict(zip(names, event.values, strict=True))
        raise AssertionError("no data package")
    finally:
        writer.close()


@dataclass
class LeaseGrant:
    """A robot's command lease held by a raw Zenoh session: the attachment its commanding messages
    carry, and the liveliness token that binds the lease to the session (keep it; undeclare it to
    let the lease go as a vanished client would), and the lease's secret session id."""

    token: bytes
    liveliness: Any
    reply: dict[str, Any]
    session_id: str = ""
    """The secret the lease is bound to (its liveliness token is ``<cell>/<robot>/lease/<id>``)."""


async def zenoh_ask(
    session: Any,
    key: str,
    body: dict[str, Any] | bytes | None = None,
    *,
    attachment: bytes | None = None,
    timeout: float = 10.0,
) -> list[dict[str, Any]]:
    """Every reply to a ``get`` on ``key`` (a dict is sent as JSON, bytes as they are), decoded as JSON
    (an error reply as ``{"error": text}``). Replies come on Zenoh's threads, so a daemon in this loop
    answers, and any number of asks may wait at once."""
    import zenoh

    payload = json.dumps(body).encode() if isinstance(body, dict) else body
    loop = asyncio.get_running_loop()
    done: asyncio.Future[None] = loop.create_future()
    replies: list[dict[str, Any]] = []

    def on_reply(reply: Any) -> None:
        if reply.ok is not None:
            decoded = json.loads(bytes(reply.ok.payload.to_bytes()))
        else:
            decoded = {"error": bytes(reply.err.payload.to_bytes()).decode(errors="replace")}
        loop.call_soon_threadsafe(replies.append, decoded)

    def finish() -> None:  # on the loop, after every reply was appended (the loop's order)
        if not done.done():
            done.set_result(None)

    def on_done() -> None:
        loop.call_soon_threadsafe(finish)

    handler = zenoh.handlers.Callback(on_reply, on_done)
    session.get(key, handler, payload=payload, attachment=attachment, timeout=timeout)
    await asyncio.wait_for(done, timeout + 10.0)
    return replies


async def acquire_lease(
    session: Any,
    cell: str,
    robot: str,
    *,
    holder: str = "tests",
    force: str | None = None,
    session_id: str | None = None,
) -> LeaseGrant:
    """Acquire ``robot``'s command lease for ``session`` as a client does: choose a secret session id
    (or reuse ``session_id``), declare the liveliness token ``<cell>/<robot>/lease/<id>``, then ask
    ``acquire`` (with ``force``: take it over, for that reason); fails the test if it is not
    granted."""
    secret = secrets.token_hex(16) if session_id is None else session_id
    liveliness = session.liveliness().declare_token(f"{cell}/{robot}/lease/{secret}")
    body: dict[str, Any] = {"action": "acquire", "session": secret, "holder": holder}
    if force is not None:
        body.update(force=True, reason=force)
    replies = await zenoh_ask(session, f"{cell}/{robot}/lease", body)
    assert len(replies) == 1, f"lease of {robot}: {replies}"
    assert replies[0].get("ok") is True, f"lease of {robot} not granted: {replies}"
    return LeaseGrant(replies[0]["token"].encode(), liveliness, replies[0], secret)


async def client_lease(client: Any, robot: str) -> LeaseGrant:
    """``robot``'s command lease as ``client`` (an ``urdaemon.client.Client``) holds it: its token,
    for raw messages on the client's session beside the client's own calls (one lease, one holder:
    a second lease on the same session would be another holder, with a secret of its own)."""
    token = await (await client.robot(robot)).ensure_lease()
    return LeaseGrant(token.encode(), None, {})


class Stepped(Generic[T]):
    """Stepped work (a generator of steps, runtime/motion.py) driven by hand, a counted number of steps
    at a time: ``step(count)`` until it returns False, then ``result()``."""

    def __init__(self, steps: Generator[None, None, T]) -> None:
        self._steps: Generator[None, None, T] | None = steps
        self._done = False
        self._result: T | None = None

    def step(self, count: int = 1) -> bool:
        """Run up to ``count`` steps; True while more remain (a refusal raises, then it is over)."""
        steps = self._steps
        if steps is None:
            return False
        try:
            for _ in range(count):
                next(steps)
        except StopIteration as stop:
            self._result, self._done, self._steps = stop.value, True, None
            return False
        except BaseException:
            self._steps = None
            raise
        return True

    def result(self) -> T:
        """What the finished work returned."""
        if not self._done:
            raise RuntimeError("the work has not finished")
        return self._result  # type: ignore[return-value]

    def close(self) -> None:
        """Abandon the work."""
        if self._steps is not None:
            self._steps.close()
            self._steps = None


def load_benchmark(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` as a module (``bench_<name>``; benchmarks are scripts, not a package),
    registered in ``sys.modules`` so its dataclasses resolve their own module."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"bench_{name}", path)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module
