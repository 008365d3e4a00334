"""Locating a part lying flat on the table in a scan: its pose from a reference (mesh or scan)."""
