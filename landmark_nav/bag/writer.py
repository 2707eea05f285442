"""Write rosbag2 directories with MCAP storage from rclpy messages."""

from pathlib import Path
from typing import Optional

from rosbags.interfaces import (
    Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError
from rosbags.typesys import get_typestore, Stores

from .errors import BagError
from .messages import serialize, type_name

__all__ = ['BagWriter', 'ROSBAG2_VERSION']

# rosbag2 metadata version written by ROS 2 Jazzy (newer readers accept it too).
ROSBAG2_VERSION = 8

_INFINITE = QosTime(sec=2147483647, nsec=4294967295)
_DEFAULT = QosTime(sec=0, nsec=0)


def _qos(latched: bool) -> Qos:
    """Return the offered QoS recorded for a topic (latched = transient local, depth 1)."""
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1 if latched else 10,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
        deadline=_INFINITE,
        lifespan=_INFINITE,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=_INFINITE,
        avoid_ros_namespace_conventions=False,
    )


class BagWriter:
    """Record rclpy messages into a new rosbag2 directory (metadata.yaml + one .mcap file).

    Use as a context manager::

        with BagWriter('bags/office') as bag:
            bag.add_topic('/scan', LaserScan)
            bag.write('/scan', stamp_ns, msg)

    The bag is what ``ros2 bag record -s mcap`` writes: ``ros2 bag info`` and
    ``ros2 bag play`` in a ROS 2 Jazzy install accept it.
    """

    def __init__(self, path) -> None:
        """Prepare a writer for a directory that must not exist yet.

        Raises:
            BagError: The directory exists already.

        """
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path} exists already; not overwriting a bag')
        self._writer = Writer(self.path, version=ROSBAG2_VERSION,
                              storage_plugin=StoragePlugin.MCAP)
        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        self._connections = {}

    def __enter__(self) -> 'BagWriter':
        """Open the bag."""
        try:
            self._writer.open()
        except (WriterError, OSError) as err:
            raise BagError(f'Could not create bag at {self.path}: {err}') from err
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Close the bag (written metadata makes it readable)."""
        self._writer.close()

    def add_topic(self, topic: str, msg_class, latched: bool = False) -> None:
        """Register a topic with its message class; latched topics replay as transient local.

        ``msg_class`` may also be a type name (``'tf2_msgs/msg/TFMessage'``) of a message
        package that is not installed: write its CDR bytes with :meth:`write_serialized`.
        """
        name = msg_class if isinstance(msg_class, str) else type_name(msg_class)
        try:
            self._connections[topic] = self._writer.add_connection(
                topic, name, typestore=self._typestore, offered_qos_profiles=[_qos(latched)])
        except (WriterError, KeyError) as err:
            raise BagError(f'Could not add topic {topic} ({name}) to {self.path}: {err}') from err

    def write(self, topic: str, stamp_ns: int, msg) -> None:
        """Write one message with its log time (integer nanoseconds since the epoch)."""
        connection: Optional[object] = self._connections.get(topic)
        if connection is None:
            raise BagError(f'Topic {topic} was not added to {self.path}')
        self._writer.write(connection, int(stamp_ns), serialize(msg))

    def write_serialized(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Write one message already serialized (CDR) with its log time [ns]."""
        connection: Optional[object] = self._connections.get(topic)
        if connection is None:
            raise BagError(f'Topic {topic} was not added to {self.path}')
        self._writer.write(connection, int(stamp_ns), bytes(data))

    def set_custom_data(self, key: str, value: str) -> None:
        """Store a string in the bag's ``metadata.yaml`` ``custom_data`` (rosbag2 >= 6).

        The package's keys start with ``landmark_nav.`` (e.g. ``landmark_nav.laser_mount``:
        ``"x y yaw"`` in m, m, rad, the ``base_link -> laser`` transform).
        """
        if not isinstance(value, str):
            raise BagError(f'custom_data value for {key!r} must be a string, got {value!r}')
        self._writer.set_custom_data(key, value)
