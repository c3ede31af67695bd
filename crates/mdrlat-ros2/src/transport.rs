//! The policy node on ROS 2: [`mdrlat_ros::Transport`] over a [`Participant`], so that
//! `mdrlat ros2` runs the very loop, controller and safety rules of `mdrlat ros`.

use crate::msg::{Header, Image, LaserScan, Odometry, Time, Twist, TwistStamped};
use crate::node::{Participant, Qos};
use mdrlat_core::Velocity;
use mdrlat_ros::controller::Sensor;
use mdrlat_ros::msg as one;
use mdrlat_ros::{Handler, Incoming, RosError, Transport};
use ros2_client::Publisher;
use std::fmt::Display;
use std::time::{Duration, Instant};

/// The velocity command's message type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CmdType {
    /// `geometry_msgs/msg/Twist` (Humble bases, TurtleBot 4, Create 3).
    #[default]
    Twist,
    /// `geometry_msgs/msg/TwistStamped` (Jazzy's `diff_drive_controller` default).
    Stamped,
}

enum Cmd {
    Twist(Publisher<Twist>),
    Stamped(Publisher<TwistStamped>),
}

/// The policy node's middleware on ROS 2.
pub struct Ros2Node {
    participant: Participant,
    cmd_type: CmdType,
    cmd: Option<(String, Cmd)>,
}

impl std::fmt::Debug for Ros2Node {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Node")
            .field("participant", &self.participant)
            .field("cmd_type", &self.cmd_type)
            .finish()
    }
}

impl Ros2Node {
    /// Joins `domain` as the node `name`; velocity commands go out as `cmd_type`.
    ///
    /// # Errors
    /// A bad name, or DDS cannot start.
    pub fn new(name: &str, domain: u16, cmd_type: CmdType) -> Result<Self, RosError> {
        Ok(Self { participant: Participant::new(name, domain)?, cmd_type, cmd: None })
    }

    /// The participant (to count matched peers, say).
    pub fn participant(&self) -> &Participant {
        &self.participant
    }
}

fn err(e: &ros2_client::ReadError) -> &dyn Display {
    e
}

impl Transport for Ros2Node {
    fn describe(&self) -> String {
        format!("{} on ROS 2 domain {}", self.participant.name(), self.participant.domain())
    }

    fn subscribe(&mut self, sensor: Sensor, topic: &str, handler: Handler) -> Result<(), RosError> {
        // Each sample becomes the shared (ROS 1 shaped) message by moving its vectors.
        match sensor {
            Sensor::Laser => {
                self.participant.subscribe::<LaserScan>(topic, Qos::SensorData, move |m| {
                    let m = m.map(one::LaserScan::from);
                    handler(Incoming::Scan(m.as_ref().map_err(err)));
                })
            }
            Sensor::Depth => {
                self.participant.subscribe::<Image>(topic, Qos::SensorData, move |m| {
                    let m = m.map(one::Image::from);
                    handler(Incoming::Depth(m.as_ref().map_err(err)));
                })
            }
            // Best effort reads a reliable odometry publisher as well.
            Sensor::Odom => {
                self.participant.subscribe::<Odometry>(topic, Qos::SensorData, move |m| {
                    let m = m.map(one::Odometry::from);
                    handler(Incoming::Odom(m.as_ref().map_err(err)));
                })
            }
        }
    }

    fn advertise(&mut self, topic: &str) -> Result<(), RosError> {
        let cmd = match self.cmd_type {
            CmdType::Twist => Cmd::Twist(self.participant.publisher(topic, Qos::Reliable)?),
            CmdType::Stamped => Cmd::Stamped(self.participant.publisher(topic, Qos::Reliable)?),
        };
        self.cmd = Some((topic.to_string(), cmd));
        Ok(())
    }

    fn publish(&mut self, velocity: Velocity) {
        let twist = Twist::planar(f64::from(velocity.v), f64::from(velocity.w));
        // A full reliable queue waits 20 ms at most, then this command is dropped and the
        // next tick's goes out: the loop never stalls on a slow base.
        match &self.cmd {
            Some((_, Cmd::Twist(p))) => {
                let _ = p.publish(twist);
            }
            Some((_, Cmd::Stamped(p))) => {
                let header = Header { stamp: Time::now(), frame_id: "base_link".into() };
                let _ = p.publish(TwistStamped { header, twist });
            }
            None => {}
        }
    }

    /// `ros2-client`'s publishers expose no acknowledgement to wait on: with a matched
    /// subscription this lingers `within` (at most 0.3 s), time for RustDDS's heartbeats to
    /// have a lost sample repaired, and says it did; with none it returns at once.
    fn flush(&mut self, within: Duration) -> bool {
        let matched = match &self.cmd {
            None => 0,
            Some((_, Cmd::Twist(p))) => self.participant.matched(p),
            Some((_, Cmd::Stamped(p))) => self.participant.matched(p),
        };
        if matched == 0 {
            return true;
        }
        let end = Instant::now() + within.min(Duration::from_millis(300));
        while Instant::now() < end {
            std::thread::sleep(Duration::from_millis(10));
        }
        true
    }

    /// ROS 2 has no master to ask a node to leave.
    fn shutdown_requested(&self) -> bool {
        false
    }

    fn shutdown(&mut self) {
        self.cmd = None; // the writer leaves the graph; the participant with the node
    }
}
