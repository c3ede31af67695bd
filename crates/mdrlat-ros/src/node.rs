//! A ROS 1 node: registration with the master (XML-RPC), the slave API peers call, and
//! TCPROS publishers and subscribers, with blocking I/O on small threads.
//!
//! The protocol is the one in the ROS wiki's "ROS/Master_API", "ROS/Slave_API" and
//! "ROS/TCPROS" pages. A publisher never blocks its caller: each subscriber connection has
//! a writer thread with a short queue, and a slow reader loses old messages, not the node's
//! control loop.

use crate::msg::{self, Message, WireError};
use crate::xmlrpc::{self, Value, XmlRpcError};
use std::collections::{HashMap, VecDeque};
use std::io::{Read, Write};
use std::marker::PhantomData;
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, Weak};
use std::time::{Duration, Instant};
use thiserror::Error;

/// Messages larger than this are refused (a 1080p 32-bit image is 8 MB).
const MAX_MESSAGE_BYTES: usize = 64 << 20;
/// Messages queued per subscriber connection; beyond it the oldest is dropped.
const QUEUE: usize = 4;
/// A subscriber link that brings nothing for this long is reconnected.
const SILENT_LINK: Duration = Duration::from_secs(10);

/// A node that cannot start or register.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RosError {
    /// The master could not be reached or answered garbage.
    #[error("ROS master {master}: {error} (is roscore running? check ROS_MASTER_URI / --master)")]
    Master {
        /// The master URI.
        master: String,
        /// Why.
        error: XmlRpcError,
    },
    /// The master refused a call.
    #[error("ROS master {master} refused {method}: {message}")]
    Refused {
        /// The master URI.
        master: String,
        /// The call.
        method: String,
        /// Its status message.
        message: String,
    },
    /// The node's configuration cannot work.
    #[error("{0}")]
    Config(String),
    /// Another middleware (ROS 2's DDS) refused: what was asked and why.
    #[error("{0}")]
    Middleware(String),
    /// A file (the CSV log) cannot be written.
    #[error("{}: {error}", path.display())]
    File {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// A socket could not be opened.
    #[error("cannot listen on {host}: {error}")]
    Listen {
        /// The address.
        host: String,
        /// Why.
        error: std::io::Error,
    },
}

/// The master URI from `ROS_MASTER_URI`, else ROS's default.
pub fn master_from_env() -> String {
    std::env::var("ROS_MASTER_URI")
        .ok()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "http://localhost:11311/".into())
}

/// The host name peers use to reach this node: `ROS_HOSTNAME`, else `ROS_IP`, else the
/// machine's host name (as roscpp and rospy choose).
pub fn host_from_env() -> String {
    ["ROS_HOSTNAME", "ROS_IP"]
        .iter()
        .find_map(|k| std::env::var(k).ok().filter(|s| !s.is_empty()))
        .or_else(|| {
            std::fs::read_to_string("/proc/sys/kernel/hostname")
                .ok()
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
        })
        .unwrap_or_else(|| "localhost".into())
}

/// A global topic name: `scan` → `/scan`.
pub fn resolve(name: &str) -> String {
    if name.starts_with('/') { name.to_string() } else { format!("/{name}") }
}

type Callback = Arc<dyn Fn(&[u8]) + Send + Sync>;
/// The last message of a latched topic, with its length prefix.
type Latched = Arc<Mutex<Option<Arc<Vec<u8>>>>>;

struct Subscription {
    topic: String,
    ty: &'static str,
    md5: String,
    callback: Callback,
    /// Publisher APIs the master lists now (the last `publisherUpdate`).
    listed: Mutex<Vec<String>>,
    /// Publisher APIs with a link thread.
    connected: Mutex<Vec<String>>,
}

/// The frames waiting for one subscriber connection of a publication.
#[derive(Default)]
struct LinkQueue {
    frames: VecDeque<Arc<Vec<u8>>>,
    /// A frame is being written.
    writing: bool,
    /// The connection is gone (or the publisher dropped).
    closed: bool,
}

/// One subscriber connection of a publication: a queue that keeps the newest [`QUEUE`]
/// frames, drained by the connection's writer thread.
type Link = Arc<(Mutex<LinkQueue>, Condvar)>;

struct Publication {
    topic: String,
    ty: &'static str,
    port: u16,
}

struct Inner {
    name: String,
    master: String,
    host: String,
    api: String,
    subscriptions: Mutex<Vec<Arc<Subscription>>>,
    publications: Mutex<Vec<Publication>>,
    shutdown_requested: AtomicBool,
    closed: AtomicBool,
}

/// A ROS 1 node registered with a master.
pub struct Node {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for Node {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Node")
            .field("name", &self.inner.name)
            .field("master", &self.inner.master)
            .field("api", &self.inner.api)
            .finish()
    }
}

fn bind(host: &str) -> Result<(TcpListener, u16), RosError> {
    let listen = |error| RosError::Listen { host: host.to_string(), error };
    let listener = TcpListener::bind(("0.0.0.0", 0)).map_err(listen)?;
    let port = listener.local_addr().map_err(listen)?.port();
    Ok((listener, port))
}

fn ok(message: &str, value: Value) -> Value {
    Value::Array(vec![Value::Int(1), Value::str(message), value])
}

impl Node {
    /// Starts a node called `name` (e.g. `/mdrlat`) that registers with `master` and is
    /// reached by peers at `host`. Checks that the master answers.
    ///
    /// # Errors
    /// No socket, or the master cannot be reached.
    pub fn new(name: &str, master: &str, host: &str) -> Result<Self, RosError> {
        let (listener, port) = bind(host)?;
        let inner = Arc::new(Inner {
            name: resolve(name),
            master: master.to_string(),
            host: host.to_string(),
            api: format!("http://{host}:{port}/"),
            subscriptions: Mutex::new(Vec::new()),
            publications: Mutex::new(Vec::new()),
            shutdown_requested: AtomicBool::new(false),
            closed: AtomicBool::new(false),
        });
        let weak = Arc::downgrade(&inner);
        xmlrpc::serve(
            listener,
            Arc::new(move |method: &str, params: &[Value]| match weak.upgrade() {
                Some(inner) => slave_api(&inner, method, params),
                None => Value::Array(vec![Value::Int(-1), Value::str("node gone"), Value::Int(0)]),
            }),
        );
        let node = Self { inner };
        node.master_call("getPid", vec![])?;
        Ok(node)
    }

    /// The node's name.
    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// The master URI.
    pub fn master(&self) -> &str {
        &self.inner.master
    }

    /// Whether the master (or anyone) asked this node to shut down (e.g. another node
    /// started with the same name).
    pub fn shutdown_requested(&self) -> bool {
        self.inner.shutdown_requested.load(Ordering::SeqCst)
    }

    fn master_call(&self, method: &str, mut params: Vec<Value>) -> Result<Value, RosError> {
        params.insert(0, Value::str(self.inner.name.clone()));
        master_call(&self.inner.master, method, &params)
    }

    /// Subscribes to `topic`; `callback` gets every message, or the decoding error of a
    /// malformed one, on the connection's thread.
    ///
    /// # Errors
    /// The master refuses or cannot be reached.
    pub fn subscribe<T: Message>(
        &self,
        topic: &str,
        callback: impl Fn(Result<T, WireError>) + Send + Sync + 'static,
    ) -> Result<(), RosError> {
        let topic = resolve(topic);
        let callback: Callback = Arc::new(move |bytes: &[u8]| callback(T::from_bytes(bytes)));
        lock(&self.inner.subscriptions).push(Arc::new(Subscription {
            topic: topic.clone(),
            ty: T::TYPE,
            md5: msg::md5sum(T::TYPE),
            callback,
            listed: Mutex::default(),
            connected: Mutex::default(),
        }));
        let publishers = self.master_call(
            "registerSubscriber",
            vec![Value::str(&topic), Value::str(T::TYPE), Value::str(&self.inner.api)],
        )?;
        let uris: Vec<String> = publishers
            .as_array()
            .unwrap_or(&[])
            .iter()
            .filter_map(|v| v.as_str().map(str::to_string))
            .collect();
        connect_publishers(&self.inner, &topic, &uris);
        Ok(())
    }

    /// Advertises `topic`. A latched topic sends its last message to new subscribers.
    ///
    /// # Errors
    /// No socket, or the master refuses or cannot be reached.
    pub fn advertise<T: Message>(
        &self,
        topic: &str,
        latch: bool,
    ) -> Result<Publisher<T>, RosError> {
        let topic = resolve(topic);
        let (listener, port) = bind(&self.inner.host)?;
        let links = Arc::new(Mutex::new(Vec::new()));
        let latched = Arc::new(Mutex::new(None));
        lock(&self.inner.publications).push(Publication {
            topic: topic.clone(),
            ty: T::TYPE,
            port,
        });
        let header = PublisherHeader {
            callerid: self.inner.name.clone(),
            topic: topic.clone(),
            ty: T::TYPE,
            md5: msg::md5sum(T::TYPE),
            definition: msg::full_definition(T::TYPE),
            latch,
        };
        accept_subscribers(listener, header, links.clone(), latched.clone());
        self.master_call(
            "registerPublisher",
            vec![Value::str(&topic), Value::str(T::TYPE), Value::str(&self.inner.api)],
        )?;
        Ok(Publisher { topic, links, latched: latch.then_some(latched), _type: PhantomData })
    }

    /// Unregisters every topic from the master. Called on drop; safe to call twice.
    pub fn shutdown(&self) {
        if self.inner.closed.swap(true, Ordering::SeqCst) {
            return;
        }
        let subs: Vec<String> =
            lock(&self.inner.subscriptions).iter().map(|s| s.topic.clone()).collect();
        for topic in subs {
            let _ = self.master_call(
                "unregisterSubscriber",
                vec![Value::str(topic), Value::str(&self.inner.api)],
            );
        }
        let pubs: Vec<String> =
            lock(&self.inner.publications).iter().map(|p| p.topic.clone()).collect();
        for topic in pubs {
            let _ = self.master_call(
                "unregisterPublisher",
                vec![Value::str(topic), Value::str(&self.inner.api)],
            );
        }
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Locks `m`, also after a panic elsewhere poisoned it (the data stays consistent: every
/// critical section here is a plain update).
pub(crate) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Calls the master and unpacks ROS's `[code, status, value]` answer.
fn master_call(master: &str, method: &str, params: &[Value]) -> Result<Value, RosError> {
    let answer = xmlrpc::call(master, method, params)
        .map_err(|error| RosError::Master { master: master.to_string(), error })?;
    match answer.as_array() {
        Some([code, status, value]) if code.as_int() == Some(1) => Ok(value.clone()),
        Some([_, status, _]) => Err(RosError::Refused {
            master: master.to_string(),
            method: method.to_string(),
            message: status.as_str().unwrap_or("").to_string(),
        }),
        _ => Err(RosError::Master {
            master: master.to_string(),
            error: XmlRpcError::Malformed(format!("{method} answered {answer:?}")),
        }),
    }
}

/// The slave API other nodes and the master call on us.
fn slave_api(inner: &Arc<Inner>, method: &str, params: &[Value]) -> Value {
    let arg = |i: usize| params.get(i).and_then(Value::as_str).unwrap_or("");
    let topics = |list: Vec<(String, &str)>| {
        Value::Array(
            list.into_iter()
                .map(|(t, ty)| Value::Array(vec![Value::str(t), Value::str(ty)]))
                .collect(),
        )
    };
    match method {
        "getPid" => ok("", Value::Int(std::process::id() as i32)),
        "getMasterUri" => ok("", Value::str(&inner.master)),
        "getBusStats" => ok("", Value::Array(vec![Value::Array(vec![]); 3])),
        "getBusInfo" => ok("", Value::Array(vec![])),
        "paramUpdate" => ok("", Value::Int(0)),
        "shutdown" => {
            inner.shutdown_requested.store(true, Ordering::SeqCst);
            eprintln!("[{}] shutdown requested by {}: {}", inner.name, arg(0), arg(1));
            ok("shutdown", Value::Int(0))
        }
        "getSubscriptions" => ok(
            "",
            topics(lock(&inner.subscriptions).iter().map(|s| (s.topic.clone(), s.ty)).collect()),
        ),
        "getPublications" => ok(
            "",
            topics(lock(&inner.publications).iter().map(|p| (p.topic.clone(), p.ty)).collect()),
        ),
        "publisherUpdate" => {
            let uris: Vec<String> = params
                .get(2)
                .and_then(Value::as_array)
                .unwrap_or(&[])
                .iter()
                .filter_map(|v| v.as_str().map(str::to_string))
                .collect();
            connect_publishers(inner, arg(1), &uris);
            ok("", Value::Int(0))
        }
        "requestTopic" => {
            let topic = arg(1);
            let tcpros = params.get(2).and_then(Value::as_array).is_some_and(|protocols| {
                protocols.iter().any(|p| {
                    p.as_array().and_then(|a| a.first()).and_then(Value::as_str) == Some("TCPROS")
                })
            });
            let port = lock(&inner.publications).iter().find(|p| p.topic == topic).map(|p| p.port);
            match (port, tcpros) {
                (Some(port), true) => ok(
                    "ready",
                    Value::Array(vec![
                        Value::str("TCPROS"),
                        Value::str(&inner.host),
                        Value::Int(i32::from(port)),
                    ]),
                ),
                (None, _) => Value::Array(vec![
                    Value::Int(0),
                    Value::str(format!("{} does not publish {topic}", inner.name)),
                    Value::Array(vec![]),
                ]),
                (Some(_), false) => Value::Array(vec![
                    Value::Int(0),
                    Value::str("only TCPROS is supported"),
                    Value::Array(vec![]),
                ]),
            }
        }
        other => Value::Array(vec![
            Value::Int(-1),
            Value::str(format!("unknown method {other}")),
            Value::Int(0),
        ]),
    }
}

// ---------------------------------------------------------------------------------------
// TCPROS.

fn encode_header(fields: &[(&str, &str)]) -> Vec<u8> {
    let mut body = Vec::new();
    for (k, v) in fields {
        let field = format!("{k}={v}");
        body.extend_from_slice(&(field.len() as u32).to_le_bytes());
        body.extend_from_slice(field.as_bytes());
    }
    let mut out = (body.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&body);
    out
}

fn read_frame(stream: &mut impl Read) -> std::io::Result<Vec<u8>> {
    let mut len = [0; 4];
    stream.read_exact(&mut len)?;
    let len = u32::from_le_bytes(len) as usize;
    if len > MAX_MESSAGE_BYTES {
        return Err(std::io::Error::other(format!("frame of {len} bytes refused")));
    }
    let mut body = vec![0; len];
    stream.read_exact(&mut body)?;
    Ok(body)
}

fn decode_header(body: &[u8]) -> HashMap<String, String> {
    let mut fields = HashMap::new();
    let mut rest = body;
    while rest.len() >= 4 {
        let n = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]) as usize;
        rest = &rest[4..];
        if n > rest.len() {
            break;
        }
        let field = String::from_utf8_lossy(&rest[..n]);
        if let Some((k, v)) = field.split_once('=') {
            fields.insert(k.to_string(), v.to_string());
        }
        rest = &rest[n..];
    }
    fields
}

/// The master's full list of `topic`'s publishers: links start to new ones; links to
/// publishers no longer listed end at their next message (or silence).
fn connect_publishers(inner: &Arc<Inner>, topic: &str, uris: &[String]) {
    let subs = lock(&inner.subscriptions);
    let Some(sub) = subs.iter().find(|s| s.topic == topic) else { return };
    // Lock order: `connected`, then `listed` (as a link thread deciding to leave).
    let mut connected = lock(&sub.connected);
    *lock(&sub.listed) = uris.to_vec();
    for uri in uris {
        if connected.contains(uri) {
            continue;
        }
        let job = SubscriberLink {
            node: Arc::downgrade(inner),
            callerid: inner.name.clone(),
            sub: sub.clone(),
            publisher: uri.clone(),
            left: true, // until it runs: its spawn may fail
        };
        let started = std::thread::Builder::new().name("tcpros-sub".into()).spawn(move || {
            let mut job = job;
            job.left = false;
            job.run();
        });
        if started.is_ok() {
            connected.push(uri.clone());
        }
    }
}

/// One subscriber connection to one publisher, on its own thread.
struct SubscriberLink {
    node: Weak<Inner>,
    callerid: String,
    sub: Arc<Subscription>,
    publisher: String,
    /// Removed itself from `connected` (on a panic in the callback it has not).
    left: bool,
}

impl Drop for SubscriberLink {
    fn drop(&mut self) {
        if !self.left {
            lock(&self.sub.connected).retain(|u| u != &self.publisher);
        }
    }
}

impl SubscriberLink {
    /// Whether the link should (still) run: the node is open and the master lists the
    /// publisher.
    fn wanted(&self) -> bool {
        self.node.upgrade().is_some_and(|n| !n.closed.load(Ordering::SeqCst))
            && lock(&self.sub.listed).contains(&self.publisher)
    }

    fn run(mut self) {
        let mut backoff = Duration::from_millis(250);
        let mut failing = false;
        loop {
            {
                // Leaving is decided and recorded under `connected`, the lock
                // `connect_publishers` holds while it reads `listed`: a publisher re-listed
                // at this moment either keeps this link or gets a new one, never neither.
                let mut connected = lock(&self.sub.connected);
                if !self.wanted() {
                    connected.retain(|u| u != &self.publisher);
                    self.left = true;
                    return;
                }
            }
            match self.receive() {
                Ok(received) => {
                    if received {
                        backoff = Duration::from_millis(250);
                        failing = false;
                    }
                }
                Err((e, received)) => {
                    if received {
                        backoff = Duration::from_millis(250);
                        failing = false;
                    }
                    if !failing && self.wanted() {
                        eprintln!(
                            "[{}] {}: {e} (retrying while it is listed)",
                            self.callerid, self.sub.topic
                        );
                    }
                    failing = true;
                }
            }
            std::thread::sleep(backoff);
            backoff = (backoff * 2).min(Duration::from_secs(5));
        }
    }

    /// One connection: requestTopic, handshake, then messages until the link ends.
    /// `Ok(received)` when it ended cleanly (EOF, or the publisher is no longer listed);
    /// `Err((why, received))` otherwise. `received`: at least one message came.
    fn receive(&self) -> Result<bool, (String, bool)> {
        let fail = |e: String| (e, false);
        let answer = xmlrpc::call(
            &self.publisher,
            "requestTopic",
            &[
                Value::str(&self.callerid),
                Value::str(&self.sub.topic),
                Value::Array(vec![Value::Array(vec![Value::str("TCPROS")])]),
            ],
        )
        .map_err(|e| fail(format!("publisher {e}")))?;
        let (host, port) = match answer.as_array() {
            Some([code, _, Value::Array(p)]) if code.as_int() == Some(1) => match p.as_slice() {
                [proto, host, port] if proto.as_str() == Some("TCPROS") => (
                    host.as_str().unwrap_or("").to_string(),
                    u16::try_from(port.as_int().unwrap_or(0)).unwrap_or(0),
                ),
                _ => return Err(fail(format!("no TCPROS offered: {answer:?}"))),
            },
            _ => return Err(fail(format!("requestTopic refused: {answer:?}"))),
        };
        let mut stream = xmlrpc::connect(&host, port, Duration::from_secs(3))
            .map_err(|e| fail(format!("{host}:{port}: {e}")))?;
        let _ = stream.set_nodelay(true);
        let _ = stream.set_read_timeout(Some(SILENT_LINK));
        let definition = msg::full_definition(self.sub.ty);
        let header = encode_header(&[
            ("message_definition", &definition),
            ("callerid", &self.callerid),
            ("topic", &self.sub.topic),
            ("md5sum", &self.sub.md5),
            ("type", self.sub.ty),
            ("tcp_nodelay", "1"),
        ]);
        stream.write_all(&header).map_err(|e| fail(e.to_string()))?;
        let reply = decode_header(&read_frame(&mut stream).map_err(|e| fail(e.to_string()))?);
        if let Some(error) = reply.get("error") {
            return Err(fail(format!("publisher refused the connection: {error}")));
        }
        let mut received = false;
        loop {
            let body = match read_frame(&mut stream) {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(received),
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Err((format!("no message for {} s", SILENT_LINK.as_secs()), received));
                }
                Err(e) => return Err((e.to_string(), received)),
            };
            if !self.wanted() {
                return Ok(received);
            }
            received = true;
            (self.sub.callback)(&body);
        }
    }
}

struct PublisherHeader {
    callerid: String,
    topic: String,
    ty: &'static str,
    md5: String,
    definition: String,
    latch: bool,
}

fn accept_subscribers(
    listener: TcpListener,
    header: PublisherHeader,
    links: Arc<Mutex<Vec<Link>>>,
    latched: Latched,
) {
    let header = Arc::new(header);
    let _ = std::thread::Builder::new().name("tcpros-accept".into()).spawn(move || {
        for stream in listener.incoming() {
            let Ok(stream) = stream else {
                std::thread::sleep(Duration::from_millis(100)); // e.g. out of file descriptors
                continue;
            };
            let (header, links, latched) = (header.clone(), links.clone(), latched.clone());
            let _ = std::thread::Builder::new()
                .name("tcpros-pub".into())
                .spawn(move || serve_subscriber(stream, &header, &links, &latched));
        }
    });
}

fn serve_subscriber(
    mut stream: TcpStream,
    header: &PublisherHeader,
    links: &Mutex<Vec<Link>>,
    latched: &Mutex<Option<Arc<Vec<u8>>>>,
) {
    let _ = stream.set_read_timeout(Some(Duration::from_secs(5)));
    let Ok(request) = read_frame(&mut stream) else { return };
    let request = decode_header(&request);
    let wanted = request.get("md5sum").map(String::as_str).unwrap_or("");
    if wanted != "*" && wanted != header.md5 {
        let error = format!(
            "md5sum mismatch on {}: {} wants {} ({}), this node publishes {} ({})",
            header.topic,
            request.get("callerid").map(String::as_str).unwrap_or("?"),
            wanted,
            request.get("type").map(String::as_str).unwrap_or("?"),
            header.md5,
            header.ty
        );
        let _ = stream.write_all(&encode_header(&[("error", &error)]));
        return;
    }
    let reply = encode_header(&[
        ("callerid", &header.callerid),
        ("md5sum", &header.md5),
        ("type", header.ty),
        ("topic", &header.topic),
        ("latching", if header.latch { "1" } else { "0" }),
        ("message_definition", &header.definition),
    ]);
    if stream.write_all(&reply).is_err() || request.get("probe").is_some_and(|p| p == "1") {
        return;
    }
    let _ = stream.set_nodelay(request.get("tcp_nodelay").is_none_or(|v| v == "1"));
    // A subscriber that stops reading loses its link instead of holding a writer forever.
    let _ = stream.set_write_timeout(Some(Duration::from_secs(2)));
    let link: Link = Arc::default();
    if header.latch
        && let Some(last) = lock(latched).clone()
    {
        lock(&link.0).frames.push_back(last);
    }
    lock(links).push(link.clone());
    let (queue, ready) = &*link;
    loop {
        let mut q = lock(queue);
        while q.frames.is_empty() && !q.closed {
            q = ready.wait(q).unwrap_or_else(std::sync::PoisonError::into_inner);
        }
        let Some(frame) = q.frames.pop_front() else { break }; // closed
        q.writing = true;
        drop(q);
        let sent = stream.write_all(&frame).is_ok();
        let mut q = lock(queue);
        q.writing = false;
        if !sent {
            q.closed = true;
            q.frames.clear();
            break;
        }
    }
    ready.notify_all();
}

/// Publishes messages of type `T` on one topic.
pub struct Publisher<T> {
    topic: String,
    links: Arc<Mutex<Vec<Link>>>,
    latched: Option<Latched>,
    _type: PhantomData<fn(T)>,
}

impl<T> std::fmt::Debug for Publisher<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Publisher").field("topic", &self.topic).finish()
    }
}

impl<T: Message> Publisher<T> {
    /// The topic.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// Sends `msg` to every connected subscriber without waiting (a full queue drops the
    /// message for that subscriber only).
    pub fn publish(&self, msg: &T) {
        let mut frame = vec![0; 4];
        msg.encode(&mut frame);
        let len = (frame.len() - 4) as u32;
        frame[..4].copy_from_slice(&len.to_le_bytes());
        let frame = Arc::new(frame);
        if let Some(latched) = &self.latched {
            *lock(latched) = Some(frame.clone());
        }
        lock(&self.links).retain(|link| {
            let mut q = lock(&link.0);
            if q.closed {
                return false;
            }
            q.frames.push_back(frame.clone());
            if q.frames.len() > QUEUE {
                q.frames.pop_front(); // a slow reader loses the oldest, never the newest
            }
            link.1.notify_all();
            true
        });
    }

    /// Subscribers connected now.
    pub fn subscribers(&self) -> usize {
        lock(&self.links).iter().filter(|l| !lock(&l.0).closed).count()
    }

    /// Waits until every queued message has been written to its socket, or `timeout`.
    /// Returns whether everything was written.
    pub fn flush(&self, timeout: Duration) -> bool {
        let end = Instant::now() + timeout;
        loop {
            let pending = lock(&self.links).iter().any(|l| {
                let q = lock(&l.0);
                !q.closed && (q.writing || !q.frames.is_empty())
            });
            if !pending {
                return true;
            }
            if Instant::now() >= end {
                return false;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

impl<T> Drop for Publisher<T> {
    fn drop(&mut self) {
        for link in lock(&self.links).iter() {
            lock(&link.0).closed = true;
            link.1.notify_all();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_round_trip() {
        let h =
            encode_header(&[("callerid", "/a"), ("md5sum", "*"), ("message_definition", "x=y\n")]);
        let fields = decode_header(&h[4..]);
        assert_eq!(fields.get("callerid").map(String::as_str), Some("/a"));
        assert_eq!(fields.get("message_definition").map(String::as_str), Some("x=y\n"));
        assert_eq!(u32::from_le_bytes([h[0], h[1], h[2], h[3]]) as usize, h.len() - 4);
        // Garbage does not panic.
        assert!(decode_header(&[255, 255, 255, 255, 1]).is_empty());
    }

    #[test]
    fn names_resolve_globally() {
        assert_eq!(resolve("scan"), "/scan");
        assert_eq!(resolve("/camera/depth"), "/camera/depth");
    }

    #[test]
    fn unreachable_master_is_a_clear_error() {
        // Port 9 (discard) on localhost is closed on any sane test machine.
        let e = Node::new("/t", "http://127.0.0.1:9/", "127.0.0.1").map(|_| ()).err();
        let text = e.map(|e| e.to_string()).unwrap_or_default();
        assert!(text.contains("127.0.0.1:9") && text.contains("roscore"), "{text}");
    }
}
