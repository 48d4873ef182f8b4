"""ISAC multi-UAV collaborative target tracking."""

__version__ = "0.1.0"
