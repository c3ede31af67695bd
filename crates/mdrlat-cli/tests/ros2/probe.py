#!/usr/bin/env python3
"""Drives `mdrlat ros2` through scripted phases as a robot's drivers and base would, over
Eclipse Cyclone DDS, and records its cmd_vel stream.

Usage: probe.py DOMAIN [--stamped]. Publishes a synthetic robot at 10 Hz (LaserScan of 720
beams over 270 degrees and 240x320 depth images with the sensor-data profile, reliable
odometry), phase by phase: good data, silence, each kind of malformed message followed by
good data again. Listens to cmd_vel with a reliable subscription, as a base does. Prints
PHASES_DONE, keeps the sensors fresh until stdin closes, then prints one JSON object: the
phases with their wall-clock bounds and every command received.
"""
import json
import math
import struct
import sys
import threading
import time

from cyclonedds.domain import DomainParticipant

from ros_types import (RELIABLE, SENSOR_DATA, BrokenLaserScan, Image, LaserScan, Odometry,
                       Twist, TwistStamped, listen_twists, reader, writer)

domain = int(sys.argv[1])
stamped = "--stamped" in sys.argv
dp = DomainParticipant(domain)
scan_pub = writer(dp, "/scan", LaserScan, SENSOR_DATA)
# A second participant: one participant cannot hold two types on one topic.
broken_pub = writer(DomainParticipant(domain), "/scan", BrokenLaserScan, SENSOR_DATA)
depth_pub = writer(dp, "/camera/depth/image_raw", Image, SENSOR_DATA)
odom_pub = writer(dp, "/odom", Odometry, RELIABLE)
cmd = reader(dp, "/cmd_vel", TwistStamped if stamped else Twist, RELIABLE)

twists = []
stop = threading.Event()


def listen():
    listen_twists(dp, cmd, stamped, stop, twists)


threading.Thread(target=listen, daemon=True).start()

# 240x320: Python's binding serialises a 640x480 float image in ~0.1 s, too slow for 10 Hz
# on a busy 2-core machine; the node area-resizes any size alike.
H, W = 240, 320
GOOD_DEPTH = struct.pack("<%df" % (H * W), *([2.5] * (H * W)))
GOOD_DEPTH_16 = struct.pack("<%dH" % (H * W), *([2500] * (H * W)))


def scan(kind):
    inc = 1.5 * math.pi / 719
    ranges = [3.0] * 720
    if kind == "scan-nan":
        ranges[100] = float("nan")
    if kind == "scan-inf":
        ranges[200] = float("inf")
    m = LaserScan(angle_min=-0.75 * math.pi, angle_max=-0.75 * math.pi + 719 * inc,
                  angle_increment=inc, range_min=0.15, range_max=12.0, ranges=ranges)
    m.header.frame_id = "laser"
    return m


def depth(kind):
    h, w, enc, step, data = H, W, "32FC1", W * 4, GOOD_DEPTH
    if kind == "depth-16uc1":
        enc, step, data = "16UC1", W * 2, GOOD_DEPTH_16
    if kind == "depth-length":
        data = GOOD_DEPTH[:-4]
    if kind == "depth-encoding":
        enc = "rgb8"
    if kind == "depth-width0":
        w, step, data = 0, 0, b""
    return Image(height=h, width=w, encoding=enc, step=step, data=data)


def publish(kind):
    if kind == "scan-bytes":
        broken_pub.write(BrokenLaserScan(angle_min=1.0, count=1_000_000))
    else:
        scan_pub.write(scan(kind))
    depth_pub.write(depth(kind))
    odom_pub.write(Odometry())


# Wait until the node drives (it subscribes, sees fresh data and publishes).
deadline = time.time() + 30
while time.time() < deadline and not any(t[1] or t[2] for t in twists):
    publish("good")
    time.sleep(0.1)

PHASES = [("good", 3.0), ("silent", 1.5), ("good", 1.5)]
for bad in ["scan-nan", "scan-inf", "scan-bytes", "depth-length", "depth-encoding",
            "depth-width0"]:
    PHASES += [(bad, 1.2), ("good", 1.2)]
PHASES += [("depth-16uc1", 1.5)]

phases = []
for name, seconds in PHASES:
    start = time.time()
    tick = start
    while time.time() < start + seconds:
        if name != "silent":
            publish(name)
        tick += 0.1  # a 10 Hz schedule, not 0.1 s after the work
        time.sleep(max(0.0, tick - time.time()))
    phases.append({"name": name, "start": start, "end": time.time()})

print("PHASES_DONE", flush=True)
# Keep sensors fresh while the test sends SIGTERM, so that a zero after it is the node's
# shutdown, not its watchdog.
done = threading.Event()


def keep_fresh():
    while not done.is_set():
        publish("good")
        time.sleep(0.1)


threading.Thread(target=keep_fresh, daemon=True).start()
sys.stdin.readline()
done.set()
time.sleep(0.5)
stop.set()
print(json.dumps({"phases": phases, "twists": twists}), flush=True)
