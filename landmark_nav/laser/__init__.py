"""Laser feature extraction: scan segmentation, corner detectors, line extractors."""
