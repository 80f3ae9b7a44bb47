"""The simulated vehicle: plant, world, faults, and the session builder every simulated flight uses."""
