#!/usr/bin/env python3
"""Drives `mdrlat ros` through scripted phases with rospy and records its Twist stream.

Run by tests/ros.rs with Debian's /usr/bin/python3 (rospy). Publishes a synthetic robot
(LaserScan of 720 beams over 270 degrees, 480x640 depth images, odometry) at 10 Hz, phase by
phase: good data, silence, and each kind of malformed message followed by good data again.
Prints PHASES_DONE when done, keeps recording until stdin closes, then prints one JSON
object: the phases with their wall-clock bounds and every Twist received.
"""
import json
import math
import struct
import sys
import threading
import time

import rospy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, LaserScan

rospy.init_node("probe", disable_signals=True)
twists = []
rospy.Subscriber("/cmd_vel", Twist, lambda m: twists.append((time.time(), m.linear.x, m.angular.z)))
scan_pub = rospy.Publisher("/scan", LaserScan, queue_size=1)
depth_pub = rospy.Publisher("/camera/depth/image_raw", Image, queue_size=1)
odom_pub = rospy.Publisher("/odom", Odometry, queue_size=1)

GOOD_DEPTH = struct.pack("<%df" % (480 * 640), *([2.5] * (480 * 640)))
GOOD_DEPTH_16 = struct.pack("<%dH" % (480 * 640), *([2500] * (480 * 640)))


def scan(kind):
    m = LaserScan()
    m.header.stamp = rospy.Time.now()
    m.header.frame_id = "laser"
    m.angle_min = -0.75 * math.pi
    m.angle_increment = 1.5 * math.pi / 719
    m.angle_max = m.angle_min + 719 * m.angle_increment
    m.range_min, m.range_max = 0.15, 12.0
    m.ranges = [3.0] * 720
    if kind == "scan-nan":
        m.ranges[100] = float("nan")
    if kind == "scan-inf":
        m.ranges[200] = float("inf")
    return m


def depth(kind):
    m = Image()
    m.header.stamp = rospy.Time.now()
    m.height, m.width, m.encoding, m.step = 480, 640, "32FC1", 640 * 4
    m.data = GOOD_DEPTH
    if kind == "depth-16uc1":
        m.encoding, m.step, m.data = "16UC1", 640 * 2, GOOD_DEPTH_16
    if kind == "depth-length":
        m.data = GOOD_DEPTH[:-4]
    if kind == "depth-encoding":
        m.encoding = "rgb8"
    if kind == "depth-width0":
        m.width, m.step, m.data = 0, 0, b""
    return m


def odom():
    m = Odometry()
    m.header.stamp = rospy.Time.now()
    m.pose.pose.orientation.w = 1.0
    return m


# Wait until the node is connected both ways.
deadline = time.time() + 30
while time.time() < deadline and not (
    twists and scan_pub.get_num_connections() and depth_pub.get_num_connections()
    and odom_pub.get_num_connections()
):
    time.sleep(0.05)

PHASES = [("good", 3.0), ("silent", 1.5), ("good", 1.5)]
for bad in ["scan-nan", "scan-inf", "depth-length", "depth-encoding", "depth-width0"]:
    PHASES += [(bad, 1.2), ("good", 1.2)]
PHASES += [("depth-16uc1", 1.5)]

phases = []
for name, seconds in PHASES:
    start = time.time()
    while time.time() < start + seconds:
        if name != "silent":
            scan_pub.publish(scan(name))
            depth_pub.publish(depth(name))
            odom_pub.publish(odom())
        time.sleep(0.1)
    phases.append({"name": name, "start": start, "end": time.time()})

print("PHASES_DONE", flush=True)
# Keep sensors fresh while the test sends SIGTERM, so that a zero after it is the node's
# shutdown, not its watchdog.
done = threading.Event()


def keep_fresh():
    while not done.is_set():
        scan_pub.publish(scan("good"))
        depth_pub.publish(depth("good"))
        odom_pub.publish(odom())
        time.sleep(0.1)


threading.Thread(target=keep_fresh, daemon=True).start()
sys.stdin.readline()
done.set()
time.sleep(0.3)
print(json.dumps({"phases": phases, "twists": twists}), flush=True)
