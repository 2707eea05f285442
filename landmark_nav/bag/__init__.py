"""rosbag2 (MCAP) reading and writing with rclpy message classes."""

from .errors import BagError
from .messages import deserialize, message_class, serialize, type_name
from .reader import BagMessage, BagReader, TopicInfo
from .writer import BagWriter

__all__ = ['BagError', 'BagMessage', 'BagReader', 'BagWriter', 'TopicInfo',
           'deserialize', 'message_class', 'serialize', 'type_name']
