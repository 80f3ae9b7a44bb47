"""Vehicle links, installed as perchd.drivers: each turns SI Setpoints into a vehicle's units."""
