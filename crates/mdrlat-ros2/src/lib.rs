//! ROS 2 for mdrlat, in pure Rust: nothing of ROS 2 is installed to build or run it.
//!
//! - [`msg`]: the ROS 2 messages the node and the simulated robot speak (CDR layouts,
//!   checked byte for byte), and their conversions to `mdrlat_ros::msg`'s;
//! - [`node`]: a participant on a DDS domain (`ros2-client` on RustDDS): ROS 2's topic and
//!   type naming, QoS profiles, `ROS_DOMAIN_ID`, one reader thread per subscription;
//! - [`transport`]: [`mdrlat_ros::Transport`] on ROS 2, so `mdrlat ros2` runs the ROS 1
//!   node's loop, controller, scan and depth conversion and safety rules unchanged.
//!
//! Like `mdrlat-ros`, this crate never depends on the simulator.

pub mod msg;
pub mod node;
pub mod transport;

pub use node::{Participant, Qos, domain_from_env, parse_domain};
/// A ROS 2 publisher (`ros2-client`'s).
pub use ros2_client::Publisher;
pub use transport::{CmdType, Ros2Node};
