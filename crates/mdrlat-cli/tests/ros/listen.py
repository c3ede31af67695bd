#!/usr/bin/env python3
"""Listens to `mdrlat ros-sim` with rospy for a few seconds and prints what arrived as JSON:
proof that rospy accepts the node's LaserScan, Image and Odometry (types, MD5 sums, bytes)."""
import json
import sys
import time

import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, LaserScan

seconds = float(sys.argv[1])
rospy.init_node("listen", disable_signals=True)
got = {"scan": [], "depth": [], "odom": []}


def on_scan(m):
    got["scan"].append({"n": len(m.ranges), "angle_min": m.angle_min, "angle_max": m.angle_max,
                        "range_max": m.range_max, "min": min(m.ranges)})


def on_depth(m):
    got["depth"].append({"h": m.height, "w": m.width, "enc": m.encoding, "step": m.step,
                         "bytes": len(m.data)})


def on_odom(m):
    got["odom"].append({"x": m.pose.pose.position.x, "y": m.pose.pose.position.y,
                        "frame": m.header.frame_id, "child": m.child_frame_id})


rospy.Subscriber("/scan", LaserScan, on_scan)
rospy.Subscriber("/camera/depth/image_raw", Image, on_depth)
rospy.Subscriber("/odom", Odometry, on_odom)
time.sleep(seconds)
print(json.dumps({k: {"count": len(v), "last": v[-1] if v else None} for k, v in got.items()}))
