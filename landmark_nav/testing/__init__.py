"""Test support: run nodes in-process on an isolated DDS domain, feed bags, collect output."""

from .harness import declared_parameters, isolate_dds, parameter_file, RosHarness
from .shared_data import SHARED_DATA, shared_data

__all__ = ['declared_parameters', 'isolate_dds', 'parameter_file', 'RosHarness',
           'SHARED_DATA', 'shared_data']
