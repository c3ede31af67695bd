//! The XML-RPC subset ROS 1 uses between nodes and the master: values, calls and responses
//! over HTTP/1.1, a blocking client and a small threaded server.

use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream, ToSocketAddrs};
use std::sync::Arc;
use std::time::Duration;
use thiserror::Error;

/// An XML-RPC value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// `<int>` / `<i4>`.
    Int(i32),
    /// `<boolean>`.
    Bool(bool),
    /// `<string>` (or an untyped value).
    Str(String),
    /// `<double>`.
    Double(f64),
    /// `<array>`.
    Array(Vec<Value>),
    /// `<struct>`.
    Struct(Vec<(String, Value)>),
}

impl Value {
    /// A string value.
    pub fn str(s: impl Into<String>) -> Self {
        Value::Str(s.into())
    }
    /// The string, if it is one.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }
    /// The integer, if it is one.
    pub fn as_int(&self) -> Option<i32> {
        match self {
            Value::Int(i) => Some(*i),
            _ => None,
        }
    }
    /// The elements, if it is an array.
    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Array(a) => Some(a),
            _ => None,
        }
    }

    fn write(&self, out: &mut String) {
        out.push_str("<value>");
        match self {
            Value::Int(i) => {
                let _ = write!(out, "<int>{i}</int>");
            }
            Value::Bool(b) => {
                let _ = write!(out, "<boolean>{}</boolean>", u8::from(*b));
            }
            Value::Str(s) => {
                out.push_str("<string>");
                escape(s, out);
                out.push_str("</string>");
            }
            Value::Double(d) => {
                let _ = write!(out, "<double>{d}</double>");
            }
            Value::Array(a) => {
                out.push_str("<array><data>");
                for v in a {
                    v.write(out);
                }
                out.push_str("</data></array>");
            }
            Value::Struct(members) => {
                out.push_str("<struct>");
                for (k, v) in members {
                    out.push_str("<member><name>");
                    escape(k, out);
                    out.push_str("</name>");
                    v.write(out);
                    out.push_str("</member>");
                }
                out.push_str("</struct>");
            }
        }
        out.push_str("</value>");
    }
}

fn escape(s: &str, out: &mut String) {
    for c in s.chars() {
        match c {
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            c => out.push(c),
        }
    }
}

/// An XML-RPC exchange that failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum XmlRpcError {
    /// The URL is not `http://host:port[/path]`.
    #[error("bad URL {0:?} (expected http://HOST:PORT/)")]
    Url(String),
    /// The peer could not be reached or the connection broke.
    #[error("{url}: {error}")]
    Io {
        /// The peer.
        url: String,
        /// Why.
        error: std::io::Error,
    },
    /// The bytes are not the XML-RPC expected.
    #[error("malformed XML-RPC: {0}")]
    Malformed(String),
    /// The peer answered with a fault.
    #[error("XML-RPC fault: {0}")]
    Fault(String),
}

// ---------------------------------------------------------------------------------------
// A minimal XML tree: enough for XML-RPC (elements, text, entities; attributes ignored).

#[derive(Debug)]
struct Element {
    name: String,
    children: Vec<Node>,
}

#[derive(Debug)]
enum Node {
    Element(Element),
    Text(String),
}

impl Element {
    fn elements(&self) -> impl Iterator<Item = &Element> {
        self.children.iter().filter_map(|n| match n {
            Node::Element(e) => Some(e),
            Node::Text(_) => None,
        })
    }
    fn child(&self, name: &str) -> Result<&Element, XmlRpcError> {
        self.elements()
            .find(|e| e.name == name)
            .ok_or_else(|| XmlRpcError::Malformed(format!("<{}> has no <{name}>", self.name)))
    }
    fn text(&self) -> String {
        self.children
            .iter()
            .filter_map(|n| match n {
                Node::Text(t) => Some(t.as_str()),
                Node::Element(_) => None,
            })
            .collect()
    }
}

/// Deepest element nesting accepted: ROS's values nest 6 deep; a bound keeps recursion (and
/// the tree's drop) far from the stack's end whatever a peer sends.
const MAX_DEPTH: usize = 32;

struct Parser<'a> {
    s: &'a str,
    pos: usize,
    depth: usize,
}

impl<'a> Parser<'a> {
    fn rest(&self) -> &'a str {
        &self.s[self.pos..]
    }
    fn err(&self, what: &str) -> XmlRpcError {
        XmlRpcError::Malformed(format!("{what} at byte {}", self.pos))
    }
    /// Skips the prolog, comments and whitespace before the root element.
    fn skip_misc(&mut self) -> Result<(), XmlRpcError> {
        loop {
            let r = self.rest();
            let trimmed = r.trim_start();
            self.pos += r.len() - trimmed.len();
            let end = if trimmed.starts_with("<?") {
                "?>"
            } else if trimmed.starts_with("<!--") {
                "-->"
            } else {
                return Ok(());
            };
            let at = trimmed.find(end).ok_or_else(|| self.err("unterminated prolog"))?;
            self.pos += at + end.len();
        }
    }
    fn element(&mut self) -> Result<Element, XmlRpcError> {
        if self.depth >= MAX_DEPTH {
            return Err(self.err(&format!("elements nested deeper than {MAX_DEPTH}")));
        }
        self.depth += 1;
        let el = self.element_body();
        self.depth -= 1;
        el
    }

    fn element_body(&mut self) -> Result<Element, XmlRpcError> {
        if !self.rest().starts_with('<') {
            return Err(self.err("expected an element"));
        }
        let close = self.rest().find('>').ok_or_else(|| self.err("unterminated tag"))?;
        let tag = &self.rest()[1..close];
        self.pos += close + 1;
        let self_closing = tag.ends_with('/');
        let tag = tag.trim_end_matches('/');
        let name = tag.split_whitespace().next().unwrap_or("").to_string();
        if name.is_empty() || name.starts_with('/') {
            return Err(self.err("expected an opening tag"));
        }
        let mut el = Element { name, children: Vec::new() };
        if self_closing {
            return Ok(el);
        }
        loop {
            let r = self.rest();
            if r.is_empty() {
                return Err(self.err(&format!("<{}> is not closed", el.name)));
            }
            if let Some(after) = r.strip_prefix("</") {
                let end = after.find('>').ok_or_else(|| self.err("unterminated tag"))?;
                if after[..end].trim() != el.name {
                    return Err(self.err(&format!("</{}> closes <{}>", &after[..end], el.name)));
                }
                self.pos += 2 + end + 1;
                return Ok(el);
            }
            if r.starts_with("<!--") {
                let end = r.find("-->").ok_or_else(|| self.err("unterminated comment"))?;
                self.pos += end + 3;
            } else if r.starts_with('<') {
                el.children.push(Node::Element(self.element()?));
            } else {
                let end = r.find('<').unwrap_or(r.len());
                el.children.push(Node::Text(unescape(&r[..end])));
                self.pos += end;
            }
        }
    }
}

fn unescape(s: &str) -> String {
    if !s.contains('&') {
        return s.to_string();
    }
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find('&') {
        out.push_str(&rest[..i]);
        rest = &rest[i..];
        let Some(end) = rest.find(';') else { break };
        let entity = &rest[1..end];
        let c = match entity {
            "lt" => Some('<'),
            "gt" => Some('>'),
            "amp" => Some('&'),
            "quot" => Some('"'),
            "apos" => Some('\''),
            e => e
                .strip_prefix("#x")
                .and_then(|h| u32::from_str_radix(h, 16).ok())
                .or_else(|| e.strip_prefix('#').and_then(|d| d.parse().ok()))
                .and_then(char::from_u32),
        };
        match c {
            Some(c) => {
                out.push(c);
                rest = &rest[end + 1..];
            }
            None => {
                out.push('&');
                rest = &rest[1..];
            }
        }
    }
    out.push_str(rest);
    out
}

fn parse_document(text: &str) -> Result<Element, XmlRpcError> {
    let mut p = Parser { s: text, pos: 0, depth: 0 };
    p.skip_misc()?;
    p.element()
}

fn parse_value(el: &Element) -> Result<Value, XmlRpcError> {
    let Some(typed) = el.elements().next() else {
        return Ok(Value::Str(el.text())); // untyped: a string
    };
    let text = typed.text();
    let bad =
        |what: &str| XmlRpcError::Malformed(format!("<{}>{what}</{}>", typed.name, typed.name));
    Ok(match typed.name.as_str() {
        "int" | "i4" => Value::Int(text.trim().parse().map_err(|_| bad(&text))?),
        "boolean" => Value::Bool(text.trim() == "1"),
        "string" => Value::Str(text),
        "double" => Value::Double(text.trim().parse().map_err(|_| bad(&text))?),
        "array" => Value::Array(
            typed.child("data")?.elements().map(parse_value).collect::<Result<_, _>>()?,
        ),
        "struct" => Value::Struct(
            typed
                .elements()
                .map(|m| Ok((m.child("name")?.text(), parse_value(m.child("value")?)?)))
                .collect::<Result<_, XmlRpcError>>()?,
        ),
        other => return Err(XmlRpcError::Malformed(format!("unsupported type <{other}>"))),
    })
}

fn params_of(root: &Element) -> Result<Vec<Value>, XmlRpcError> {
    match root.elements().find(|e| e.name == "params") {
        Some(params) => params.elements().map(|p| parse_value(p.child("value")?)).collect(),
        None => Ok(Vec::new()),
    }
}

/// A `methodCall` document.
pub fn encode_call(method: &str, params: &[Value]) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?><methodCall><methodName>");
    escape(method, &mut out);
    out.push_str("</methodName><params>");
    for p in params {
        out.push_str("<param>");
        p.write(&mut out);
        out.push_str("</param>");
    }
    out.push_str("</params></methodCall>");
    out
}

/// A `methodResponse` document carrying `value`.
pub fn encode_response(value: &Value) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?><methodResponse><params><param>");
    value.write(&mut out);
    out.push_str("</param></params></methodResponse>");
    out
}

/// Parses a `methodCall`: its method name and parameters.
///
/// # Errors
/// Not an XML-RPC call.
pub fn decode_call(text: &str) -> Result<(String, Vec<Value>), XmlRpcError> {
    let root = parse_document(text)?;
    if root.name != "methodCall" {
        return Err(XmlRpcError::Malformed(format!("<{}> is not <methodCall>", root.name)));
    }
    Ok((root.child("methodName")?.text().trim().to_string(), params_of(&root)?))
}

/// Parses a `methodResponse`: its (first) value, or the fault.
///
/// # Errors
/// Not an XML-RPC response, or a fault.
pub fn decode_response(text: &str) -> Result<Value, XmlRpcError> {
    let root = parse_document(text)?;
    if root.name != "methodResponse" {
        return Err(XmlRpcError::Malformed(format!("<{}> is not <methodResponse>", root.name)));
    }
    if let Ok(fault) = root.child("fault") {
        let v = parse_value(fault.child("value")?)?;
        return Err(XmlRpcError::Fault(format!("{v:?}")));
    }
    params_of(&root)?
        .into_iter()
        .next()
        .ok_or_else(|| XmlRpcError::Malformed("response without a value".into()))
}

// ---------------------------------------------------------------------------------------
// HTTP.

/// `host:port` of an `http://host:port[/path]` URL.
///
/// # Errors
/// Another scheme or no port.
pub fn host_port(url: &str) -> Result<(String, u16), XmlRpcError> {
    let bad = || XmlRpcError::Url(url.to_string());
    let rest = url.strip_prefix("http://").ok_or_else(bad)?;
    let authority = rest.split('/').next().unwrap_or("");
    let (host, port) = authority.rsplit_once(':').ok_or_else(bad)?;
    let port = port.parse().map_err(|_| bad())?;
    if host.is_empty() {
        return Err(bad());
    }
    Ok((host.to_string(), port))
}

/// Reads one HTTP message (request or response): the start line and the body.
fn read_http(stream: &mut BufReader<TcpStream>) -> std::io::Result<(String, String)> {
    // Bounded lines and header count: a peer cannot make us buffer without end.
    let mut read_line = |line: &mut String| (&mut *stream).take(8192).read_line(line);
    let mut start = String::new();
    read_line(&mut start)?;
    let mut length = None;
    for _ in 0..100 {
        let mut line = String::new();
        if read_line(&mut line)? == 0 {
            break;
        }
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':')
            && k.trim().eq_ignore_ascii_case("content-length")
        {
            length = v.trim().parse::<usize>().ok();
        }
    }
    let mut body = Vec::new();
    match length {
        Some(n) if n <= 64 << 20 => {
            body.resize(n, 0);
            stream.read_exact(&mut body)?;
        }
        Some(n) => {
            return Err(std::io::Error::other(format!("HTTP body of {n} bytes refused")));
        }
        None => {
            stream.take(64 << 20).read_to_end(&mut body)?;
        }
    }
    let body = String::from_utf8(body)
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "body is not UTF-8"))?;
    Ok((start.trim_end().to_string(), body))
}

/// Connects to `host:port`, trying every address it resolves to (`localhost` may give
/// `::1` first while the peer listens on 127.0.0.1 only).
///
/// # Errors
/// No address answers; the last error.
pub fn connect(host: &str, port: u16, timeout: Duration) -> std::io::Result<TcpStream> {
    let mut last = std::io::Error::new(std::io::ErrorKind::NotFound, "no address");
    for addr in (host, port).to_socket_addrs()? {
        match TcpStream::connect_timeout(&addr, timeout) {
            Ok(s) => return Ok(s),
            Err(e) => last = e,
        }
    }
    Err(last)
}

/// Calls `method` on the XML-RPC server at `url` and returns its value.
///
/// # Errors
/// The server cannot be reached, answers garbage, or answers with a fault.
pub fn call(url: &str, method: &str, params: &[Value]) -> Result<Value, XmlRpcError> {
    let (host, port) = host_port(url)?;
    let io = |error| XmlRpcError::Io { url: url.to_string(), error };
    let stream = connect(&host, port, Duration::from_secs(3)).map_err(io)?;
    stream.set_read_timeout(Some(Duration::from_secs(10))).map_err(io)?;
    stream.set_nodelay(true).map_err(io)?;
    let body = encode_call(method, params);
    let request = format!(
        "POST /RPC2 HTTP/1.1\r\nHost: {host}:{port}\r\nUser-Agent: mdrlat\r\n\
         Content-Type: text/xml\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    (&stream).write_all(request.as_bytes()).map_err(io)?;
    let (status, body) = read_http(&mut BufReader::new(stream)).map_err(io)?;
    if !status.contains(" 200") {
        return Err(XmlRpcError::Malformed(format!("HTTP status {status:?}")));
    }
    decode_response(&body)
}

/// Handles one XML-RPC call: method name and parameters to the response value.
pub type Handler = Arc<dyn Fn(&str, &[Value]) -> Value + Send + Sync>;

/// Serves XML-RPC on `listener` until the process ends (one thread per connection).
pub fn serve(listener: TcpListener, handler: Handler) {
    std::thread::Builder::new()
        .name("xmlrpc".into())
        .spawn(move || {
            for stream in listener.incoming() {
                let Ok(stream) = stream else {
                    std::thread::sleep(Duration::from_millis(100)); // e.g. out of descriptors
                    continue;
                };
                let handler = handler.clone();
                let _ = std::thread::Builder::new()
                    .name("xmlrpc-conn".into())
                    .spawn(move || answer(stream, &handler));
            }
        })
        .ok();
}

fn answer(stream: TcpStream, handler: &Handler) {
    let _ = stream.set_read_timeout(Some(Duration::from_secs(10)));
    let _ = stream.set_nodelay(true);
    let Ok(clone) = stream.try_clone() else { return };
    let mut reader = BufReader::new(clone);
    let Ok((_, body)) = read_http(&mut reader) else { return };
    let response = match decode_call(&body) {
        Ok((method, params)) => encode_response(&handler(&method, &params)),
        Err(e) => encode_response(&Value::Array(vec![
            Value::Int(-1),
            Value::str(e.to_string()),
            Value::Int(0),
        ])),
    };
    let http = format!(
        "HTTP/1.1 200 OK\r\nContent-Type: text/xml\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n{response}",
        response.len()
    );
    let _ = (&stream).write_all(http.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip() {
        let v = Value::Array(vec![
            Value::Int(1),
            Value::str("a <b> & c"),
            Value::Array(vec![Value::str("TCPROS"), Value::str("host"), Value::Int(4242)]),
            Value::Bool(true),
            Value::Double(0.25),
            Value::Struct(vec![("k".into(), Value::Int(-3))]),
            Value::Array(vec![]),
        ]);
        assert_eq!(decode_response(&encode_response(&v)).ok(), Some(v.clone()));
        let (m, p) = decode_call(&encode_call("requestTopic", std::slice::from_ref(&v)))
            .ok()
            .unwrap_or_default();
        assert_eq!((m.as_str(), p), ("requestTopic", vec![v]));
    }

    #[test]
    fn parses_what_python_writes() {
        // xmlrpc.client's style: newlines, untyped strings, <i4>, empty <data/>, entities.
        let text = "<?xml version='1.0'?>\n<methodResponse>\n<params>\n<param>\n<value><array><data>\n\
            <value><i4>1</i4></value>\n<value>Registered [/x] &amp; ok</value>\n\
            <value><array><data>\n</data></array></value>\n<value><array><data/></array></value>\n\
            </data></array></value>\n</param>\n</params>\n</methodResponse>\n";
        let v = decode_response(text).ok();
        assert_eq!(
            v,
            Some(Value::Array(vec![
                Value::Int(1),
                Value::str("Registered [/x] & ok"),
                Value::Array(vec![]),
                Value::Array(vec![]),
            ]))
        );
        let fault = "<?xml version='1.0'?><methodResponse><fault><value><struct><member>\
            <name>faultCode</name><value><int>1</int></value></member></struct></value></fault>\
            </methodResponse>";
        assert!(matches!(decode_response(fault), Err(XmlRpcError::Fault(_))));
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let deep = format!("{}{}", "<a>".repeat(100_000), "</a>".repeat(100_000));
        let e = decode_response(&deep).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("nested deeper than 32"), "{e}");
        let deep_value = format!(
            "<methodResponse><params><param>{}{}</param></params></methodResponse>",
            "<value><array><data>".repeat(20),
            "</data></array></value>".repeat(20)
        );
        assert!(decode_response(&deep_value).is_err());
    }

    #[test]
    fn garbage_is_an_error() {
        for text in ["", "<", "<a>", "<methodResponse><params>", "<a></b>", "plain"] {
            assert!(decode_response(text).is_err(), "{text:?}");
        }
        assert!(host_port("http://h:11311/").is_ok());
        for url in ["h:1", "http://h/", "http://:1/", "https://h:1/", "http://h:x/"] {
            assert!(host_port(url).is_err(), "{url}");
        }
    }
}
