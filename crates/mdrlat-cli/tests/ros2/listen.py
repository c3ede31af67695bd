#!/usr/bin/env python3
"""Listens to `mdrlat ros2-sim`'s topics over Eclipse Cyclone DDS for SECONDS and prints
what it decoded as JSON: count and the last message's shape per topic, and the nodes
announced on ros_discovery_info (namespace|name|readers|writers), as `ros2 node list` sees
them.

Usage: listen.py DOMAIN SECONDS. Subscribes best effort, as rviz or a logger would.
"""
import json
import sys
import time

from cyclonedds.domain import DomainParticipant

from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from ros_types import (DISCOVERY, SENSOR_DATA, Image, LaserScan, Odometry,
                       ParticipantEntitiesInfo, reader)

domain, seconds = int(sys.argv[1]), float(sys.argv[2])
dp = DomainParticipant(domain)
readers = {
    "scan": reader(dp, "/scan", LaserScan, SENSOR_DATA),
    "depth": reader(dp, "/camera/depth/image_raw", Image, SENSOR_DATA),
    "odom": reader(dp, "/odom", Odometry, SENSOR_DATA),
}
# As `ros2 node list` learns the nodes: ros_discovery_info (no rt/ prefix).
graph = DataReader(dp, Topic(dp, "ros_discovery_info", ParticipantEntitiesInfo), qos=DISCOVERY)
nodes = set()
heard = {k: {"count": 0, "last": None} for k in readers}
end = time.time() + seconds
while time.time() < end:
    for k, r in readers.items():
        for m in r.take(N=50):
            if not hasattr(m, "header"):
                continue  # an InvalidSample: a writer left
            heard[k]["count"] += 1
            if k == "scan":
                heard[k]["last"] = {"n": len(m.ranges), "angle_max": m.angle_max,
                                    "frame": m.header.frame_id}
            elif k == "depth":
                heard[k]["last"] = {"h": m.height, "w": m.width, "enc": m.encoding,
                                    "bytes": len(m.data)}
            else:
                heard[k]["last"] = {"child": m.child_frame_id, "x": m.pose.pose.position.x}
    for info in graph.take(N=50):
        if not hasattr(info, "node_entities_info_seq"):
            continue
        for n in info.node_entities_info_seq:
            nodes.add("%s|%s|%d|%d" % (n.node_namespace, n.node_name, len(n.reader_gid_seq),
                                       len(n.writer_gid_seq)))
    time.sleep(0.02)
heard["nodes"] = sorted(nodes)
print(json.dumps(heard), flush=True)
