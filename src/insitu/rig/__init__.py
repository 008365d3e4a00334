"""The rig as configured: which device backends to use and its calibration files."""
