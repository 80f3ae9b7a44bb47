"""The rigs `perchd bench` measures with: the agent's loop against synthetic and socket-fed
vehicles, and the CPU-load processes set beside it."""
