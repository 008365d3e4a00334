"""3-D measurement: camera rays against the scan head's light planes."""
