"""What every part of perchd shares: SI value types, clocks, errors, URIs, the run-time context."""
