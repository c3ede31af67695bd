//! `mdrlat ros2` (the policy as a ROS 2 node) and `mdrlat ros2-sim` (the simulator as a ROS 2
//! robot): the ROS 1 commands' arguments, loop and bridge on `mdrlat-ros2`'s transport.

use super::ros::{
    LastCommand, NodeArgs, SimRobot, SimRobotArgs, lock, readings, run_node, run_sim,
};
use anyhow::Result;
use mdrlat_ros::robot;
use mdrlat_ros2::msg::{Image, LaserScan, Odometry, Twist, TwistStamped};
use mdrlat_ros2::{CmdType, Participant, Qos, Ros2Node};
use mdrlat_sim::bridge::{Received, SensorFrame, Transport};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// The DDS domain and the command type, shared by `ros2` and `ros2-sim`.
#[derive(Debug, Clone, clap::Args)]
pub struct Domain {
    /// DDS domain id, 0–232 (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, value_parser = parse_domain)]
    pub domain_id: Option<u16>,
    /// Velocity commands as geometry_msgs/msg/TwistStamped (Jazzy's diff_drive_controller)
    /// instead of Twist.
    #[arg(long)]
    pub stamped: bool,
}

fn parse_domain(s: &str) -> Result<u16, String> {
    mdrlat_ros2::parse_domain(s)
}

impl Domain {
    fn id(&self) -> Result<u16> {
        match self.domain_id {
            Some(d) => Ok(d),
            None => mdrlat_ros2::domain_from_env().map_err(anyhow::Error::msg),
        }
    }
    fn cmd_type(&self) -> CmdType {
        if self.stamped { CmdType::Stamped } else { CmdType::Twist }
    }
}

/// Arguments of `mdrlat ros2`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub domain: Domain,
    #[command(flatten)]
    pub node: NodeArgs,
}

/// Every topic and the node name must be ROS 2 names: checked before anything starts.
fn check_names(name: &str, t: &super::ros::Topics) -> Result<()> {
    mdrlat_ros2::node::node_name(name)?;
    for topic in [&t.scan_topic, &t.depth_topic, &t.odom_topic, &t.cmd_topic] {
        mdrlat_ros2::node::topic_name(topic)?;
    }
    Ok(())
}

/// `mdrlat ros2`.
pub fn run(a: &Args) -> Result<()> {
    let domain = a.domain.id()?;
    check_names(&a.node.name, &a.node.topics)?;
    run_node(&a.node, "ros2", || Ok(Ros2Node::new(&a.node.name, domain, a.domain.cmd_type())?))
}

/// Arguments of `mdrlat ros2-sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    #[command(flatten)]
    pub domain: Domain,
    #[command(flatten)]
    pub robot: SimRobotArgs,
}

/// `mdrlat ros2-sim`: the simulator's bridge ([`mdrlat_sim::bridge`]) on ROS 2.
pub fn sim(a: &SimArgs) -> Result<()> {
    let (r, domain) = (&a.robot, a.domain.id()?);
    check_names(&r.name, &r.topics)?;
    run_sim(r, "ros2-sim", |stop| {
        let mut p = Participant::new(&r.name, domain)?;
        let last = Arc::new(Mutex::new(LastCommand::default()));
        let cmd = &r.topics.cmd_topic;
        // A base's subscription: reliable (it matches reliable publishers only).
        match a.domain.cmd_type() {
            CmdType::Twist => {
                let last = last.clone();
                p.subscribe::<Twist>(cmd, Qos::Reliable, move |m| {
                    lock(&last).set(m.ok().map(|t| (t.linear.x, t.angular.z)));
                })?;
            }
            CmdType::Stamped => {
                let last = last.clone();
                p.subscribe::<TwistStamped>(cmd, Qos::Reliable, move |m| {
                    lock(&last).set(m.ok().map(|t| (t.twist.linear.x, t.twist.angular.z)));
                })?;
            }
        }
        // As drivers publish: scans and images with the sensor-data profile, odometry
        // reliable.
        Ok(Ros2Robot {
            scan: p.publisher(&r.topics.scan_topic, Qos::SensorData)?,
            depth: p.publisher(&r.topics.depth_topic, Qos::SensorData)?,
            odom: p.publisher(&r.topics.odom_topic, Qos::Reliable)?,
            encoding: r.depth_encoding.into(),
            last,
            participant: Some(p),
            stop,
        })
    })
}

/// The bridge's transport on ROS 2.
struct Ros2Robot {
    scan: mdrlat_ros2::Publisher<LaserScan>,
    depth: mdrlat_ros2::Publisher<Image>,
    odom: mdrlat_ros2::Publisher<Odometry>,
    encoding: robot::DepthEncoding,
    last: Arc<Mutex<LastCommand>>,
    participant: Option<Participant>,
    stop: Arc<AtomicBool>,
}

impl Transport for Ros2Robot {
    fn latest_command(&mut self) -> Option<Received> {
        lock(&self.last).received()
    }
    fn publish(&mut self, f: &SensorFrame<'_>) {
        let (scan, depth, odom) = robot::messages(&readings(f), self.encoding);
        let _ = self.scan.publish(scan.into());
        let _ = self.depth.publish(depth.into());
        let _ = self.odom.publish(odom.into());
    }
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }
}

impl SimRobot for Ros2Robot {
    fn describe(&self) -> String {
        self.participant
            .as_ref()
            .map_or_else(String::new, |p| format!("ROS 2 domain {} as {}", p.domain(), p.name()))
    }
    fn malformed(&self) -> u64 {
        lock(&self.last).malformed()
    }
    fn shutdown(&mut self) {
        self.participant = None;
    }
}
