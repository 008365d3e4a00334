"""Device protocols and their backends: sim (the virtual rig), replay (recorded sequences)."""
