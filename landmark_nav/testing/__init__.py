"""Test support: run nodes in-process on an isolated DDS domain, feed bags, collect output."""

from .harness import isolate_dds, RosHarness

__all__ = ['RosHarness', 'isolate_dds']
