"""Fakes of real devices at their own interface (a C library, a USB backend, a serial peer)."""
