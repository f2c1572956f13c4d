"""Heatmap detectors (PnLCalib-compatible networks). Import submodules explicitly;
this package does not import torch on import."""
