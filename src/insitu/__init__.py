"""insitu: in-situ structured-light measurement and laser marking with a 3-D galvo scan head."""

__version__ = "0.1.0"
