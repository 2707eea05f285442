"""The protocol and session modules are pure: no clock, no I/O, no rclpy."""

import ast

from landmark_nav.drivers import (clock_filter, laser_session, lms2xx, p2os, p2os_client, scip2,
                                  scip2_commands, scip2_decoder, scip2_encoders, scip2_frames,
                                  scip2_values, stream)
import pytest

ALLOWED = {'collections', 'dataclasses', 'math', 're', 'statistics', 'struct', 'typing', 'numpy',
           'landmark_nav'}


@pytest.mark.parametrize('module', [clock_filter, laser_session, lms2xx, p2os, p2os_client, scip2,
                                    scip2_commands, scip2_decoder, scip2_encoders, scip2_frames,
                                    scip2_values, stream],
                         ids=lambda m: m.__name__)
def test_module_is_pure(module):
    with open(module.__file__, encoding='utf-8') as f:
        tree = ast.parse(f.read())
    imported = {alias.name.split('.')[0] for node in ast.walk(tree)
                if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module.split('.')[0] for node in ast.walk(tree)
                 if isinstance(node, ast.ImportFrom)}
    assert imported <= ALLOWED, imported
