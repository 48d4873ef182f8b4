"""ISAC multi-UAV collaborative target tracking."""
