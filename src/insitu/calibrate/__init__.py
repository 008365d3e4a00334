"""Calibrations fitted from measurements. The scan-field correction: :mod:`.field` (RBF network
and correction table, their cross-validation and inverse), :mod:`.field_file` (the file the
scan-head driver reads, ``correction_from_file``) and :mod:`.report` (quiver report).

Kept free of imports so that each calibration module loads only what it needs."""
