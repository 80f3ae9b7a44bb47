"""The cf2 (Crazyflie SITL firmware) socket protocol: one CRTP packet per UDP datagram.

Byte 0 is the CRTP header (port = hdr >> 4, channel = hdr & 3; bits 2-3 are reserved, the
firmware ignores them and cflib sets them, so classify with `hdr & 0xF3`), the rest is the
payload, 30 bytes at most (src/modules/interface/crtp.h). No length, no checksum.

Physics -> firmware (port 9, the simulator port, src/hal/src/sensors_sitl.c):
    IMU   <BB6h: 0x90, 0, acc x y z [1/2048 g], gyro x y z [4000/65536 deg/s], body FLU;
          the accelerometer reads specific force (+1 g on z at rest)
    baro  <BBfff: 0x90, 2, pressure [mbar], temperature [C], altitude [m]
Physics -> firmware, ordinary CRTP (src/modules/src/crtp_localization_service.c):
    pose  <BB7f: 0x61 (port 6 ch 1), 8 (EXT_POSE), x y z [m], qx qy qz qw (world, Z up)
Firmware -> physics:
    motors <B4H: 0x90, m1..m4 PWM 0..65535 (src/modules/src/power_distribution_sitl.c)
    calibrated: the 2 bytes [0x90, 0x01], once, when the gyro bias is found
    handshake: the 1 byte 0xF3, answered with 0xF3 (src/hal/src/socketlink.c)
    anything else: CRTP for the client (cflib)
"""

from __future__ import annotations

import enum
import math
import struct

HANDSHAKE = b"\xf3"
"""cf2's hello and our answer (the CRTP null header, no payload)."""
PROBE = b"\xff"
"""cflib's udp:// scan probe; any reply means "a Crazyflie is here"."""
MAX_DATAGRAM = 31
"""[bytes] header + 30 payload: cf2 truncates anything longer."""

SIM_HEADER = 0x90  # port 9 channel 0
EXTPOSE_HEADER = 0x61  # port 6 (localization) channel 1 (generic)
IMU_TYPE, BARO_TYPE, EXTPOSE_TYPE = 0, 2, 8

G_IMU = 9.81
"""[m/s^2] gravity in the accelerometer scale (CrazySim's plugin converts with 9.81)."""
ACC_LSB_G = 32.0 / 65536.0
"""[g per LSB] +-16 g in int16."""
GYRO_LSB_DPS = 4000.0 / 65536.0
"""[deg/s per LSB] +-2000 deg/s in int16."""

_IMU = struct.Struct("<BB6h")
_BARO = struct.Struct("<BBfff")
_POSE = struct.Struct("<BB7f")
_MOTORS = struct.Struct("<B4H")


class Kind(enum.Enum):
    """What a datagram from cf2 is."""

    HANDSHAKE = "handshake"
    MOTORS = "motors"
    CALIBRATED = "calibrated"
    CLIENT = "client"  # CRTP for cflib: forwarded


_ACC_SCALE = 1.0 / (G_IMU * ACC_LSB_G)  # LSB per m/s^2
_GYRO_SCALE = 180.0 / math.pi / GYRO_LSB_DPS  # LSB per rad/s


def imu_packet(
    acc_mps2: tuple[float, float, float], gyro_rads: tuple[float, float, float]
) -> bytes:
    """Specific force [m/s^2] and body rates [rad/s], body FLU; rounded and clipped to
    int16 (the plugin's cast wraps around; a clip saturates, as a sensor does). Sent 1000
    times a second, so written out rather than looped."""
    ax, ay, az = acc_mps2
    gx, gy, gz = gyro_rads
    a, g = _ACC_SCALE, _GYRO_SCALE
    return _IMU.pack(
        SIM_HEADER,
        IMU_TYPE,
        max(-32768, min(32767, round(ax * a))),
        max(-32768, min(32767, round(ay * a))),
        max(-32768, min(32767, round(az * a))),
        max(-32768, min(32767, round(gx * g))),
        max(-32768, min(32767, round(gy * g))),
        max(-32768, min(32767, round(gz * g))),
    )


def decode_imu(data: bytes) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Inverse of imu_packet (to the LSB): ([m/s^2] x3, [rad/s] x3)."""
    _, _, *raw = _IMU.unpack(data)
    return (
        tuple(c * ACC_LSB_G * G_IMU for c in raw[:3]),  # type: ignore[return-value]
        tuple(math.radians(c * GYRO_LSB_DPS) for c in raw[3:]),
    )


def baro_packet(pressure_mbar: float, temperature_c: float, altitude_m: float) -> bytes:
    return _BARO.pack(SIM_HEADER, BARO_TYPE, pressure_mbar, temperature_c, altitude_m)


def pressure_mbar(altitude_m: float) -> float:
    """[mbar] standard atmosphere at an altitude above sea level [m]."""
    return 1013.25 * (1.0 - 2.25577e-5 * altitude_m) ** 5.25588


def extpose_packet(p: tuple[float, float, float], q: tuple[float, float, float, float]) -> bytes:
    """World position [m] and attitude (x, y, z, w), Z up."""
    return _POSE.pack(EXTPOSE_HEADER, EXTPOSE_TYPE, *p, *q)


def classify(data: bytes) -> Kind:
    """Sort a datagram from cf2 (motor packets are exactly 9 bytes on port 9 channel 0)."""
    if data == HANDSHAKE:
        return Kind.HANDSHAKE
    if data and data[0] & 0xF3 == SIM_HEADER:
        if len(data) == _MOTORS.size:
            return Kind.MOTORS
        if len(data) == 2 and data[1] == 0x01:
            return Kind.CALIBRATED
    return Kind.CLIENT


def decode_motors(data: bytes) -> tuple[int, int, int, int]:
    """m1..m4 PWM (0..65535) of a motor packet."""
    return _MOTORS.unpack(data)[1:]  # type: ignore[return-value]


def motors_packet(m1: int, m2: int, m3: int, m4: int) -> bytes:
    """What cf2 sends (for test doubles of the firmware)."""
    return _MOTORS.pack(SIM_HEADER, m1, m2, m3, m4)
