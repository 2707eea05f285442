"""Serial transport for the drivers: pyserial URLs, timeouts, reconnect with back-off.

``serial_for_url`` accepts device paths (``/dev/ttyUSB0``, ``/dev/ttyACM0``) and URLs
(``socket://host:port`` for a device server or an emulator's TCP port, ``rfc2217://``,
``loop://`` for tests). Device ports are opened exclusively (POSIX lock), so two drivers
cannot interleave on one port. This module owns the port, its timeouts and reconnects;
the protocol modules stay pure (bytes in, frames out).
"""

import errno
import time
from typing import Callable, Optional

import serial


class TransportError(OSError):
    """The port cannot be opened, or it failed while in use; the message says why."""


def describe_open_error(port: str, err: BaseException) -> str:
    """Turn an exception from opening a port into one actionable sentence."""
    code = getattr(err, 'errno', None)
    text = str(err)
    if isinstance(err, PermissionError) or code == errno.EACCES or 'Permission denied' in text:
        return (f'{port}: permission denied. Add your user to the dialout group '
                f'(sudo usermod -aG dialout $USER, then log in again) or install a udev rule '
                f'giving the device to that group (SUBSYSTEM=="tty", GROUP="dialout", '
                f'MODE="0660")')
    if isinstance(err, FileNotFoundError) or code == errno.ENOENT or 'No such file' in text:
        return (f'{port}: no such device. Is it plugged in and powered? '
                f'(ls /dev/ttyUSB* /dev/ttyACM* /dev/serial/by-id/)')
    if code == errno.EBUSY or 'lock' in text.lower() or 'busy' in text.lower():
        return f'{port}: in use by another process (the port is opened exclusively)'
    if isinstance(err, ConnectionRefusedError) or 'refused' in text.lower():
        return f'{port}: connection refused (nothing listens at that address)'
    return f'{port}: cannot open ({text})'


class SerialTransport:
    """One serial port (or URL) with read/write timeouts and reconnect with back-off.

    Call :meth:`ensure_open` periodically: it (re)opens the port when it is closed and the
    back-off delay has passed (0.5 s doubling up to 8 s by default). :meth:`read` and
    :meth:`write` raise :class:`TransportError` when the device disappears; the port is then
    closed and the next :meth:`ensure_open` tries again.
    """

    def __init__(self, url: str, baudrate: int = 115200, timeout: float = 0.1,
                 exclusive: bool = True, backoff_min: float = 0.5, backoff_max: float = 8.0,
                 clock: Callable[[], float] = time.monotonic,
                 opener: Callable[..., serial.SerialBase] = serial.serial_for_url) -> None:
        """Remember the settings; nothing is opened yet.

        Raises:
            ValueError: A setting is out of range.

        """
        if baudrate <= 0:
            raise ValueError(f'baudrate must be > 0, got {baudrate}')
        if timeout < 0:
            raise ValueError(f'timeout must be >= 0 s, got {timeout}')
        if not 0 < backoff_min <= backoff_max:
            raise ValueError('need 0 < backoff_min <= backoff_max, got '
                             f'{backoff_min} and {backoff_max}')
        self.url = url
        self.baudrate = baudrate
        self.timeout = timeout
        self.exclusive = exclusive
        self._backoff_min, self._backoff_max = backoff_min, backoff_max
        self._backoff = backoff_min
        self._clock = clock
        self._opener = opener
        self._port: Optional[serial.SerialBase] = None
        self._next_attempt = -float('inf')
        self.last_error = ''
        self.reconnects = 0

    @property
    def connected(self) -> bool:
        """Whether the port is open."""
        return self._port is not None

    def open_port(self) -> None:
        """Open the port now.

        Raises:
            TransportError: With an actionable message (missing device, permission, busy).

        """
        kwargs = {'baudrate': self.baudrate, 'timeout': self.timeout,
                  'write_timeout': max(self.timeout, 1.0)}
        if self.exclusive and not self.url.startswith(('socket://', 'rfc2217://', 'loop://')):
            kwargs['exclusive'] = True
        try:
            self._port = self._opener(self.url, **kwargs)
        except (serial.SerialException, OSError, ValueError) as err:
            self._port = None
            self.last_error = describe_open_error(self.url, err.__cause__ or err)
            raise TransportError(self.last_error) from err
        self._backoff = self._backoff_min
        self.last_error = ''

    def ensure_open(self) -> bool:
        """Open the port if it is closed and the back-off allows; return whether it is open."""
        if self._port is not None:
            return True
        now = self._clock()
        if now < self._next_attempt:
            return False
        try:
            self.open_port()
            self.reconnects += 1
            return True
        except TransportError:
            self._next_attempt = now + self._backoff
            self._backoff = min(2.0 * self._backoff, self._backoff_max)
            return False

    def _failed(self, what: str, err: BaseException) -> TransportError:
        self.close()
        self.last_error = f'{self.url}: {what} failed ({err}); the device disappeared?'
        return TransportError(self.last_error)

    def read(self, max_bytes: int = 4096) -> bytes:
        """Read what is available (up to ``max_bytes``; b'' after the timeout).

        Raises:
            TransportError: The port is closed or failed (it is then closed).

        """
        if self._port is None:
            raise TransportError(f'{self.url}: not open')
        try:
            waiting = self._port.in_waiting
            return self._port.read(max(1, min(max_bytes, waiting or 1)))
        except (serial.SerialException, OSError) as err:
            raise self._failed('read', err) from err

    def write(self, data: bytes) -> None:
        """Write all bytes.

        Raises:
            TransportError: The port is closed or failed (it is then closed).

        """
        if self._port is None:
            raise TransportError(f'{self.url}: not open')
        try:
            self._port.write(data)
            self._port.flush()
        except (serial.SerialException, OSError) as err:
            raise self._failed('write', err) from err

    def close(self) -> None:
        """Close the port (safe to call twice)."""
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError):
                pass
