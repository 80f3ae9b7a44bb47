"""perchd: fly a vehicle onto a surface along a time-to-contact (tau) plan."""

__version__ = "0.1.0"
