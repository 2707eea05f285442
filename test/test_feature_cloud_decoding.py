"""feature_cloud_to_arrays: the packed fast path and the general path give the same columns."""

from landmark_nav.feature_msgs import (CORNER_FIELDS, feature_cloud_to_arrays,
                                       LINE_FIELDS, make_feature_cloud)
import numpy as np
from sensor_msgs.msg import PointField


def test_packed_clouds_round_trip_exactly():
    rng = np.random.default_rng(0)
    for names, float64 in ((CORNER_FIELDS, True), (LINE_FIELDS, False)):
        cols = {k: rng.normal(size=7) for k in names}
        out = feature_cloud_to_arrays(make_feature_cloud(5, 'laser', names, cols, float64))
        dtype = np.float64 if float64 else np.float32
        for k in names:
            assert out[k].dtype == np.float64
            assert np.array_equal(out[k], cols[k].astype(dtype).astype(float)), k
        out['x'][0] = 1e9  # the columns are the caller's to change
        assert feature_cloud_to_arrays(make_feature_cloud(
            5, 'laser', names, cols, float64))['x'][0] != 1e9


def test_a_cloud_with_padding_takes_the_general_path():
    cols = {'x': np.array([1.5, -2.0]), 'y': np.array([0.25, 3.0])}
    msg = make_feature_cloud(5, 'laser', ('x', 'y'), cols, True)
    table = np.frombuffer(msg.data, dtype='<f8').reshape(2, 2)
    padded = np.zeros((2, 3))
    padded[:, [0, 2]] = table  # y moved to offset 16, 8 bytes of padding between
    msg.data = padded.tobytes()
    msg.fields = [PointField(name='x', offset=0, datatype=PointField.FLOAT64, count=1),
                  PointField(name='y', offset=16, datatype=PointField.FLOAT64, count=1)]
    msg.point_step, msg.row_step = 24, 48
    out = feature_cloud_to_arrays(msg)
    assert np.array_equal(out['x'], cols['x']) and np.array_equal(out['y'], cols['y'])
