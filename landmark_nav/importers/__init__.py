"""Import real laser logs (Carmen, CMU Wean Hall, BreezySLAM) into rosbag2 (MCAP) bags.

The parsers are pure Python/numpy; :mod:`.writer` builds the ROS messages. The bags follow
the imported-bag contract: ``/scan``, ``/odom``, ``/ground_truth/odom`` (when the log has a
reference), no ``/tf``, and the facts in ``metadata.yaml`` ``custom_data``.
"""

from .common import LineError, ParsedLog, ScanRecord, Sensor
from .drift import DriftModel, parse_drift_model, propagate_covariance, synthetic_odometry
from .stamps import repair_stamps, StampRepairs
from .writer import CUSTOM_KEYS, FORMATS, guess_format, import_log, ImportResult, parse_log

__all__ = ['CUSTOM_KEYS', 'DriftModel', 'FORMATS', 'ImportResult', 'LineError', 'ParsedLog',
           'ScanRecord', 'Sensor', 'StampRepairs', 'guess_format', 'import_log',
           'parse_drift_model', 'parse_log', 'propagate_covariance', 'repair_stamps',
           'synthetic_odometry']
