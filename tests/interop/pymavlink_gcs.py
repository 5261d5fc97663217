#!/usr/bin/env python3
"""Interoperability: pymavlink (the MAVLink reference implementation that MAVProxy
and most ground stations are built on) acts as a ground station through
autopilot-link's MAVLink router, with vehicle-sim as the autopilot behind it.

Usage: pymavlink_gcs.py PORT   (autopilot-link's `udpin:127.0.0.1:PORT` endpoint)
Exits non-zero with a message on the first thing that does not work.
"""
import sys
import time

from pymavlink import mavutil

PORT = int(sys.argv[1])
VEHICLE = (1, 1)
m = mavutil.mavlink_connection(f"udpout:127.0.0.1:{PORT}", source_system=255, source_component=190)
last_hb = 0.0


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


def gcs_heartbeat():
    """Every second, as a ground station does; a udpin endpoint learns its peers this way."""
    global last_hb
    if time.time() - last_hb >= 1.0:
        last_hb = time.time()
        m.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)


def wait(what, pred, timeout=10):
    deadline = time.time() + timeout
    while time.time() < deadline:
        gcs_heartbeat()
        msg = m.recv_match(blocking=True, timeout=0.2)
        if msg is not None and msg.get_type() != "BAD_DATA" and pred(msg):
            return msg
    fail(f"no {what} within {timeout} s")


def src(msg):
    return (msg.get_srcSystem(), msg.get_srcComponent())


# Generous: autopilot-link and vehicle-sim may still be starting.
hb = wait("HEARTBEAT from system 1 component 1",
          lambda x: x.get_type() == "HEARTBEAT" and src(x) == VEHICLE, timeout=30)
if hb.autopilot != mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA or hb.type != mavutil.mavlink.MAV_TYPE_QUADROTOR:
    fail(f"vehicle heartbeat does not look like ArduCopter: {hb}")
m.target_system, m.target_component = VEHICLE
print(f"vehicle heartbeat through the router: mode {mavutil.mode_string_v10(hb)}, MAVLink {m.WIRE_PROTOCOL_VERSION}")
companion = wait("HEARTBEAT of autopilot-link (component 191)",
                 lambda x: x.get_type() == "HEARTBEAT" and src(x) == (1, 191))
if companion.type != mavutil.mavlink.MAV_TYPE_ONBOARD_CONTROLLER:
    fail(f"companion heartbeat type {companion.type}")
print("autopilot-link's own heartbeat (onboard controller, component 191) is visible too")


def command(cmd, *params):
    p = list(params) + [0] * (7 - len(params))
    m.mav.command_long_send(VEHICLE[0], VEHICLE[1], cmd, 0, *p)
    a = wait(f"COMMAND_ACK for command {cmd}", lambda x: x.get_type() == "COMMAND_ACK" and x.command == cmd)
    return a.result


# A COMMAND_ACK from the vehicle for a request made through the router.
if command(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavutil.mavlink.MAVLINK_MSG_ID_GPS_RAW_INT, 500000) \
        != mavutil.mavlink.MAV_RESULT_ACCEPTED:
    fail("SET_MESSAGE_INTERVAL refused")
print("COMMAND_ACK (SET_MESSAGE_INTERVAL) accepted")

# pymavlink's own ArduCopter mode mapping: LAND, then GUIDED by name; the vehicle's
# heartbeat follows.
for mode in ("LAND", "GUIDED"):
    m.set_mode(mode)
    custom = m.mode_mapping()[mode]
    hb = wait(f"a {mode} heartbeat",
              lambda x: x.get_type() == "HEARTBEAT" and src(x) == VEHICLE and x.custom_mode == custom)
    print(f"mode {mode}: heartbeat custom_mode {hb.custom_mode}")

# And the explicit command form, with its ack.
if command(mavutil.mavlink.MAV_CMD_DO_SET_MODE, mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
           m.mode_mapping()["GUIDED"]) != mavutil.mavlink.MAV_RESULT_ACCEPTED:
    fail("DO_SET_MODE GUIDED refused")
print("COMMAND_ACK (DO_SET_MODE GUIDED) accepted")

# Telemetry keeps flowing at the rate autopilot-link asked for.
start, n = time.time(), 0
while time.time() - start < 2.0:
    gcs_heartbeat()
    if m.recv_match(type="ATTITUDE", blocking=True, timeout=0.5) is not None:
        n += 1
print(f"ATTITUDE through the router at {n / 2.0:.0f} Hz")
if n < 20:
    fail(f"only {n} ATTITUDE in 2 s")
print("OK: pymavlink flew vehicle-sim through autopilot-link's router")
