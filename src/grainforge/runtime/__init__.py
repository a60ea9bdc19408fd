"""Processes, staging, estimates and clusters: how grainforge runs work."""
