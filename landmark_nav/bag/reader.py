"""Read rosbag2 directories (MCAP or SQLite storage) into rclpy messages."""

from dataclasses import dataclass
from pathlib import Path
import struct
from typing import Iterable, Iterator, Optional, Tuple

from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError

from .errors import BagError
from .messages import deserialize

__all__ = ['BagReader', 'BagMessage', 'TopicInfo']


@dataclass(frozen=True)
class TopicInfo:
    """What a bag holds on one topic."""

    name: str
    type_name: str
    count: int
    latched: bool


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: topic, type, log time (ns) and the CDR bytes."""

    topic: str
    type_name: str
    log_time_ns: int
    data: bytes

    def decode(self):
        """Deserialize into an rclpy message."""
        return deserialize(self.data, self.type_name)


_READ_ERRORS = (ReaderError, OSError, KeyError, ValueError, struct.error, EOFError,
                AssertionError, IndexError, TypeError, UnicodeDecodeError, MemoryError,
                OverflowError)


class BagReader:
    """Read a rosbag2 directory (or a bare .mcap file) as a context manager.

    Every failure of the storage layer is re-raised as :class:`BagError` naming the bag.
    """

    def __init__(self, path) -> None:
        """Check that the path exists and looks like a bag.

        Raises:
            BagError: Missing path or not a bag.

        """
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'No bag at {self.path}')
        if self.path.is_dir() and not (self.path / 'metadata.yaml').is_file():
            raise BagError(f'{self.path} is not a rosbag2 directory (no metadata.yaml)')
        try:
            self._reader = Reader(self.path)
        except _READ_ERRORS as err:
            raise BagError(f'Could not open bag {self.path}: {err}') from err

    def __enter__(self) -> 'BagReader':
        """Open the bag."""
        try:
            self._reader.open()
        except _READ_ERRORS as err:
            raise BagError(f'Could not read bag {self.path}: {err}') from err
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Close the bag."""
        if self._reader.is_open:
            self._reader.close()

    @property
    def start_ns(self) -> int:
        """Log time of the first message."""
        return int(self._reader.start_time)

    @property
    def end_ns(self) -> int:
        """Log time just after the last message."""
        return int(self._reader.end_time)

    @property
    def duration_ns(self) -> int:
        """Duration covered by the messages."""
        return int(self._reader.duration)

    @property
    def custom_data(self) -> dict:
        """Return the ``custom_data`` strings of ``metadata.yaml`` (empty dict when none)."""
        metadata = getattr(self._reader.storage, 'metadata', None)  # rosbag2 directory
        return dict(getattr(metadata, 'custom', None) or {})

    def topics(self) -> dict:
        """Return {topic: TopicInfo}."""
        result = {}
        for name, info in self._reader.topics.items():
            latched = any(
                qos.durability == QosDurability.TRANSIENT_LOCAL
                for conn in info.connections
                for qos in getattr(conn.ext, 'offered_qos_profiles', []) or [])
            result[name] = TopicInfo(name, info.msgtype or '', int(info.msgcount), latched)
        return result

    def messages(self, topics: Optional[Iterable[str]] = None,
                 start_ns: Optional[int] = None,
                 stop_ns: Optional[int] = None) -> Iterator[BagMessage]:
        """Yield messages in log-time order, optionally only some topics and a time window.

        Raises:
            BagError: A topic is not in the bag, or the storage is corrupt.

        """
        connections = self._reader.connections
        if topics is not None:
            wanted = set(topics)
            missing = wanted - {c.topic for c in connections}
            if missing:
                raise BagError(f'{self.path} has no topic {", ".join(sorted(missing))}')
            connections = [c for c in connections if c.topic in wanted]
            if not connections:
                return
        try:
            for conn, stamp, data in self._reader.messages(connections, start_ns, stop_ns):
                yield BagMessage(conn.topic, conn.msgtype, int(stamp), bytes(data))
        except _READ_ERRORS as err:
            raise BagError(f'Corrupt bag {self.path}: {err}') from err

    def decoded(self, topics: Optional[Iterable[str]] = None) -> Iterator[Tuple[str, int, object]]:
        """Yield (topic, log_time_ns, rclpy message) in log-time order."""
        for item in self.messages(topics):
            yield item.topic, item.log_time_ns, item.decode()
