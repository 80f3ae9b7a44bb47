"""cf2's packets (perchd.sim.firmware.cf2wire) against bytes worked out by hand from the
firmware's layouts (src/hal/src/sensors_sitl.c, power_distribution_sitl.c,
crtp_localization_service.c)."""

from __future__ import annotations

import math
import struct

import pytest

from perchd.sim.firmware import cf2wire as wire


def test_an_imu_sample_at_rest_reads_plus_one_g_on_z_as_2048():
    # 9.81 m/s^2 / 9.81 / (32 / 65536) = 2048 = 0x0800, little-endian 00 08
    assert wire.imu_packet((0.0, 0.0, 9.81), (0.0, 0.0, 0.0)) == bytes.fromhex(
        "90 00 0000 0000 0008 0000 0000 0000"
    )


def test_gyro_lsbs_are_4000_over_65536_degrees_per_second():
    # 1 rad/s = 57.29578 deg/s / 0.06103516 = 938.7 -> 939 = 0x03AB; -0.5 rad/s -> -469 = 0xFE2B
    pk = wire.imu_packet((0.0, 0.0, 0.0), (1.0, -0.5, 0.0))
    assert pk[8:14] == bytes.fromhex("AB03 2BFE 0000")


def test_accelerations_are_signed_per_axis_and_clipped_at_16_g():
    # -4.905 m/s^2 = -0.5 g = -1024 = 0xFC00; 20 g clips to 32767 = 0x7FFF
    pk = wire.imu_packet((-4.905, 20 * 9.81, -20 * 9.81), (0.0, 0.0, 100.0))
    assert pk[2:8] == bytes.fromhex("00FC FF7F 0080")
    assert pk[12:14] == bytes.fromhex("FF7F")  # 100 rad/s is beyond 2000 deg/s: clipped


def test_imu_decodes_back_to_the_lsb():
    acc, gyro = wire.decode_imu(wire.imu_packet((0.1, -2.0, 9.7), (0.01, -0.2, 3.0)))
    assert acc == pytest.approx((0.1, -2.0, 9.7), abs=9.81 * 32 / 65536)
    assert gyro == pytest.approx((0.01, -0.2, 3.0), abs=math.radians(4000 / 65536))


def test_the_external_pose_is_port_6_channel_1_type_8_with_seven_floats():
    pk = wire.extpose_packet((1.0, -2.0, 0.5), (0.0, 0.0, 0.0, 1.0))
    assert len(pk) == 30 <= wire.MAX_DATAGRAM
    assert pk[:2] == bytes([0x61, 8])
    assert pk[2:6] == bytes.fromhex("0000803F")  # 1.0f
    assert pk[6:10] == bytes.fromhex("000000C0")  # -2.0f
    assert pk[26:30] == bytes.fromhex("0000803F")  # qw last


def test_the_barometer_packet_is_type_2_with_three_floats():
    pk = wire.baro_packet(1013.25, 25.0, 0.0)
    assert pk[:2] == bytes([0x90, 2]) and len(pk) == 14
    assert struct.unpack("<fff", pk[2:]) == pytest.approx((1013.25, 25.0, 0.0))
    assert wire.pressure_mbar(0.0) == pytest.approx(1013.25)
    assert wire.pressure_mbar(100.0) == pytest.approx(1001.3, abs=0.1)  # ~12 Pa per metre


def test_motor_packets_decode_little_endian_pwm():
    data = bytes.fromhex("90 1027 204E 3075 FFFF")  # 10000, 20000, 30000, 65535
    assert wire.classify(data) is wire.Kind.MOTORS
    assert wire.decode_motors(data) == (10000, 20000, 30000, 65535)
    assert wire.motors_packet(10000, 20000, 30000, 65535) == data


@pytest.mark.parametrize(
    "data, kind",
    [
        (b"\xf3", wire.Kind.HANDSHAKE),
        (bytes.fromhex("90 0000 0000 0000 0000"), wire.Kind.MOTORS),
        (bytes.fromhex("9C 0000 0000 0000 0000"), wire.Kind.MOTORS),  # reserved bits set
        (bytes.fromhex("9001"), wire.Kind.CALIBRATED),
        (bytes.fromhex("9C01"), wire.Kind.CALIBRATED),
        (bytes.fromhex("9000"), wire.Kind.CLIENT),
        (bytes.fromhex("FC 7064"), wire.Kind.CLIENT),  # a link echo for cflib
        (bytes.fromhex("91 0000 0000 0000 0000"), wire.Kind.CLIENT),  # port 9 channel 1
        (bytes.fromhex("30" + "00" * 14), wire.Kind.CLIENT),
    ],
    ids=[
        "hello",
        "motors",
        "motors-reserved",
        "calibrated",
        "calibrated-reserved",
        "port9-other",
        "echo",
        "port9-ch1",
        "rpyt",
    ],
)
def test_datagrams_from_the_firmware_are_sorted_by_header_and_length(data, kind):
    assert wire.classify(data) is kind
