"""Motion-capture pose sources (NatNet, ZMQ, simulator), chosen by URI scheme."""
