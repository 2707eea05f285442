"""Offline evaluation against the simulator's ground truth (pure numpy)."""
