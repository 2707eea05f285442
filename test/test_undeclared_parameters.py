"""An undeclared parameter stops a node in its constructor, before it does anything.

``ekf_slam --ros-args -p sigm_range:=0.1`` must print its one-line error before the node
logs that it runs, and a driver must not open its device first: each node refuses unknown
names (:func:`~landmark_nav.nodes.common.reject_undeclared`) once it has declared its
parameters, before it creates a timer, starts a thread or logs at INFO.
"""

import importlib
import threading

from landmark_nav.nodes.common import ParameterError
from landmark_nav.tools.docs_params import (_NO_DEVICE, _private_context, _quiet_logger,
                                            _recording, NODES)
import pytest
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node
from rclpy.parameter import Parameter


@pytest.mark.parametrize('name', list(NODES))
def test_an_undeclared_name_is_refused_before_the_node_starts_anything(name, monkeypatch):
    module, cls, _ = NODES[name]
    node_class = getattr(importlib.import_module(module), cls)
    started = []

    def recorded(what, original):
        def call(self, *args, **kwargs):
            started.append(what)
            return original(self, *args, **kwargs)
        return call

    monkeypatch.setattr(Node, 'create_timer', recorded('a timer', Node.create_timer))
    monkeypatch.setattr(threading.Thread, 'start', recorded('a thread', threading.Thread.start))
    monkeypatch.setattr(RcutilsLogger, 'info', recorded('an INFO line', RcutilsLogger.info))
    overrides = [Parameter(k, value=v) for k, v in _NO_DEVICE.get(name, {}).items()]
    overrides.append(Parameter('sigm_range', value=0.1))
    with _private_context() as context:
        node = None
        try:
            with pytest.raises(ParameterError, match=f"^{name} has no parameter 'sigm_range'"):
                node = node_class(context=context, parameter_overrides=overrides)
        finally:
            if node is not None:
                node.destroy_node()
    assert not started, f'{name} started {", ".join(started)} before refusing the name'


@pytest.mark.parametrize('name', list(NODES))
def test_every_declared_name_passes_the_check(name):
    """The check runs after the last declaration: each name the node declares is accepted."""
    module, cls, _ = NODES[name]
    node_class = getattr(importlib.import_module(module), cls)
    records = []
    with _private_context() as context, _quiet_logger(name):
        device = [Parameter(k, value=v) for k, v in _NO_DEVICE.get(name, {}).items()]
        with _recording(records):
            node_class(context=context, parameter_overrides=device).destroy_node()
        given = {k: v for k, v, _ in records if v is not None}
        given.update(_NO_DEVICE.get(name, {}))
        overrides = [Parameter(k, value=v) for k, v in given.items()]
        node_class(context=context, parameter_overrides=overrides).destroy_node()
    assert len(given) > 5
