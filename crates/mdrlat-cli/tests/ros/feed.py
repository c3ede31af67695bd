#!/usr/bin/env python3
"""Publishes a synthetic robot (512-beam scan over 270 degrees, 480x640 16UC1 depth,
odometry) at 10 Hz for argv[1] seconds, as node /feed. Used to kill and restart a publisher
under a running `mdrlat ros`. With argv[2] == "narrow" the scan covers 180 degrees only."""
import math
import struct
import sys
import time

import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, LaserScan

rospy.init_node("feed", disable_signals=True)
scan_pub = rospy.Publisher("/scan", LaserScan, queue_size=1)
depth_pub = rospy.Publisher("/camera/depth/image_raw", Image, queue_size=1)
odom_pub = rospy.Publisher("/odom", Odometry, queue_size=1)
depth = Image(height=480, width=640, encoding="16UC1", step=1280,
              data=struct.pack("<%dH" % (480 * 640), *([1800] * (480 * 640))))
scan = LaserScan(angle_min=-0.75 * math.pi, angle_max=0.75 * math.pi,
                 angle_increment=1.5 * math.pi / 511, range_min=0.1, range_max=8.0,
                 ranges=[2.5] * 512)
if len(sys.argv) > 2 and sys.argv[2] == "narrow":
    scan.angle_min, scan.angle_max = -0.5 * math.pi, 0.5 * math.pi
    scan.angle_increment = math.pi / 511
odom = Odometry()
odom.pose.pose.orientation.w = 1.0
end = time.time() + float(sys.argv[1])
while time.time() < end:
    scan_pub.publish(scan)
    depth_pub.publish(depth)
    odom_pub.publish(odom)
    time.sleep(0.1)
