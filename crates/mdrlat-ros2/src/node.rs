//! One ROS 2 participant: a `ros2-client` node on a DDS domain, subscriptions read on a
//! thread each, publishers, and ROS 2's naming and QoS conventions.
//!
//! Discovery is RustDDS's: SPDP/SEDP over UDP multicast on the domain's ports, so peers on
//! the same domain find each other without a master; the node announces itself on
//! `ros_discovery_info` (which is what `ros2 node list` reads).

use crate::msg::Ros2Message;
use mdrlat_ros::RosError;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher,
    QosProfile, ReadError,
};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// The largest domain id ROS 2 uses (its port arithmetic leaves 0–232 on Linux).
pub const MAX_DOMAIN_ID: u16 = 232;

/// The domain from `ROS_DOMAIN_ID` (unset or empty: 0, as ROS 2).
///
/// # Errors
/// The variable is not a number in 0..=232.
pub fn domain_from_env() -> Result<u16, String> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(s) if s.trim().is_empty() => Ok(0),
        Ok(s) => parse_domain(&s).map_err(|e| format!("ROS_DOMAIN_ID={s}: {e}")),
    }
}

/// Parses a domain id.
///
/// # Errors
/// Not a number in 0..=232.
pub fn parse_domain(s: &str) -> Result<u16, String> {
    match s.trim().parse::<u16>() {
        Ok(d) if d <= MAX_DOMAIN_ID => Ok(d),
        _ => Err(format!("expected a domain id in 0..={MAX_DOMAIN_ID}")),
    }
}

/// The QoS a topic is read or written with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Qos {
    /// ROS 2's sensor-data profile: best effort, volatile (a best-effort subscription
    /// matches best-effort and reliable publishers alike, so the node reads every driver);
    /// keep last 5 for a publisher, as drivers do, but 1 for a subscription: the node uses
    /// the newest sample only, and a peer sending oversized samples fills one slot, not five.
    SensorData,
    /// Reliable, volatile, keep last 10 (ROS 2's default profile): what a base's
    /// `cmd_vel` subscription asks for and what `odom` usually is.
    Reliable,
}

impl Qos {
    fn profile(self, reading: bool) -> QosProfile {
        match self {
            Qos::SensorData => QosProfile::default()
                .reliability(Reliability::BestEffort)
                .durability(Durability::Volatile)
                .history(History::KeepLast { depth: if reading { 1 } else { 5 } }),
            Qos::Reliable => QosProfile::default()
                .reliability(Reliability::Reliable {
                    when_full: WhenFull::Wait(Duration::from_millis(20)),
                })
                .durability(Durability::Volatile)
                .history(History::KeepLast { depth: 10 }),
        }
    }
}

/// A ROS topic name as ROS 2 resolves it for a node in the root namespace: `scan` and
/// `/scan` are both `/scan` (DDS topic `rt/scan`).
///
/// # Errors
/// Not a valid ROS name (empty, `//`, characters other than letters, digits, `_`).
pub fn topic_name(topic: &str) -> Result<Name, RosError> {
    let absolute = if topic.starts_with('/') { topic.to_string() } else { format!("/{topic}") };
    Name::parse(&absolute)
        .map_err(|e| RosError::Config(format!("topic {topic:?}: not a ROS 2 name ({e:?})")))
}

/// A node name `/ns/name` as ROS 2's namespace and base name.
///
/// # Errors
/// Not a valid ROS 2 node name.
pub fn node_name(name: &str) -> Result<NodeName, RosError> {
    let absolute = if name.starts_with('/') { name.to_string() } else { format!("/{name}") };
    let (ns, base) = absolute.rsplit_once('/').unwrap_or(("/", &absolute));
    let ns = if ns.is_empty() { "/" } else { ns };
    NodeName::new(ns, base)
        .map_err(|e| RosError::Config(format!("node name {name:?}: not a ROS 2 name ({e:?})")))
}

fn dds(what: &str, e: impl std::fmt::Display) -> RosError {
    RosError::Middleware(format!("ROS 2 (DDS): {what}: {e}"))
}

/// A node on a DDS domain.
pub struct Participant {
    node: Node,
    domain: u16,
    stop: Arc<AtomicBool>,
    readers: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for Participant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Participant")
            .field("node", &self.node.fully_qualified_name())
            .field("domain", &self.domain)
            .finish()
    }
}

impl Participant {
    /// Joins `domain` as the node `name` (e.g. `/mdrlat`).
    ///
    /// # Errors
    /// A bad name, or the DDS participant cannot open its sockets.
    pub fn new(name: &str, domain: u16) -> Result<Self, RosError> {
        let node_name = node_name(name)?;
        let context = Context::with_options(ContextOptions::new().domain_id(domain))
            .map_err(|e| dds(&format!("joining domain {domain}"), e))?;
        let node = context
            .new_node(
                node_name,
                NodeOptions::new().enable_rosout(false).start_parameter_services(false),
            )
            .map_err(|e| dds(&format!("creating node {name}"), e))?;
        Ok(Self { node, domain, stop: Arc::default(), readers: Vec::new() })
    }

    /// The node's fully qualified name.
    pub fn name(&self) -> String {
        self.node.fully_qualified_name()
    }

    /// The DDS domain.
    pub fn domain(&self) -> u16 {
        self.domain
    }

    /// Subscribes to `topic`: `on` gets each sample, or why one could not be decoded (a
    /// sample of the right type name with the wrong bytes), on the subscription's own
    /// thread, until the participant is dropped.
    ///
    /// # Errors
    /// A bad topic name, or DDS refuses.
    pub fn subscribe<M: Ros2Message>(
        &mut self,
        topic: &str,
        qos: Qos,
        mut on: impl FnMut(Result<M, ReadError>) + Send + 'static,
    ) -> Result<(), RosError> {
        let name = topic_name(topic)?;
        let (pkg, ty) = M::TYPE;
        let t = self
            .node
            .create_topic(&name, MessageTypeName::new(pkg, ty), &qos.profile(true))
            .map_err(|e| dds(&format!("topic {topic}"), e))?;
        let mut sub = self
            .node
            .create_subscription::<M>(&t, None)
            .map_err(|e| dds(&format!("subscribing to {topic}"), e))?;
        let mut poll = Poll::new().map_err(|e| dds("poll", e))?;
        poll.registry()
            .register(&mut sub, Token(0), Interest::READABLE)
            .map_err(|e| dds(&format!("polling {topic}"), e))?;
        let stop = self.stop.clone();
        let reader = std::thread::Builder::new()
            .name(format!("ros2 {topic}"))
            .spawn(move || {
                let mut events = Events::with_capacity(4);
                while !stop.load(Ordering::SeqCst) {
                    // Edge-triggered: drain everything before waiting again.
                    loop {
                        match sub.take() {
                            Ok(Some((m, _))) => on(Ok(m)),
                            Ok(None) => break,
                            Err(e @ ReadError::Deserialization { .. }) => on(Err(e)),
                            Err(_) => break, // the reader's own trouble: wait and retry
                        }
                    }
                    let _ = poll.poll(&mut events, Some(Duration::from_millis(50)));
                }
            })
            .map_err(|e| dds("a reader thread", e))?;
        self.readers.push(reader);
        Ok(())
    }

    /// A publisher on `topic`.
    ///
    /// # Errors
    /// A bad topic name, or DDS refuses.
    pub fn publisher<M: Ros2Message>(
        &mut self,
        topic: &str,
        qos: Qos,
    ) -> Result<Publisher<M>, RosError> {
        let name = topic_name(topic)?;
        let (pkg, ty) = M::TYPE;
        let t = self
            .node
            .create_topic(&name, MessageTypeName::new(pkg, ty), &qos.profile(false))
            .map_err(|e| dds(&format!("topic {topic}"), e))?;
        self.node
            .create_publisher::<M>(&t, None)
            .map_err(|e| dds(&format!("advertising {topic}"), e))
    }

    /// Subscriptions to `topic` discovered on the domain (any node's, any type).
    pub fn subscriptions(&self, topic: &str) -> usize {
        topic_name(topic).map_or(0, |n| self.node.subscription_count(&n.to_string()))
    }

    /// Subscriptions matched with one of this participant's publishers.
    pub fn matched<M: serde::Serialize>(&self, publisher: &Publisher<M>) -> usize {
        publisher.get_subscription_count(&self.node)
    }

    /// Publishers on `topic` discovered on the domain.
    pub fn publishers(&self, topic: &str) -> usize {
        topic_name(topic).map_or(0, |n| self.node.publisher_count(&n.to_string()))
    }
}

impl Drop for Participant {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        for r in self.readers.drain(..) {
            let _ = r.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_resolve_in_the_root_namespace() {
        let node = NodeName::new("/", "n").map_err(|e| format!("{e:?}"));
        let Ok(node) = node else { panic!("{node:?}") };
        for (topic, dds) in [
            ("/scan", "rt/scan"),
            ("scan", "rt/scan"),
            ("/camera/depth/image_raw", "rt/camera/depth/image_raw"),
        ] {
            let n = topic_name(topic).map_err(|e| e.to_string());
            assert_eq!(n.map(|n| n.to_dds_name("rt", &node, "")), Ok(dds.to_string()));
        }
        for bad in ["", "/", "/a//b", "/a b", "/9lives"] {
            assert!(topic_name(bad).is_err(), "{bad:?}");
        }
        let n = node_name("/robot/mdrlat").map_err(|e| e.to_string());
        assert_eq!(n.map(|n| n.fully_qualified_name()), Ok("/robot/mdrlat".to_string()));
        assert_eq!(
            node_name("mdrlat").map(|n| n.fully_qualified_name()).map_err(|e| e.to_string()),
            Ok("/mdrlat".to_string())
        );
        assert!(node_name("/a/").is_err());
    }

    #[test]
    fn domain_ids() {
        assert_eq!(parse_domain("0"), Ok(0));
        assert_eq!(parse_domain(" 232 "), Ok(232));
        for bad in ["233", "-1", "x", "1.5"] {
            assert!(parse_domain(bad).is_err(), "{bad}");
        }
    }
}
