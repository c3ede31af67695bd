//! `mdrlat ros`: a ROS 1 node in pure Rust that drives a robot with an mdrlat policy
//! (SPEC §6, the paper's section 3.2).
//!
//! - [`msg`]: the five message types the node speaks, their wire format and MD5 sums,
//!   computed from `.msg` files embedded in the crate (no ROS installation needed);
//! - [`xmlrpc`] and [`node`]: the master and slave APIs and TCPROS, on blocking sockets;
//! - [`convert`]: any laser scan to the simulator's 512 beams over 270°, any depth image to
//!   its 128 x 160 frame — the only sim-to-real step besides `mdrlat-core`'s normalisation,
//!   which the simulator and this node share;
//! - [`controller`]: frame stacks, the watchdog and the safety rules, free of transport;
//! - [`run`]: the node's loop over any middleware ([`Transport`]; [`Ros1`] here, ROS 2 in
//!   `mdrlat-ros2`);
//! - [`robot`]: the messages a turtlebot2 publishes, from plain readings (the simulator on
//!   ROS 1, `mdrlat ros-sim`, sends its bridge's frames through it).
//!
//! This crate never depends on the simulator: the real robot and the simulator share only
//! `mdrlat-core`.

pub mod controller;
pub mod convert;
pub mod msg;
pub mod node;
pub mod robot;
pub mod run;
pub mod xmlrpc;

pub use controller::{Command, Controller, ControllerConfig, Policy, Sensor};
pub use convert::{NonFinite, ScanOptions};
pub use node::{Node, Publisher, RosError};
pub use run::{Handler, Incoming, NodeConfig, Ros1, RunSummary, Transport, Trigger, run};
