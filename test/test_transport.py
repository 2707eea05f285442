"""Serial transport: URLs, clear open errors, reconnect with back-off after a device loss."""

import errno
import socket
import threading
import time

from landmark_nav.drivers.transport import describe_open_error, SerialTransport, TransportError
import pytest
import serial


def test_loop_url_round_trip():
    port = SerialTransport('loop://', timeout=0.05)
    assert port.ensure_open()
    port.write(b'VV\n')
    got = b''
    for _ in range(10):
        got += port.read()
        if got == b'VV\n':
            break
    assert got == b'VV\n'
    port.close()
    port.close()
    assert not port.connected


def test_missing_device_names_it():
    port = SerialTransport('/dev/ttyLANDMARKNAV_NOPE')
    with pytest.raises(TransportError, match='no such device'):
        port.open_port()
    assert 'ttyLANDMARKNAV_NOPE' in port.last_error


def test_error_messages_are_actionable():
    msg = describe_open_error('/dev/ttyUSB0', PermissionError(errno.EACCES, 'Permission denied'))
    assert 'dialout' in msg and 'udev' in msg
    assert 'in use' in describe_open_error('/dev/ttyUSB0', OSError(errno.EBUSY, 'busy'))
    assert 'refused' in describe_open_error('socket://x:1', ConnectionRefusedError('refused'))


def test_bad_settings():
    for kwargs in ({'baudrate': 0}, {'timeout': -1}, {'backoff_min': 0},
                   {'backoff_min': 5, 'backoff_max': 1}):
        with pytest.raises(ValueError):
            SerialTransport('loop://', **kwargs)


def test_backoff_doubles_up_to_the_cap():
    now = [0.0]
    calls = []

    def opener(url, **kwargs):
        calls.append(now[0])
        raise OSError(errno.ENOENT, 'No such file or directory')

    port = SerialTransport('/dev/ttyUSB9', clock=lambda: now[0], opener=opener,
                           backoff_min=0.5, backoff_max=2.0)
    for t in [x * 0.25 for x in range(40)]:  # 10 s in 0.25 s steps
        now[0] = t
        assert not port.ensure_open()
    gaps = [b - a for a, b in zip(calls, calls[1:])]
    assert gaps[:3] == [0.5, 1.0, 2.0] and all(g == 2.0 for g in gaps[3:])


class FlakyPort:
    """A fake device: serves its bytes, then fails like an unplugged USB adapter."""

    def __init__(self, payload, fail_after):
        self.payload, self.reads, self.fail_after = payload, 0, fail_after
        self.in_waiting = len(payload)

    def read(self, n):
        self.reads += 1
        if self.reads > self.fail_after:
            raise serial.SerialException('device reports readiness to read but returned no data')
        return self.payload

    def write(self, data):
        pass

    def flush(self):
        pass

    def close(self):
        pass


def test_device_that_vanishes_and_returns_is_reopened():
    now = [0.0]
    attempts = []
    available = [True]

    def opener(url, **kwargs):
        attempts.append(now[0])
        if not available[0]:
            raise OSError(errno.ENOENT, 'No such file or directory')
        return FlakyPort(b'scan', fail_after=2)

    port = SerialTransport('/dev/ttyACM0', clock=lambda: now[0], opener=opener)
    assert port.ensure_open() and port.read() == b'scan'
    assert port.read() == b'scan'
    with pytest.raises(TransportError, match='disappeared'):
        port.read()
    assert not port.connected
    available[0] = False            # unplugged for a while: back-off, no busy loop
    for step in range(1, 9):
        now[0] = 0.25 * step
        assert not port.ensure_open()
    available[0] = True             # plugged in again
    now[0] = 10.0
    assert port.ensure_open() and port.read() == b'scan'
    assert port.reconnects == 2
    assert len(attempts) <= 6


def test_socket_url_round_trip():
    server = socket.socket()
    server.bind(('127.0.0.1', 0))
    server.listen(1)
    host, port_no = server.getsockname()

    def serve():
        conn, _ = server.accept()
        conn.sendall(conn.recv(16).upper())
        conn.close()

    worker = threading.Thread(target=serve)
    worker.start()
    port = SerialTransport(f'socket://{host}:{port_no}', timeout=0.2)
    assert port.ensure_open()
    port.write(b'md0000')
    got = b''
    deadline = time.monotonic() + 5.0
    while got != b'MD0000' and time.monotonic() < deadline:
        got += port.read()
    assert got == b'MD0000'
    port.close()
    worker.join(timeout=5)
    server.close()
