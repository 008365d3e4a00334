"""Image processing: laser line centres and spots."""
