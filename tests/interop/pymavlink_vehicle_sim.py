#!/usr/bin/env python3
"""Interoperability: pymavlink (the MAVLink reference implementation, what MAVProxy
and most ground stations are built on) flies skymesh's vehicle-sim.

Usage: pymavlink_vehicle_sim.py PORT
Exits non-zero with a message on the first thing that does not behave like
ArduCopter on the wire.
"""
import sys
import time

from pymavlink import mavutil

PORT = int(sys.argv[1])
m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{PORT}", source_system=255, source_component=190)


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


hb = m.wait_heartbeat(timeout=10)
if hb is None:
    fail("no HEARTBEAT")
if hb.autopilot != mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA or hb.type != mavutil.mavlink.MAV_TYPE_QUADROTOR:
    fail(f"heartbeat does not look like ArduCopter: {hb}")
print(f"heartbeat from system {m.target_system}: mode {m.flightmode}, MAVLink {'2' if m.WIRE_PROTOCOL_VERSION == '2.0' else '1'}")


def ack_for(command, timeout=5):
    deadline = time.time() + timeout
    while time.time() < deadline:
        a = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=deadline - time.time())
        if a is not None and a.command == command:
            return a
    fail(f"no COMMAND_ACK for command {command}")


def command(cmd, *params):
    p = list(params) + [0] * (7 - len(params))
    m.mav.command_long_send(m.target_system, m.target_component, cmd, 0, *p)
    a = ack_for(cmd)
    return a.result


# Stream rate through the standard interval command.
if command(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavutil.mavlink.MAVLINK_MSG_ID_ATTITUDE, 20000) != 0:
    fail("SET_MESSAGE_INTERVAL refused")
start, n = time.time(), 0
while time.time() - start < 2.0:
    if m.recv_match(type="ATTITUDE", blocking=True, timeout=1) is not None:
        n += 1
rate = n / 2.0
print(f"ATTITUDE at {rate:.0f} Hz after asking for 50 Hz")
if not 30 <= rate <= 70:
    fail(f"ATTITUDE rate {rate} Hz")

# ArduCopter refuses to arm in LAND, with a reason.
m.set_mode("LAND")
time.sleep(0.5)
if command(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavutil.mavlink.MAV_RESULT_ACCEPTED:
    fail("armed in LAND")

# pymavlink's own ArduCopter mode mapping: GUIDED by name.
m.set_mode("GUIDED")
deadline = time.time() + 5
while m.flightmode != "GUIDED" and time.time() < deadline:
    m.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
if m.flightmode != "GUIDED":
    fail(f"mode is {m.flightmode}, wanted GUIDED")

if command(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) != mavutil.mavlink.MAV_RESULT_ACCEPTED:
    fail("arming refused in GUIDED")
m.motors_armed_wait()
if command(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10) != mavutil.mavlink.MAV_RESULT_ACCEPTED:
    fail("takeoff refused")

deadline = time.time() + 30
alt = 0.0
while time.time() < deadline:
    g = m.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=2)
    if g is not None:
        alt = g.relative_alt / 1000.0
        if abs(alt - 10.0) < 0.5:
            break
else:
    fail(f"did not reach 10 m, last {alt:.2f} m")
print(f"took off to {alt:.2f} m")

# A GUIDED position target through SET_POSITION_TARGET_LOCAL_NED: 10 m north.
mask = 0b0000111111111000  # position only
m.mav.set_position_target_local_ned_send(0, m.target_system, m.target_component,
                                         mavutil.mavlink.MAV_FRAME_LOCAL_NED, mask,
                                         10, 0, -10, 0, 0, 0, 0, 0, 0, 0, 0)
deadline = time.time() + 30
while time.time() < deadline:
    p = m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=2)
    if p is not None and abs(p.x - 10) < 0.5 and abs(p.y) < 0.5:
        break
else:
    fail("did not reach the local position target")
print(f"reached local target x={p.x:.2f} y={p.y:.2f} z={p.z:.2f}")

if command(mavutil.mavlink.MAV_CMD_NAV_LAND) != mavutil.mavlink.MAV_RESULT_ACCEPTED:
    fail("land refused")
print("OK: pymavlink flew vehicle-sim")
