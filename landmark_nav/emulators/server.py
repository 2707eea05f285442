"""Serve an emulated device over a pseudo-terminal and/or a TCP port, with fault injection.

A :class:`Device` is pure protocol logic with a clock passed in: :meth:`Device.receive`
turns the bytes a driver wrote into reply frames, :meth:`Device.poll` yields frames the
device streams on its own (continuous scans, P2OS status packets). :class:`DeviceServer`
owns the endpoints and a thread that moves bytes between them and the device:

* a pseudo-terminal in raw mode whose slave path is published as a stable symlink
  (``link``), like ``/dev/serial/by-id/...``, so a driver can open the same path again
  after the port has "vanished" and come back as a new pty;
* a TCP port (``socket://host:port`` in pyserial, MobileSim-style), one client at a time.

Outgoing frames pass through a :class:`FaultInjector`; faults are injected on request
(:meth:`DeviceServer.inject`) or at random with a given rate: garbage bytes, a corrupted
checksum/CRC byte, a truncated frame, a dropped reply, silence for a while, and the port
disappearing for a while.
"""

from dataclasses import dataclass
import errno
import os
import select
import socket
import threading
import time
import tty
from typing import Callable, List, Optional, Sequence, Tuple

from landmark_nav.stop_signals import stop_on_signals
import numpy as np

FAULT_KINDS = ('garbage', 'corrupt', 'truncate', 'drop', 'silence', 'vanish')


class EndpointError(OSError):
    """A pty link or TCP port cannot be opened; the message names it and its option."""


class Device:
    """Protocol logic of one emulated device (subclass it; no I/O, clock passed in)."""

    def receive(self, data: bytes, now: float) -> List[bytes]:
        """Consume bytes from the driver; return the reply frames, in order."""
        raise NotImplementedError

    def poll(self, now: float) -> List[bytes]:
        """Return frames the device sends on its own at time ``now`` (default: none)."""
        return []

    def next_due(self, now: float) -> Optional[float]:
        """Return when :meth:`poll` next has something to send (None: no deadline known).

        The server sleeps until then (at most its loop period), so frames leave at the
        times the device model gives them rather than on the loop's tick.
        """
        return None

    def disconnected(self) -> None:
        """Forget per-connection state (the link went down or the client left)."""


@dataclass
class Fault:
    """One fault request: ``kind`` from :data:`FAULT_KINDS`, ``duration`` for silence/vanish."""

    kind: str
    duration: float = 1.0

    def __post_init__(self) -> None:
        """Validate the kind and the duration."""
        if self.kind not in FAULT_KINDS:
            raise ValueError(f'unknown fault {self.kind!r}; one of {", ".join(FAULT_KINDS)}')
        if not self.duration >= 0.0:
            raise ValueError(f'fault duration must be >= 0 s, got {self.duration}')


def parse_fault(text: str) -> Fault:
    """Parse ``kind`` or ``kind:seconds`` (e.g. ``silence:2``) into a :class:`Fault`."""
    kind, _, seconds = text.partition(':')
    try:
        duration = float(seconds) if seconds else 1.0
    except ValueError:
        raise ValueError(f'bad fault duration in {text!r}') from None
    return Fault(kind, duration)


class FaultInjector:
    """Apply queued or random faults to outgoing frames.

    Frame-level faults (garbage, corrupt, truncate, drop) act on the next frame sent;
    time-level faults (silence, vanish) open a window during which nothing is sent (and,
    for vanish, the server closes its endpoints). ``rate`` is the probability per frame of
    a random frame-level fault from ``random_kinds``.
    """

    def __init__(self, seed: int = 0, rate: float = 0.0,
                 random_kinds: Sequence[str] = ('garbage', 'corrupt', 'truncate', 'drop')) -> None:
        """Set up the random source and the queue."""
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f'fault rate must be in [0, 1], got {rate}')
        for kind in random_kinds:
            Fault(kind)
        self._rng = np.random.default_rng(seed)
        self.rate = rate
        self.random_kinds = tuple(random_kinds)
        self._queue: List[Fault] = []
        self._lock = threading.Lock()
        self.silent_until = -float('inf')
        self.vanish_until = -float('inf')
        self.injected: List[str] = []

    def inject(self, fault: Fault, now: float) -> None:
        """Queue a frame-level fault or open a silence/vanish window starting ``now``."""
        with self._lock:
            if fault.kind == 'silence':
                self.silent_until = max(self.silent_until, now + fault.duration)
            elif fault.kind == 'vanish':
                self.vanish_until = max(self.vanish_until, now + fault.duration)
            else:
                self._queue.append(fault)
            self.injected.append(fault.kind)

    def silent(self, now: float) -> bool:
        """Whether nothing may be sent at ``now`` (silence or vanish window)."""
        return now < self.silent_until or now < self.vanish_until

    def vanished(self, now: float) -> bool:
        """Whether the endpoints must be down at ``now``."""
        return now < self.vanish_until

    def _next_kind(self) -> Optional[str]:
        with self._lock:
            if self._queue:
                return self._queue.pop(0).kind
        if self.rate > 0.0 and self.random_kinds and self._rng.random() < self.rate:
            kind = str(self._rng.choice(self.random_kinds))
            self.injected.append(kind)
            return kind
        return None

    def apply(self, frame: bytes) -> bytes:
        """Return the bytes to send for ``frame`` (possibly damaged, or b'' if dropped)."""
        kind = self._next_kind()
        if kind is None or not frame:
            return frame
        if kind == 'drop':
            return b''
        if kind == 'garbage':
            junk = self._rng.integers(0, 256, int(self._rng.integers(1, 64)), dtype=np.uint8)
            return junk.tobytes() + frame
        if kind == 'truncate':
            return frame[:int(self._rng.integers(0, len(frame)))]
        # corrupt: flip one bit of the last byte that is not a line terminator, which is a
        # checksum/CRC byte in all three protocols' frames
        body = frame.rstrip(b'\n\r')
        index = len(body) - 1 if body else len(frame) - 1
        damaged = bytearray(frame)
        damaged[index] ^= 1 << int(self._rng.integers(0, 8))
        return bytes(damaged)


class DeviceServer:
    """Serve a :class:`Device` on a pty (stable symlink) and/or a TCP port, in a thread.

    Example::

        server = DeviceServer(UrgDevice(...), link='/tmp/urg', tcp_port=0)
        server.start()          # server.link -> /dev/pts/N, server.tcp_port is bound
        ...                     # a driver opens '/tmp/urg' or f'socket://127.0.0.1:{port}'
        server.inject(Fault('vanish', 1.5))
        server.stop()
    """

    def __init__(self, device: Device, link: Optional[str] = None,
                 tcp_port: Optional[int] = None, tcp_host: str = '127.0.0.1',
                 faults: Optional[FaultInjector] = None, period: float = 0.002,
                 clock: Callable[[], float] = time.monotonic,
                 options: Tuple[str, str] = ('--link', '--tcp')) -> None:
        """Configure; nothing is opened until :meth:`start`.

        Args:
            device: The protocol logic.
            link: Path of the symlink to the pty slave (None: no pty).
            tcp_port: TCP port to listen on (0: any free port; None: no TCP).
            tcp_host: Address to bind.
            faults: Fault injector (default: one that injects nothing by itself).
            period: Loop period [s] for polling the device.
            clock: Monotonic clock [s].
            options: The command-line options that set ``link`` and ``tcp_port``, named
                in the error when an endpoint cannot be opened.

        """
        if link is None and tcp_port is None:
            raise ValueError('serve on a pty link, a TCP port or both')
        self.device = device
        self.link = link
        self.tcp_port = tcp_port
        self.tcp_host = tcp_host
        self.faults = faults or FaultInjector()
        self.period = period
        self._clock = clock
        self.options = options
        self._linked = False  # the link is ours (made by _open_endpoints)
        self._master: Optional[int] = None
        self._slave: Optional[int] = None
        self._listener: Optional[socket.socket] = None
        self._client: Optional[socket.socket] = None
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self.pty_path: Optional[str] = None
        self.bytes_in = 0
        self.bytes_out = 0
        self.bytes_dropped = 0  # not written: the pty was full (the client did not read)

    # --- endpoints -------------------------------------------------------------------

    def _open_endpoints(self) -> None:
        # the TCP port first: a port in use leaves the pty link (maybe another's) untouched
        if self.tcp_port is not None:
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                listener.bind((self.tcp_host, self.tcp_port))
            except OSError as err:
                listener.close()
                raise EndpointError(self._bind_problem(err)) from None
            listener.listen(1)
            listener.setblocking(False)
            self._listener = listener
            self.tcp_port = listener.getsockname()[1]
        if self.link is not None:
            master, slave = os.openpty()
            tty.setraw(slave)
            tty.setraw(master)
            os.set_blocking(master, False)
            self._master, self._slave = master, slave
            self.pty_path = os.ttyname(slave)
            tmp = f'{self.link}.{os.getpid()}.tmp'
            try:
                if os.path.lexists(tmp):
                    os.unlink(tmp)
                os.symlink(self.pty_path, tmp)
                os.replace(tmp, self.link)
                self._linked = True
            except OSError as err:
                raise EndpointError(f'cannot create the pty link {self.link}: {err.strerror}; '
                                    f'choose another with {self.options[0]} PATH') from None

    def _bind_problem(self, err: OSError) -> str:
        """Return the one-line error of a TCP port that cannot be bound."""
        port, option = self.tcp_port, self.options[1]
        if err.errno == errno.EADDRINUSE:
            return f'TCP port {port} is in use; choose another with {option} PORT'
        if err.errno == errno.EACCES:
            return (f'TCP port {port} needs privileges to bind (ports below 1024); choose '
                    f'another with {option} PORT')
        return (f'cannot listen on TCP {self.tcp_host}:{port} ({option}): '
                f'{err.strerror or err}')

    def _close_endpoints(self) -> None:
        # the link goes first: a driver that sees the port break must not find it still there
        if self._linked and os.path.islink(self.link):
            os.unlink(self.link)
        self._linked = False
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        for sock in (self._client, self._listener):
            if sock is not None:
                sock.close()
        self._client = self._listener = None
        self.device.disconnected()

    @property
    def url(self) -> str:
        """The pyserial URL of the TCP endpoint, or the pty link."""
        if self.tcp_port is not None:
            return f'socket://{self.tcp_host}:{self.tcp_port}'
        return str(self.link)

    # --- loop -------------------------------------------------------------------------

    def start(self) -> 'DeviceServer':
        """Open the endpoints and start the serving thread; return self.

        Raises:
            EndpointError: A pty link or TCP port cannot be opened (nothing is left open).
        """
        try:
            self._open_endpoints()
        except OSError:
            self._close_endpoints()
            raise
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name='device-server', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the endpoints (safe to call twice)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        with self._lock:
            self._close_endpoints()

    def __enter__(self) -> 'DeviceServer':
        """Start serving."""
        return self.start()

    def __exit__(self, *exc) -> None:
        """Stop serving."""
        self.stop()

    def inject(self, fault: Fault) -> None:
        """Inject a fault now (thread-safe)."""
        self.faults.inject(fault, self._clock())

    def _readable(self) -> List[int]:
        fds = [fd for fd in (self._master,) if fd is not None]
        fds += [s.fileno() for s in (self._listener, self._client) if s is not None]
        return fds

    def _run(self) -> None:
        down = False
        while not self._stop.is_set():
            now = self._clock()
            with self._lock:
                if self.faults.vanished(now):
                    if not down:
                        self._close_endpoints()
                        down = True
                    time.sleep(self.period)
                    continue
                if down:
                    self._open_endpoints()
                    down = False
                fds = self._readable()
                due = self.device.next_due(now)
            wait = self.period if due is None else min(self.period, max(0.0, due - now))
            try:
                ready, _, _ = select.select(fds, [], [], wait)
            except (OSError, ValueError):
                ready = []
            with self._lock:
                if self.faults.vanished(self._clock()):
                    continue
                for fd in ready:
                    self._service(fd)
                now = self._clock()
                frames = self.device.poll(now)
                self._send(frames, now)

    def _service(self, fd: int) -> None:
        if self._listener is not None and fd == self._listener.fileno():
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            if self._client is not None:
                self._client.close()
                self.device.disconnected()
            client.setblocking(False)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._client = client
            return
        data = b''
        try:
            if self._master is not None and fd == self._master:
                data = os.read(fd, 65536)
            elif self._client is not None and fd == self._client.fileno():
                data = self._client.recv(65536)
                if not data:
                    self._client.close()
                    self._client = None
                    self.device.disconnected()
                    return
        except BlockingIOError:
            return
        except OSError:
            return
        if data:
            self.bytes_in += len(data)
            now = self._clock()
            self._send(self.device.receive(data, now), now)

    def _send(self, frames: List[bytes], now: float) -> None:
        if not frames or self.faults.silent(now):
            return
        out = b''.join(self.faults.apply(frame) for frame in frames)
        if not out:
            return
        if self._master is not None:
            self.bytes_dropped += self._write_fd(self._master, out)
        if self._client is not None:
            try:
                self._client.sendall(out)
            except OSError:
                self._client.close()
                self._client = None
                self.device.disconnected()
        self.bytes_out += len(out)

    @staticmethod
    def _write_fd(fd: int, data: bytes) -> int:
        """Write to the pty master; drop what does not fit (nobody is reading).

        Returns:
            The number of bytes dropped.
        """
        view = memoryview(data)
        while view:
            try:
                n = os.write(fd, view)
            except BlockingIOError:
                return len(view)
            except OSError as err:
                if err.errno in (errno.EIO, errno.EAGAIN):
                    return len(view)
                raise
            view = view[n:]
        return 0


def serve_forever(server: DeviceServer, announce: Callable[[str], None] = print,
                  stop: Optional[threading.Event] = None) -> None:
    """Start ``server``, announce its endpoints and block until SIGINT / SIGTERM.

    Both signals stop it even when the process started with SIGINT ignored (a background
    job of a script); the pty link and the TCP port are closed before it returns.

    Args:
        server: The device server.
        announce: Prints the endpoints.
        stop: Ends the serving when set (default: a new event the signals set).

    """
    stop = stop or threading.Event()
    stop_on_signals(stop)
    server.start()
    try:
        if server.link is not None:
            announce(f'pty: {server.link} -> {server.pty_path}')
        if server.tcp_port is not None:
            announce(f'tcp: socket://{server.tcp_host}:{server.tcp_port}')
        while not stop.wait(0.5):
            pass
    finally:
        server.stop()
