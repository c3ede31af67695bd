#!/usr/bin/env python3
"""Hostile peers on `mdrlat ros2`'s domain, over Eclipse Cyclone DDS and raw UDP, while a
well-behaved robot keeps its sensors fresh; records the node's cmd_vel stream.

Usage: hostile.py DOMAIN SECONDS. For SECONDS, at once:
- a robot publishes good scans (720 beams), 240x320 depth images and odometry at 10 Hz and
  listens to cmd_vel (reliable), as in probe.py;
- garbage RTPS: datagrams to the domain's discovery multicast port and to the unicast ports
  of its first participants: random bytes, an RTPS header followed by random submessages,
  submessages whose length runs past the datagram, a DATA submessage with absurd offsets;
- oversized samples: LaserScans of 2,000,000 ranges (8 MB) on /scan, and Images claiming
  4000x4000 pixels with 16 MB of data on the depth topic;
- fragment bombs: 1 kB DATA_FRAG datagrams to the well-known builtin readers (SPDP, SEDP
  publications and subscriptions) from participants nobody discovered, each announcing a
  256 MB sample under a new sequence number (unpatched RustDDS allocated each in full);
- a discovery flood: 16 participants with a writer each created and deleted over and over.
Prints one JSON object: every command received (time, v, w) and the phase bounds.
"""
import json
import math
import os
import random
import socket
import struct
import sys
import threading
import time

from cyclonedds.domain import DomainParticipant

from ros_types import (RELIABLE, SENSOR_DATA, Image, LaserScan, Odometry, Twist, listen_twists,
                       reader, writer)

domain, seconds = int(sys.argv[1]), float(sys.argv[2])
rng = random.Random(7)
stop = threading.Event()
dp = DomainParticipant(domain)
scan_pub = writer(dp, "/scan", LaserScan, SENSOR_DATA)
depth_pub = writer(dp, "/camera/depth/image_raw", Image, SENSOR_DATA)
odom_pub = writer(dp, "/odom", Odometry, RELIABLE)
cmd = reader(dp, "/cmd_vel", Twist, RELIABLE)
twists = []


def listen():
    listen_twists(dp, cmd, False, stop, twists)


H, W = 240, 320
DEPTH = struct.pack("<%df" % (H * W), *([2.5] * (H * W)))
INC = 1.5 * math.pi / 719
SCAN = LaserScan(angle_min=-0.75 * math.pi, angle_max=-0.75 * math.pi + 719 * INC,
                 angle_increment=INC, range_min=0.15, range_max=12.0, ranges=[3.0] * 720)


def robot():
    tick = time.time()
    while not stop.is_set():
        scan_pub.write(SCAN)
        depth_pub.write(Image(height=H, width=W, encoding="32FC1", step=W * 4, data=DEPTH))
        odom_pub.write(Odometry())
        tick += 0.1
        time.sleep(max(0.0, tick - time.time()))


def garbage_rtps():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
    base = 7400 + 250 * domain
    targets = [("239.255.0.1", base), ("239.255.0.1", base + 1)]
    targets += [("127.0.0.1", base + 10 + 2 * i + k) for i in range(6) for k in (0, 1)]
    header = b"RTPS" + bytes([2, 3, 1, 15]) + os.urandom(12)
    sent = 0
    while not stop.is_set():
        kind = sent % 4
        if kind == 0:
            pkt = os.urandom(rng.randint(1, 1400))
        elif kind == 1:
            pkt = header + os.urandom(rng.randint(0, 1400))
        elif kind == 2:  # a submessage whose length runs past the datagram
            pkt = header + bytes([0x15, 0x01]) + struct.pack("<H", 60000) + os.urandom(8)
        else:  # DATA with an octetsToInlineQos pointing nowhere and a 4 GB serialized size
            body = struct.pack("<HH", 0, 0xFFFF) + os.urandom(16) + struct.pack("<ii", 0, 1)
            body += b"\x00\x01\x00\x00" + struct.pack("<I", 0xFFFFFFF0)
            pkt = header + bytes([0x15, 0x05]) + struct.pack("<H", len(body)) + body
        for t in targets:
            try:
                s.sendto(pkt, t)
            except OSError:
                pass
        sent += 1
        time.sleep(0.002)


def fragment_bombs():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    base = 7400 + 250 * domain
    ports = [base + 10 + 2 * i + k for i in range(6) for k in (0, 1)]
    # (reader, writer) entity ids: SPDP, SEDP publications, SEDP subscriptions.
    pairs = [("000100c7", "000100c2"), ("000003c7", "000003c2"), ("000004c7", "000004c2")]
    header = b"RTPS" + bytes([2, 3, 1, 15]) + os.urandom(12)
    sn = 0
    while not stop.is_set():
        sn += 1
        for reader, writer in pairs:
            body = struct.pack("<HH", 0, 28) + bytes.fromhex(reader) + bytes.fromhex(writer)
            body += struct.pack("<iI", 0, sn) + struct.pack("<IHHI", 1, 1, 1024, 256 << 20)
            body += os.urandom(1024)
            pkt = header + bytes([0x16, 0x01]) + struct.pack("<H", len(body)) + body
            for p in ports:
                try:
                    s.sendto(pkt, ("127.0.0.1", p))
                except OSError:
                    pass
        time.sleep(0.01)


def oversized():
    p = DomainParticipant(domain)
    big_scan = writer(p, "/scan", LaserScan, SENSOR_DATA)
    big_depth = writer(p, "/camera/depth/image_raw", Image, SENSOR_DATA)
    huge = LaserScan(angle_min=-0.75 * math.pi, angle_max=0.75 * math.pi,
                     angle_increment=1.5 * math.pi / 1999999, range_max=12.0,
                     ranges=[2.0] * 2000000)
    blob = bytes(16 * 1024 * 1024)
    while not stop.is_set():
        big_scan.write(huge)
        big_depth.write(Image(height=4000, width=4000, encoding="8UC1", step=4000, data=blob))
        time.sleep(0.5)


def flood():
    while not stop.is_set():
        ps = [DomainParticipant(domain) for _ in range(16)]
        ws = [writer(p, "/flood_%d" % i, Twist, RELIABLE) for i, p in enumerate(ps)]
        time.sleep(0.3)
        del ws, ps


threading.Thread(target=listen, daemon=True).start()
threading.Thread(target=robot, daemon=True).start()
# Let the node drive on good data first.
time.sleep(3.0)
calm_end = time.time()
for f in (garbage_rtps, fragment_bombs, oversized, flood):
    threading.Thread(target=f, daemon=True).start()
time.sleep(seconds)
stop.set()
time.sleep(0.3)
print(json.dumps({"calm_end": calm_end, "end": time.time(), "twists": twists}), flush=True)
