"""Map ROS type names ('sensor_msgs/msg/LaserScan') to rclpy message classes and back."""

import importlib

from rclpy.serialization import deserialize_message, serialize_message

from .errors import BagError

__all__ = ['deserialize', 'message_class', 'serialize', 'type_name']


def message_class(type_name_: str) -> type:
    """Return the message class for a type name such as 'nav_msgs/msg/Odometry'.

    Raises:
        BagError: The name is malformed or the message package is not installed.

    """
    parts = type_name_.split('/')
    if len(parts) != 3 or parts[1] != 'msg':
        raise BagError(f'Not a ROS 2 message type name: {type_name_!r}')
    package, _, name = parts
    try:
        module = importlib.import_module(f'{package}.msg')
        return getattr(module, name)
    except (ImportError, AttributeError) as err:
        raise BagError(f'Message type {type_name_} is not installed') from err


def type_name(cls_or_msg) -> str:
    """Return 'pkg/msg/Name' for a message class or instance."""
    cls = cls_or_msg if isinstance(cls_or_msg, type) else type(cls_or_msg)
    package = cls.__module__.split('.')[0]
    return f'{package}/msg/{cls.__name__}'


def serialize(msg) -> bytes:
    """Serialize a message to CDR bytes as stored in rosbag2 and sent over DDS."""
    return serialize_message(msg)


def deserialize(data: bytes, type_name_: str):
    """Deserialize CDR bytes of the named type into an rclpy message.

    Raises:
        BagError: The bytes do not decode as that type.

    """
    cls = message_class(type_name_)
    try:
        return deserialize_message(bytes(data), cls)
    except Exception as err:  # rclpy raises a bare RuntimeError-like error
        raise BagError(f'Could not decode a {type_name_} message: {err}') from err
