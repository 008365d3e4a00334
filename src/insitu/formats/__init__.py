"""The files insitu reads and writes (docs/formats.md), with validation."""
