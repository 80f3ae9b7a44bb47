"""Firmware in the loop (docs/firmware.md): a vehicle's own firmware in its own process,
flown by perchd over its real link, with the true state published as mocap.

    harness.py    what every firmware shares: FirmwareVehicle, ProcessGroup, TruthPublisher
    cf2.py        the Crazyflie's SITL firmware against our physics (1 kHz, real time)
    quadrotor.py  that physics: a rigid-body quadrotor with CrazySim's Crazyflie model
    cf2wire.py    cf2's socket protocol: packet encoders and decoders
    relay.py      cflib's udp:// link to the firmware, through the physics' socket
"""
