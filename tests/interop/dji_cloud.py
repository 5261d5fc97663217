#!/usr/bin/env python3
"""A DJI Cloud API "cloud" built on paho-mqtt (a third-party client) flying skymesh's
DJI gateway through a third-party broker (mosquitto). Run by scripts/interop-dji.sh,
which starts mosquitto and the mesh and passes the ports, credentials and CA.

The cloud side of the document (../shared/specs/dji-cloud-live-flight-controls.md with
specs/FACTS.md): it publishes on thing/product/{sn}/services, events_reply and drc/down,
and reads services_reply, events and drc/up. Result codes are read from
protocols/dji-proto/src/codes.rs so this script and the gateway cannot drift.

Exits 0 when every check passed, 1 with a message naming the first mismatch.
"""

import argparse
import json
import math
import re
import sys
import threading
import time
import urllib.request
import uuid

import paho.mqtt.client as mqtt


class Mismatch(Exception):
    """The gateway did not do what the document (or skymesh's code table) says."""


def check(cond, what):
    if not cond:
        raise Mismatch(what)


def step(text):
    print(f"[{time.monotonic() - T0:6.2f}s] {text}", flush=True)


T0 = time.monotonic()


def now_ms():
    return int(time.time() * 1000)


def load_codes(path):
    """`pub const NAME: u32 = VALUE;` from codes.rs (VALUE may name another constant)."""
    raw = dict(re.findall(r"pub const (\w+): u32 = (\w+);", open(path, encoding="utf-8").read()))
    codes = {}
    for name, value in raw.items():
        while not value.isdigit():
            value = raw[value]
        codes[name] = int(value)
    for needed in ("OK", "UNKNOWN_METHOD", "WRONG_TYPE", "OUT_OF_RANGE", "MISSING_FIELD",
                   "FLIGHT_AUTHORITY_REQUIRED", "NO_FLIGHT_AUTHORITY", "SEQ_OUT_OF_ORDER", "STICK_STALE"):
        check(needed in codes, f"{path} has no {needed}")
    return codes


class Connection:
    """One paho connection (MQTT 3.1.1) that keeps every message it receives, in order."""

    def __init__(self, name, args, port, tls, password=None):
        self.name = name
        self.sn = args.sn
        self.cond = threading.Condition()
        self.messages = []  # (topic suffix, parsed JSON or None)
        self.connack = None
        self.subacks = set()
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2,
                                  client_id=f"{name}-{uuid.uuid4().hex[:8]}",
                                  protocol=mqtt.MQTTv311)
        self.client.username_pw_set(args.user, args.password if password is None else password)
        if tls:
            # Verifies the broker's certificate chain and its IP SAN (127.0.0.1).
            self.client.tls_set(ca_certs=args.ca)
        self.client.on_connect = self._on_connect
        self.client.on_subscribe = self._on_subscribe
        self.client.on_message = self._on_message
        self.host, self.port = args.host, port

    def _on_connect(self, _client, _userdata, _flags, reason_code, _properties):
        with self.cond:
            self.connack = reason_code
            self.cond.notify_all()

    def _on_subscribe(self, _client, _userdata, mid, _reason_codes, _properties):
        with self.cond:
            self.subacks.add(mid)
            self.cond.notify_all()

    def _on_message(self, _client, _userdata, msg):
        prefix = f"thing/product/{self.sn}/"
        suffix = msg.topic[len(prefix):] if msg.topic.startswith(prefix) else msg.topic
        try:
            body = json.loads(msg.payload)
        except ValueError:
            body = None
        self.handle(suffix, body)
        with self.cond:
            self.messages.append((suffix, body))
            self.cond.notify_all()

    def handle(self, suffix, body):
        """Hook for subclasses (runs on paho's network thread)."""

    def connect(self, timeout=5.0):
        """Connects; returns paho's CONNACK reason code (check `.is_failure`)."""
        self.client.connect(self.host, self.port, keepalive=30)
        self.client.loop_start()
        with self.cond:
            self.cond.wait_for(lambda: self.connack is not None, timeout)
        check(self.connack is not None, f"{self.name}: no CONNACK from the broker within {timeout} s")
        return self.connack

    def subscribe(self, suffixes):
        _rc, mid = self.client.subscribe([(f"thing/product/{self.sn}/{s}", 1) for s in suffixes])
        with self.cond:
            ok = self.cond.wait_for(lambda: mid in self.subacks, 5.0)
        check(ok, f"{self.name}: no SUBACK for {suffixes}")

    def publish(self, suffix, payload):
        if not isinstance(payload, (bytes, str)):
            payload = json.dumps(payload)
        self.client.publish(f"thing/product/{self.sn}/{suffix}", payload, qos=1)

    def mark(self):
        """A cursor: messages after this point."""
        with self.cond:
            return len(self.messages)

    def expect(self, suffix, pred, timeout, what, start=0):
        """The first message on `suffix` at or after `start` that satisfies `pred`."""
        deadline = time.monotonic() + timeout
        with self.cond:
            i = start
            while True:
                while i < len(self.messages):
                    s, body = self.messages[i]
                    i += 1
                    if s == suffix and body is not None and pred(body):
                        return body
                left = deadline - time.monotonic()
                if left <= 0:
                    raise Mismatch(f"{self.name}: no {what} on {suffix} within {timeout} s")
                self.cond.wait(left)

    def latest(self, suffix, pred):
        """The newest message on `suffix` that satisfies `pred` (it must exist)."""
        with self.cond:
            for s, body in reversed(self.messages):
                if s == suffix and body is not None and pred(body):
                    return body
        raise Mismatch(f"{self.name}: nothing received on {suffix} yet")

    def collect(self, suffix, pred, start=0):
        with self.cond:
            return [b for s, b in self.messages[start:] if s == suffix and b is not None and pred(b)]

    def close(self):
        self.client.disconnect()
        self.client.loop_stop()


class Cloud(Connection):
    """services → services_reply, events (answering need_reply on events_reply)."""

    def __init__(self, args):
        super().__init__("cloud", args, args.port, tls=False)
        self.events_answered = 0

    def handle(self, suffix, body):
        if suffix == "events" and isinstance(body, dict) and body.get("need_reply") == 1:
            self.publish("events_reply", {
                "tid": body.get("tid"), "bid": body.get("bid"), "method": body.get("method"),
                "gateway": self.sn, "timestamp": now_ms(), "data": {"result": 0},
            })
            self.events_answered += 1

    def call(self, method, data, timeout=10.0):
        """Publishes a service request; returns the reply's `data`."""
        tid = str(uuid.uuid4())
        self.publish("services", {"tid": tid, "bid": str(uuid.uuid4()), "timestamp": now_ms(),
                                  "method": method, "data": data})
        reply = self.expect("services_reply", lambda b: b.get("tid") == tid, timeout,
                            f"services_reply to {method}")
        check(reply.get("method") == method, f"{method}: reply names method {reply.get('method')!r}")
        check(reply.get("gateway") in (None, self.sn), f"{method}: reply from gateway {reply.get('gateway')!r}")
        check(isinstance(reply.get("data"), dict) and isinstance(reply["data"].get("result"), int),
              f"{method}: reply without an integer data.result: {reply}")
        return reply["data"]

    def expect_result(self, method, data, want, codes, timeout=10.0):
        got = self.call(method, data, timeout)["result"]
        check(got == codes[want], f"{method}: result {got}, expected {want} ({codes[want]})")
        return got

    def event(self, method, pred, timeout, start, what=None):
        body = self.expect("events", lambda b: b.get("method") == method and pred(b.get("data") or {}),
                           timeout, what or f"{method} event", start)
        return body["data"]


class DrcCloud(Connection):
    """drc/down → drc/up, over the broker's TLS listener."""

    def __init__(self, args):
        super().__init__("drc-cloud", args, args.tls_port, tls=True)

    def send(self, method, data):
        self.publish("drc/down", {"method": method, "data": data})

    def reply(self, method, pred, timeout, start, what=None):
        body = self.expect("drc/up", lambda b: b.get("method") == method and pred(b.get("data") or {}),
                           timeout, what or f"{method} on drc/up", start)
        return body["data"]

    def osd(self, timeout=3.0):
        """The newest osd_info_push, waiting for a fresh one."""
        return self.reply("osd_info_push", lambda d: "latitude" in d, timeout, self.mark(),
                          "osd_info_push")


def wait_for_mesh(status_file, timeout=60.0):
    deadline = time.monotonic() + timeout
    addr, last = None, None
    while time.monotonic() < deadline:
        try:
            addr = addr or open(status_file, encoding="utf-8").read().strip() or None
            if addr:
                with urllib.request.urlopen(f"http://{addr}/status", timeout=2) as r:
                    last = {s["name"]: s["state"] for s in json.load(r)}
                if all(last.get(n) == "running" for n in ("vehicle-sim", "autopilot-link", "shot-engine", "dji-gateway")):
                    return addr
        except (OSError, ValueError):
            pass
        time.sleep(0.2)
    raise Mismatch(f"mesh not running within {timeout} s (services: {last})")


def metrics(addr):
    with urllib.request.urlopen(f"http://{addr}/metrics", timeout=2) as r:
        return r.read().decode()


def offset_m(a, b):
    """(north, east) metres from fix a to fix b (dicts with latitude/longitude)."""
    r = 6_371_000.0
    north = math.radians(b["latitude"] - a["latitude"]) * r
    east = math.radians(b["longitude"] - a["longitude"]) * r * math.cos(math.radians(a["latitude"]))
    return north, east


def wrap_deg(d):
    """An angle difference in (−180, 180]."""
    return -((-d + 180.0) % 360.0 - 180.0)


def stick_stream(drc, first_seq, n, x=0.0, y=0.0, h=0.0, w=0.0):
    """`n` drone_control at 10 Hz from `first_seq`; returns the next seq."""
    start = time.monotonic()
    for k in range(n):
        drc.send("drone_control", {"seq": first_seq + k, "x": x, "y": y, "h": h, "w": w})
        time.sleep(max(0.0, start + (k + 1) * 0.1 - time.monotonic()))
    return first_seq + n


def expect_accepted(drc, mark, seqs):
    """Every drone_control of `seqs` (sent after `mark`) was answered result 0."""
    want = set(seqs)
    deadline = time.monotonic() + 3.0
    while True:
        replies = drc.collect("drc/up", lambda b: b.get("method") == "drone_control", mark)
        ok = {(b["data"].get("output") or {}).get("seq") for b in replies if b["data"].get("result") == 0}
        missing = sorted(want - ok)
        if not missing:
            return
        check(time.monotonic() < deadline,
              f"drone_control not answered 0 for seq {missing[:10]}: "
              f"{[b['data'] for b in replies if (b['data'].get('output') or {}).get('seq') in missing][:5]}")
        time.sleep(0.1)


def hostile_services(cloud, codes):
    step("hostile payloads on services: malformed JSON, no tid, oversized, deep nesting, wrong types")
    for raw in (b'{"tid": "x", "bid": ', b"\xff\xfe not json", b"[1, 2, 3]",
                json.dumps({"bid": "b", "timestamp": now_ms(), "method": "flight_authority_grab",
                            "data": {}}).encode(),
                b'{"tid":"t","bid":"b","timestamp":1,"method":"flight_authority_grab","data":"'
                + b"x" * 70_000 + b'"}',
                b"[" * 30_000 + b"]" * 30_000):
        cloud.publish("services", raw)
    bad = {
        # A string where the document says double.
        "WRONG_TYPE": ("takeoff_to_point", takeoff_request(0.0, 0.0, 600.0, target_latitude="north")),
        # Latitude above 90.
        "OUT_OF_RANGE": ("takeoff_to_point", takeoff_request(91.0, 0.0, 600.0)),
        # drc_mode_enter without its broker.
        "MISSING_FIELD": ("drc_mode_enter", {"osd_frequency": 10, "hsi_frequency": 1}),
    }
    for code, (method, data) in bad.items():
        cloud.expect_result(method, data, code, codes)
        step(f"  {method} with a bad field → {code} ({codes[code]})")


def takeoff_request(lat, lon, height, **override):
    data = {
        "target_latitude": lat, "target_longitude": lon, "target_height": height,
        "security_takeoff_height": 20, "rth_altitude": 30, "rc_lost_action": 0,
        "commander_mode_lost_action": 1, "commander_flight_height": 20,
        "flight_id": str(uuid.uuid4()), "max_speed": 5,
    }
    data.update(override)
    return data


def drc_enter_request(args, password):
    return {
        "mqtt_broker": {
            "address": f"{args.host}:{args.tls_port}", "client_id": f"drc-{args.sn}",
            "username": args.user, "password": password, "expire_time": int(time.time()) + 3600,
            "enable_tls": True,
        },
        "osd_frequency": 10, "hsi_frequency": 1,
    }


def scenario(args, codes):
    step("waiting for the mesh (vehicle-sim, autopilot-link, shot-engine, dji-gateway)")
    addr = wait_for_mesh(args.status_file)

    step("mosquitto refuses a wrong password")
    intruder = Connection("intruder", args, args.port, tls=False, password="wrong-" + args.password)
    rc = intruder.connect()
    intruder.close()
    check(rc.is_failure, f"mosquitto accepted a wrong password (CONNACK {rc})")

    cloud = Cloud(args)
    rc = cloud.connect()
    check(not rc.is_failure, f"cloud: mosquitto refused the right password (CONNACK {rc})")
    cloud.subscribe(["services_reply", "events"])

    step("waiting for the gateway on mosquitto: an unknown method is answered UNKNOWN_METHOD")
    deadline = time.monotonic() + 30
    while True:
        try:
            got = cloud.call("skymesh_interop_no_such_method", {}, timeout=1.0)["result"]
            break
        except Mismatch:
            if time.monotonic() > deadline:
                raise
    check(got == codes["UNKNOWN_METHOD"], f"unknown method: result {got}, expected {codes['UNKNOWN_METHOD']}")

    home_lat, home_lon, home_alt = args.home
    # 12 m north of home, 20 m up; heights are ellipsoidal (the mesh's geoid undulation is 0).
    target_lat = home_lat + math.degrees(12.0 / 6_371_000.0)
    takeoff = takeoff_request(target_lat, home_lon, home_alt + 20.0)
    step("takeoff_to_point without flight authority → FLIGHT_AUTHORITY_REQUIRED")
    cloud.expect_result("takeoff_to_point", takeoff, "FLIGHT_AUTHORITY_REQUIRED", codes)

    hostile_services(cloud, codes)

    step("flight_authority_grab → 0 (the gateway still serves after the hostile input)")
    cloud.expect_result("flight_authority_grab", {}, "OK", codes)

    step("takeoff_to_point 12 m north at 20 m → 0, then progress events until success")
    mark = cloud.mark()
    cloud.expect_result("takeoff_to_point", takeoff, "OK", codes, timeout=15.0)
    final = cloud.event("takeoff_to_point_progress",
                        lambda d: d.get("status") in ("wayline_ok", "task_finish", "wayline_failed",
                                                      "wayline_cancel"),
                        45.0, mark, "a final takeoff_to_point_progress")
    statuses = [b["data"].get("status") for b in
                cloud.collect("events", lambda b: b.get("method") == "takeoff_to_point_progress", mark)]
    step(f"  takeoff_to_point_progress: {' → '.join(dict.fromkeys(statuses))}")
    check(final.get("status") in ("wayline_ok", "task_finish") and final.get("result") == 0,
          f"takeoff_to_point ended {final}")

    drc = DrcCloud(args)
    rc = drc.connect()
    check(not rc.is_failure, f"drc-cloud: mosquitto (TLS) refused the connection (CONNACK {rc})")
    drc.subscribe(["drc/up"])

    step("drc_mode_enter with a wrong password → non-zero result (the broker refuses the gateway)")
    got = cloud.call("drc_mode_enter", drc_enter_request(args, "wrong-" + args.password), timeout=15.0)["result"]
    check(got != 0, "drc_mode_enter succeeded with a wrong password")
    step(f"  result {got}")

    step("drc_mode_enter naming mosquitto's TLS listener → 0 and drc_status_notify 2")
    mark = cloud.mark()
    cloud.expect_result("drc_mode_enter", drc_enter_request(args, args.password), "OK", codes, timeout=15.0)
    cloud.event("drc_status_notify", lambda d: d.get("drc_state") == 2 and d.get("result") == 0,
                5.0, mark, "drc_status_notify with drc_state 2")

    step("heart_beat is echoed on drc/up")
    mark = drc.mark()
    stamp = now_ms()
    drc.send("heart_beat", {"seq": 1, "timestamp": stamp})
    drc.reply("heart_beat", lambda d: d.get("seq") == 1 and d.get("timestamp") == stamp, 5.0, mark,
              "heart_beat echo")

    step("hostile payloads on drc/down: malformed JSON, unknown method, out-of-range stick")
    mark = drc.mark()
    drc.publish("drc/down", b'{"method": "drone_control", "data": {')
    drc.send("skymesh_interop_no_such_method", {})
    got = drc.reply("skymesh_interop_no_such_method", lambda d: "result" in d, 5.0, mark)["result"]
    check(got == codes["UNKNOWN_METHOD"], f"drc unknown method: result {got}")
    drc.send("drone_control", {"seq": 0, "x": 0.0, "y": 99.0, "h": 0.0, "w": 0.0})
    got = drc.reply("drone_control", lambda d: "result" in d, 5.0, mark)["result"]
    check(got == codes["OUT_OF_RANGE"], f"drone_control y=99: result {got}, expected OUT_OF_RANGE")

    step("drone_control at 10 Hz: turn clockwise 30°/s for 2 s, then forward 3 m/s for 3 s")
    before = drc.osd()
    mark = drc.mark()
    seq = stick_stream(drc, 1, 20, w=30.0)
    turned = drc.latest("drc/up", lambda b: b.get("method") == "osd_info_push")["data"]
    seq = stick_stream(drc, seq, 30, y=3.0)
    step("a lower seq → SEQ_OUT_OF_ORDER (319033)")
    drc.send("drone_control", {"seq": 5, "x": 0.0, "y": 3.0, "h": 0.0, "w": 0.0})
    got = drc.reply("drone_control", lambda d: (d.get("output") or {}).get("seq") == 5
                    and d.get("result") != 0, 5.0, mark, "drone_control reply to seq 5 (lower)")
    check(got["result"] == codes["SEQ_OUT_OF_ORDER"], f"lower seq: result {got['result']}")
    expect_accepted(drc, mark, range(1, seq))
    osd_count = len(drc.collect("drc/up", lambda b: b.get("method") == "osd_info_push", mark))
    step(f"  {seq - 1} × result 0; {osd_count} osd_info_push during the 5 s stream (asked 10 Hz)")
    check(osd_count >= 15, f"only {osd_count} osd_info_push in 5 s at osd_frequency 10")

    time.sleep(2.0)  # the stream stopped: the gateway brakes; let the vehicle settle
    after = drc.osd()
    turn = wrap_deg(after["attitude_head"] - before["attitude_head"])
    step(f"  heading {before['attitude_head']:.1f}° → {after['attitude_head']:.1f}° ({turn:+.1f}°)")
    check(30.0 < turn < 90.0, f"turned {turn:+.1f}° (30°/s clockwise for 2 s asked)")
    # Forward is the nose's direction while flying straight (between the turn's end and now).
    heading = turned["attitude_head"] + wrap_deg(after["attitude_head"] - turned["attitude_head"]) / 2
    north, east = offset_m(turned, after)
    h = math.radians(heading)
    forward = north * math.cos(h) + east * math.sin(h)
    lateral = -north * math.sin(h) + east * math.cos(h)
    step(f"  moved {forward:.1f} m forward, {lateral:+.1f} m sideways (heading {heading:.1f}°)")
    check(forward > 6.0, f"the vehicle moved only {forward:.1f} m forward (3 m/s for 3 s asked)")
    check(abs(lateral) < 2.0, f"the vehicle drifted {lateral:.1f} m sideways")

    step("the next drone_control after the stream went stale → STICK_STALE (319034)")
    mark = drc.mark()
    drc.send("drone_control", {"seq": seq, "x": 0.0, "y": 0.0, "h": 0.0, "w": 0.0})
    got = drc.reply("drone_control", lambda d: (d.get("output") or {}).get("seq") == seq, 5.0, mark)["result"]
    check(got == codes["STICK_STALE"], f"stale stream: result {got}, expected {codes['STICK_STALE']}")

    step("seq 0 restarts the stream: forward 3 m/s for 1.5 s, the vehicle moves")
    mark = drc.mark()
    seq = stick_stream(drc, 0, 15, y=3.0)
    expect_accepted(drc, mark, range(0, seq))
    moving = drc.osd()
    check(math.hypot(moving["speed_x"], moving["speed_y"]) > 1.0, f"not moving forward again: {moving}")

    step("drone_emergency_stop while the sticks still push forward → 0; the vehicle stops")
    mark = drc.mark()
    drc.send("drone_emergency_stop", {})
    seq = stick_stream(drc, seq, 30, y=3.0)
    got = drc.reply("drone_emergency_stop", lambda d: "result" in d, 5.0, mark)["result"]
    check(got == 0, f"drone_emergency_stop: result {got}")
    o = drc.osd()
    speed = math.hypot(o["speed_x"], o["speed_y"])
    step(f"  3 s later: {speed:.2f} m/s horizontal, {o['speed_z']:+.2f} m/s vertical")
    check(speed < 0.3 and abs(o["speed_z"]) < 0.3, f"not hovering 3 s after the emergency stop: {o}")
    refused = drc.collect("drc/up", lambda b: b.get("method") == "drone_control"
                          and b["data"].get("result") == codes["NO_FLIGHT_AUTHORITY"], mark)
    step(f"  {len(refused)} of the 30 sticks after it refused NO_FLIGHT_AUTHORITY (safety holds the vehicle)")
    check(len(refused) >= 20, "the sticks after the emergency stop were not refused NO_FLIGHT_AUTHORITY")

    step("drc_mode_exit → 0 and drc_status_notify 0")
    mark = cloud.mark()
    cloud.expect_result("drc_mode_exit", {}, "OK", codes)
    cloud.event("drc_status_notify", lambda d: d.get("drc_state") == 0, 5.0, mark,
                "drc_status_notify with drc_state 0")
    drc.close()

    # The dropped payloads are counted (by kind): the gateway's counters reach /metrics
    # through its 1 Hz stats sample. 6 were sent on services, 1 on drc/down.
    deadline = time.monotonic() + 5.0
    while True:
        counted = {}
        for name, labels, value in re.findall(
                r"^(skymesh_dji_malformed_total|skymesh_dji_drc_malformed_total)\{([^}]*)\} (\S+)$",
                metrics(addr), re.M):
            kind = re.search(r'(?:kind|reason)="([^"]*)"', labels)
            key = f"{'drc/down' if '_drc_' in name else 'services'} {kind.group(1) if kind else '?'}"
            counted[key] = counted.get(key, 0) + float(value)
        services = sum(v for k, v in counted.items() if k.startswith("services"))
        drc_down = sum(v for k, v in counted.items() if k.startswith("drc/down"))
        if services >= 6 and drc_down >= 1:
            break
        check(time.monotonic() < deadline,
              f"malformed payloads not counted: {counted} (6 sent on services, 1 on drc/down)")
        time.sleep(0.5)
    step(f"  malformed payloads counted by the gateway: {counted}")
    step(f"events answered on events_reply: {cloud.events_answered}")
    cloud.close()


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, required=True, help="mosquitto's plain listener")
    p.add_argument("--tls-port", type=int, required=True, help="mosquitto's TLS listener")
    p.add_argument("--ca", required=True, help="the CA that signed the TLS listener's certificate")
    p.add_argument("--user", required=True)
    p.add_argument("--password", required=True)
    p.add_argument("--sn", required=True, help="the gateway's gateway_sn")
    p.add_argument("--home", type=float, nargs=3, required=True, metavar=("LAT", "LON", "ALT_MSL"))
    p.add_argument("--status-file", required=True, help="the supervisor's --status-file")
    p.add_argument("--codes", required=True, help="protocols/dji-proto/src/codes.rs")
    args = p.parse_args()
    try:
        scenario(args, load_codes(args.codes))
    except Mismatch as e:
        print(f"dji interop FAILED: {e}", file=sys.stderr, flush=True)
        return 1
    print("dji interop: mosquitto + paho-mqtt flew vehicle-sim through the DJI gateway", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
