"""Models of the camera and the scan head: pure numpy, no devices."""
