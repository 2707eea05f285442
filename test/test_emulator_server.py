"""DeviceServer and FaultInjector: pty link, TCP, faults, vanish and return."""

import os
import time

from landmark_nav.emulators.server import (Device, DeviceServer, Fault, FaultInjector,
                                           parse_fault)
import pytest
import serial


class _Echo(Device):
    """Reply ``<data>`` to every write; stream a tick line every 20 ms."""

    def __init__(self) -> None:
        self.last = 0.0
        self.disconnects = 0

    def receive(self, data, now):
        return [b'<' + data + b'>\n']

    def poll(self, now):
        if now - self.last >= 0.02:
            self.last = now
            return [b'tick\n']
        return []

    def disconnected(self):
        self.disconnects += 1


def _read_until(port, token: bytes, timeout: float = 2.0) -> bytes:
    data = b''
    deadline = time.monotonic() + timeout
    while token not in data and time.monotonic() < deadline:
        data += port.read(256)
    return data


def test_pty_and_tcp_carry_replies_and_stream(tmp_path):
    link = str(tmp_path / 'dev')
    with DeviceServer(_Echo(), link=link, tcp_port=0) as server:
        assert os.path.islink(link) and os.readlink(link) == server.pty_path
        with serial.serial_for_url(link, timeout=0.05) as pty_port:
            pty_port.write(b'hello')
            assert b'<hello>' in _read_until(pty_port, b'<hello>')
            assert b'tick\n' in _read_until(pty_port, b'tick\n')
        with serial.serial_for_url(server.url, timeout=0.05) as tcp_port:
            tcp_port.write(b'net')
            assert b'<net>' in _read_until(tcp_port, b'<net>')
    assert not os.path.lexists(link)


def test_vanish_breaks_the_port_and_the_link_returns(tmp_path):
    link = str(tmp_path / 'dev')
    device = _Echo()
    with DeviceServer(device, link=link) as server:
        port = serial.serial_for_url(link, timeout=0.05)
        server.inject(Fault('vanish', 1.0))
        with pytest.raises(serial.SerialException):
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                port.read(256)
        port.close()
        deadline = time.monotonic() + 3.0
        while not os.path.lexists(link) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert os.path.islink(link)
        with serial.serial_for_url(link, timeout=0.05) as port:
            port.write(b'back')
            assert b'<back>' in _read_until(port, b'<back>')
    assert device.disconnects >= 1


def test_silence_window_sends_nothing(tmp_path):
    link = str(tmp_path / 'dev')
    with DeviceServer(_Echo(), link=link) as server:
        with serial.serial_for_url(link, timeout=0.05) as port:
            assert b'tick' in _read_until(port, b'tick')
            server.inject(Fault('silence', 0.4))
            time.sleep(0.05)
            port.reset_input_buffer()
            quiet = port.read(256) + port.read(256)
            assert quiet == b''
            assert b'tick' in _read_until(port, b'tick')


def test_frame_faults_damage_exactly_one_frame():
    faults = FaultInjector(seed=3)
    frame = b'ABCDEFGH\n'
    faults.inject(Fault('drop'), 0.0)
    assert faults.apply(frame) == b''
    faults.inject(Fault('truncate'), 0.0)
    cut = faults.apply(frame)
    assert len(cut) < len(frame) and frame.startswith(cut)
    faults.inject(Fault('corrupt'), 0.0)
    bad = faults.apply(frame)
    diff = [i for i in range(len(frame)) if bad[i] != frame[i]]
    assert diff == [7] and bin(bad[7] ^ frame[7]).count('1') == 1
    faults.inject(Fault('garbage'), 0.0)
    junk = faults.apply(frame)
    assert junk.endswith(frame) and len(junk) > len(frame)
    assert faults.apply(frame) == frame
    assert faults.injected == ['drop', 'truncate', 'corrupt', 'garbage']


def test_random_fault_rate_is_respected():
    faults = FaultInjector(seed=1, rate=0.2)
    damaged = sum(faults.apply(b'0123456789\n') != b'0123456789\n' for _ in range(2000))
    assert 300 < damaged < 500


@pytest.mark.parametrize('text,kind,duration', [('silence:2.5', 'silence', 2.5),
                                                ('garbage', 'garbage', 1.0)])
def test_parse_fault(text, kind, duration):
    fault = parse_fault(text)
    assert (fault.kind, fault.duration) == (kind, duration)


@pytest.mark.parametrize('text', ['melt', 'silence:x', 'vanish:-1'])
def test_parse_fault_rejects_bad_text(text):
    with pytest.raises(ValueError):
        parse_fault(text)


def test_server_needs_an_endpoint():
    with pytest.raises(ValueError):
        DeviceServer(_Echo())


class _Delayed(Device):
    """Answer every write ``delay`` seconds later (a device model with its own timing)."""

    def __init__(self, delay: float) -> None:
        self.delay = delay
        self.pending = []

    def receive(self, data, now):
        self.pending.append((now + self.delay, b'<' + data + b'>\n'))
        return []

    def poll(self, now):
        due = [frame for t, frame in self.pending if t <= now]
        self.pending = [(t, frame) for t, frame in self.pending if t > now]
        return due

    def next_due(self, now):
        return min((t for t, _ in self.pending), default=None)


def test_frames_leave_when_the_device_says_not_on_the_loop_tick(tmp_path):
    # Loop period 1 s, replies due 5 ms after each request: the server sleeps until the
    # device's next deadline, so the reply arrives in about 5 ms, not at the next tick (a
    # server waking on its ticks answers each request sent right after a reply about 1 s
    # later). Only which wake-up is checked: the delay itself depends on the machine's load.
    link = str(tmp_path / 'dev')
    delays = []
    with DeviceServer(_Delayed(0.005), link=link, period=1.0):
        with serial.serial_for_url(link, timeout=0.002) as port:
            for k in range(5):
                sent = time.monotonic()
                port.write(b'q%d' % k)
                assert b'>' in _read_until(port, b'>')
                delays.append(time.monotonic() - sent)
    print('reply delays [ms]', [round(d * 1e3, 2) for d in delays])
    assert min(delays) >= 0.005
    assert sorted(delays)[2] < 0.1  # median: the deadline's wake-up, not the 1 s tick


@pytest.mark.parametrize('device, option, extra', [
    ('robot', '--tcp', []), ('robot', '--laser-tcp', ['--tcp', '0']), ('urg', '--tcp', [])])
def test_a_port_in_use_is_named_with_its_option(tmp_path, processes, device, option, extra):
    """``emulate robot`` with its TCP port taken said ``[Errno 98] Address already in use``."""
    import socket
    import subprocess
    import sys
    taken = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    taken.bind(('127.0.0.1', 0))
    taken.listen(1)
    port = taken.getsockname()[1]
    link = tmp_path / 'link'
    link.symlink_to(tmp_path)  # another emulator's link: left as it is
    args = [sys.executable, '-m', 'landmark_nav.tools.cli', 'emulate', device, '--link',
            str(link), *extra, option, str(port)]
    if device == 'robot':
        args += ['--laser-link', str(tmp_path / 'laser')]
    try:
        proc = processes.start(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        out, err = proc.communicate(timeout=120)
    finally:
        taken.close()
    assert proc.returncode == 2, err
    assert err.strip().splitlines()[-1] == (f'landmark_nav: error: TCP port {port} is in use; '
                                            f'choose another with {option} PORT')
    assert 'Traceback' not in err
    if option == '--tcp':  # the first port opened: nothing was touched before it failed
        assert os.readlink(link) == str(tmp_path)
