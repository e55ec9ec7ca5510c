"""The simulated twin (safepath.sim)."""
