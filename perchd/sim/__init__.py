"""The simulated vehicle: plant, world, faults, the sim:// driver, the vehicle family and real firmware in the loop."""
