"""The files of shared/spec/formats.md (recorded sequences, point clouds, jobs), with validation."""
