"""The autopilot parameters checked at connect, each dialect's (drivers/mavlink/params.py,
ardupilot.py, px4.py): refused by name before any mode change, or set with configure=1;
real pymavlink over loopback UDP against a vehicle double."""

from __future__ import annotations

import logging
import re

import pytest

pytest.importorskip("pymavlink")

from mavlink_double import ARDUPILOT, PX4, SAFE_PARAMS, VehicleDouble, connected

from perchd.core.errors import ConfigError


def test_ardupilot_without_thrust_as_thrust_is_refused_before_any_mode_change():
    v = VehicleDouble(ARDUPILOT, params={"GUID_OPTIONS": 4.0, "MOT_THST_HOVER": 0.35})
    try:
        with pytest.raises(ConfigError, match=r"GUID_OPTIONS=4 lacks bit 3.*GUID_OPTIONS=12"):
            connected(v)
        assert v.modes == []
    finally:
        v.close()


@pytest.mark.parametrize(
    "autopilot, params, named",
    [
        (
            PX4,
            {"COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 0.0},
            [
                r"COM_OF_LOSS_T=1 \(wanted <= 0.3 s\)",
                r"COM_OBL_RC_ACT=0 \(wanted 4 \(Land\) or 5 \(Hold\)\)",
            ],
        ),
        (PX4, {"COM_OBL_RC_ACT": 3.0}, [r"COM_OBL_RC_ACT=3 \(wanted"]),  # Return
        (
            ARDUPILOT,
            {"GUID_TIMEOUT": 3.0, "FS_GCS_ENABLE": 1.0, "FS_GCS_TIMEOUT": 5.0},
            [
                r"GUID_TIMEOUT=3 \(wanted <= 0.5 s\)",
                r"FS_GCS_ENABLE=1 \(wanted 5 \(Land\)\)",
                r"FS_GCS_TIMEOUT=5 \(wanted <= 2 s\)",
            ],
        ),
        # the EKF ignores the mocap (docs/firmware.md, "Mocap to the autopilot"), boosts thrust
        (
            ARDUPILOT,
            {"VISO_TYPE": 0.0, "EK3_SRC1_POSXY": 3.0, "EK3_SRC1_POSZ": 1.0, "EK3_SRC1_YAW": 1.0},
            [
                r"VISO_TYPE=0 \(wanted 1 \(MAVLink\)\)",
                r"EK3_SRC1_POSXY=3 \(wanted 6 \(ExternalNav\)\)",
                r"EK3_SRC1_POSZ=1 \(wanted 6",
                r"EK3_SRC1_YAW=1 \(wanted 6",
            ],
        ),
        (
            PX4,
            {"EKF2_EV_CTRL": 0.0, "EKF2_HGT_REF": 1.0},
            [
                r"EKF2_EV_CTRL=0 \(wanted bits 0, 1 and 3 set",
                r"EKF2_HGT_REF=1 \(wanted 3 \(vision\)\)",
            ],
        ),
        (PX4, {"EKF2_EV_CTRL": 3.0}, [r"EKF2_EV_CTRL=3 \(wanted"]),  # position but not yaw
        (ARDUPILOT, {"ATC_ANGLE_BOOST": 1.0}, [r"ATC_ANGLE_BOOST=1 \(wanted 0"]),
    ],
)
def test_unsafe_autopilot_parameters_are_refused_by_name_before_any_mode_change(
    autopilot, params, named
):
    v = VehicleDouble(autopilot, params={**SAFE_PARAMS[autopilot], **params})
    try:
        with pytest.raises(ConfigError, match="unsafe autopilot parameters") as err:
            connected(v)
        for pattern in named:
            assert re.search(pattern, str(err.value)), str(err.value)
        assert "configure=1" in str(err.value) and v.modes == []
    finally:
        v.close()


@pytest.mark.parametrize(
    "autopilot, params, wanted",
    [
        (
            PX4,
            {"COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 0.0},
            {"COM_OF_LOSS_T": 0.3, "COM_OBL_RC_ACT": 4.0},
        ),
        (
            ARDUPILOT,
            {"GUID_TIMEOUT": 3.0, "FS_GCS_ENABLE": 0.0, "FS_GCS_TIMEOUT": 5.0},
            {"GUID_TIMEOUT": 0.5, "FS_GCS_ENABLE": 5.0, "FS_GCS_TIMEOUT": 2.0},
        ),
    ],
)
def test_configure_sets_the_failsafe_parameters_reads_them_back_and_logs_them(
    autopilot, params, wanted, caplog
):
    v = VehicleDouble(autopilot, params={**SAFE_PARAMS[autopilot], **params})
    try:
        with caplog.at_level(logging.WARNING, logger="perchd.drivers.mavlink"):
            drv = connected(v, "&configure=1")
        drv.close()
        assert dict(v.param_sets) == pytest.approx(wanted)  # PX4's integer went bytewise
        assert {k: v.params[k] for k in wanted} == pytest.approx(wanted)
        for name in wanted:
            assert f"set {name} from" in caplog.text
    finally:
        v.close()
