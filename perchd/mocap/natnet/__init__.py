"""NatNet (OptiTrack Motive): wire format, packet models, the client source and a server emulator."""
