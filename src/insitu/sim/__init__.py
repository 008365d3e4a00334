"""The simulated rig: workpieces, scene ray casting, rendering and recorded sequences."""
