"""Test support: run nodes in-process on an isolated DDS domain, feed bags, collect output."""

from .harness import declared_parameters, isolate_dds, parameter_file, RosHarness

__all__ = ['declared_parameters', 'isolate_dds', 'parameter_file', 'RosHarness']
