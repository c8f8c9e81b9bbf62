//! The wire to one drive: tokio-modbus's RTU master over a serial port or the simulator's TCP
//! endpoint (raw RTU frames), and for seed 003's sub-indexed requests, which no standard master
//! frames, a small RTU exchange of its own over the same kind of stream.

use std::fmt;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::{Instant, timeout, timeout_at};
use tokio_modbus::client::{Context, Reader, Writer, rtu};
use tokio_modbus::prelude::{ExceptionCode, ReadCode, Slave, SlaveContext};

use crate::dict::{Address, Map};

/// Where the bus is.
#[derive(Clone, Debug)]
pub enum Target {
    /// The simulator's TCP endpoint (`HOST:PORT`), raw RTU frames.
    Tcp(String),
    /// A serial port at a baud rate (8N1).
    Serial {
        /// The port (`/dev/ttyUSB0`).
        port: String,
        /// Bits a second.
        baud: u32,
    },
}

/// Why a request failed.
#[derive(Debug)]
pub enum Error {
    /// The drive refused it with an exception.
    Refused {
        /// The exception code.
        code: u8,
        /// What the code means in the drive's map.
        meaning: String,
    },
    /// No answer in time.
    Timeout,
    /// The port or the connection failed, or a reply was malformed.
    Link(String),
    /// The command itself is wrong (an unknown name, a value that does not fit).
    Usage(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Refused { code, meaning } => write!(f, "refused by the drive (exception {code:02X}: {meaning})"),
            Error::Timeout => write!(f, "no answer from the drive in time"),
            Error::Link(why) => write!(f, "link: {why}"),
            Error::Usage(why) => write!(f, "{why}"),
        }
    }
}

impl std::error::Error for Error {}

/// What an exception code means in `map`: the reasons the map answers with it.
pub fn meaning(map: Map, code: u8) -> String {
    use drive_core::maps::layout::Exceptions;
    let codes = map.layout().map_or(Exceptions::MODBUS, |l| l.exceptions);
    let reasons = [
        (codes.function, "the drive does not serve this function"),
        (codes.unknown, "no such register"),
        (codes.read_only, "read-only register"),
        (codes.write_only, "write-only register"),
        (codes.out_of_range, "value out of range"),
        (codes.byte_count, "malformed request"),
        (codes.split, "half of a 32-bit value written alone"),
        (codes.busy, "busy: the axis moves, a run or a save is under way"),
        (codes.disabled, "the power stage is off"),
        (codes.faulted, "a latched fault or stop must be cleared first"),
        (codes.not_now, "not in the present mode or state"),
        (codes.infeasible, "no trajectory within the limits"),
        (codes.unsupported, "the drive does not do this"),
    ];
    let mut out: Vec<&str> = Vec::new();
    for (e, why) in reasons {
        if e.code() == code && !out.contains(&why) {
            out.push(why);
        }
    }
    if out.is_empty() { format!("code {code} is not one of the {} map's", map.name()) } else { out.join("; or ") }
}

/// A byte stream to the bus.
trait Stream: AsyncRead + AsyncWrite + Unpin + Send {}
impl<T: AsyncRead + AsyncWrite + Unpin + Send> Stream for T {}

/// How requests are framed.
enum Io {
    /// tokio-modbus's RTU master.
    Modbus(Context),
    /// Our own exchange of raw frames (seed 003's sub-indexed requests).
    Raw(Box<dyn Stream>),
}

/// The identification strings of function 0x2B / 0x0E, objects 0-6.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Identity {
    /// Objects 0x00-0x06 (vendor, product code, revision, URL, product, model, application).
    pub objects: Vec<(u8, String)>,
}

impl Identity {
    /// Object `id`'s text, empty if absent.
    pub fn object(&self, id: u8) -> &str {
        self.objects.iter().find(|(i, _)| *i == id).map_or("", |(_, s)| s.as_str())
    }
}

/// A connection to the drive at one slave address, with the map it answers with.
pub struct Link {
    target: Target,
    slave: u8,
    io: Io,
    /// How long a request may take, answer included.
    pub limit: Duration,
    /// The map the drive answers with.
    pub map: Map,
}

async fn open(target: &Target) -> Result<Box<dyn Stream>, Error> {
    let (stream, baud): (Box<dyn Stream>, u32) = match target {
        Target::Tcp(at) => {
            let s = tokio::net::TcpStream::connect(at).await.map_err(|e| Error::Link(format!("{at}: {e}")))?;
            // A request must not wait for the ACK of an earlier piece (Nagle's algorithm).
            s.set_nodelay(true).map_err(|e| Error::Link(e.to_string()))?;
            (Box::new(s), 115_200)
        }
        Target::Serial { port, baud } => {
            let s = tokio_serial::SerialStream::open(&tokio_serial::new(port, *baud))
                .map_err(|e| Error::Link(format!("{port}: {e}")))?;
            (Box::new(s), *baud)
        }
    };
    Ok(Box::new(framed(stream, t15(baud))))
}

/// The stream with what it receives handed on in frames: bytes gathered until a silence of
/// `gap`. A UART (and QEMU's) delivers a reply byte by byte, and tokio-modbus 0.17's RTU
/// decoder loses its place on a device identification reply of which it has seen two bytes;
/// a whole frame it always takes.
fn framed(stream: Box<dyn Stream>, gap: Duration) -> tokio::io::DuplexStream {
    let (ours, theirs) = tokio::io::duplex(1024);
    let (mut line_rx, mut line_tx) = tokio::io::split(stream);
    let (mut pipe_rx, mut pipe_tx) = tokio::io::split(ours);
    // When the link is dropped the writer sees the pipe's end and tells the reader, so that the
    // port or the connection closes (a serial port opens once; the simulator serves one
    // connection at a time).
    let closed = std::sync::Arc::new(tokio::sync::Notify::new());
    let closing = std::sync::Arc::clone(&closed);
    tokio::spawn(async move {
        let mut buf = vec![0u8; 512];
        loop {
            let first = tokio::select! {
                r = line_rx.read(&mut buf) => r,
                () = closed.notified() => return,
            };
            let mut n = match first {
                Ok(0) | Err(_) => return,
                Ok(n) => n,
            };
            while n < buf.len() {
                match timeout(gap, line_rx.read(buf.get_mut(n..).unwrap_or_default())).await {
                    Ok(Ok(m)) if m > 0 => n += m,
                    _ => break,
                }
            }
            if pipe_tx.write_all(buf.get(..n).unwrap_or_default()).await.is_err() {
                return;
            }
        }
    });
    tokio::spawn(async move {
        let _ = tokio::io::copy(&mut pipe_rx, &mut line_tx).await;
        closing.notify_one();
    });
    theirs
}

/// The silence inside a frame's gathering: 1.5 characters of 11 bits at `baud`, at least 3 ms
/// (the host's scheduling and QEMU's pace).
fn t15(baud: u32) -> Duration {
    Duration::from_micros(16_500_000 / u64::from(baud.max(1200))).max(Duration::from_millis(3))
}

/// The silence that ends a frame at `baud`: 3.5 characters of 11 bits, at least 1.75 ms, with
/// a margin for the host's scheduling.
fn t35(baud: u32) -> Duration {
    let chars = Duration::from_micros(38_500_000 / u64::from(baud.max(1200)));
    chars.max(Duration::from_micros(1750)) + Duration::from_millis(2)
}

/// A tokio-modbus request's answer within `limit`, an exception in `map`'s words.
async fn answered<T>(
    limit: Duration,
    map: Map,
    request: impl std::future::Future<Output = tokio_modbus::Result<T>>,
) -> Result<T, Error> {
    let answer = timeout(limit, request).await.map_err(|_| Error::Timeout)?.map_err(|e| Error::Link(e.to_string()))?;
    answer.map_err(|e: ExceptionCode| {
        let code = u8::from(e);
        Error::Refused { code, meaning: meaning(map, code) }
    })
}

impl Link {
    /// Connects to slave `slave` on `target`, answering with `map` (or, if `None`, the map its
    /// identification names).
    pub async fn connect(target: Target, slave: u8, map: Option<Map>, limit: Duration) -> Result<Self, Error> {
        let stream = open(&target).await?;
        let io = Io::Modbus(rtu::attach_slave(stream, Slave(slave)));
        let mut link = Self { target, slave, io, limit, map: map.unwrap_or(Map::Native) };
        if map.is_none() {
            let id = link.identify().await?;
            link.map = Map::from_application_name(id.object(6));
        }
        if link.map.sub_indexed() {
            // Drop tokio-modbus's stream before opening ours: a serial port opens once.
            // Its framing tasks close the port once they see the pipe's end: retry a moment.
            link.io = Io::Raw(Box::new(tokio::io::empty()));
            let mut tries = 0;
            link.io = Io::Raw(loop {
                tokio::task::yield_now().await;
                match open(&link.target).await {
                    Ok(s) => break s,
                    Err(_) if tries < 25 => tries += 1,
                    Err(e) => return Err(e),
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            });
        }
        Ok(link)
    }

    /// The slave address.
    pub fn slave(&self) -> u8 {
        self.slave
    }

    /// Talks to slave `slave` from now on (tokio-modbus framing only).
    pub fn set_slave(&mut self, slave: u8) {
        self.slave = slave;
        if let Io::Modbus(ctx) = &mut self.io {
            ctx.set_slave(Slave(slave));
        }
    }

    /// The device identification (0x2B / 0x0E, regular category, from object 0).
    pub async fn identify(&mut self) -> Result<Identity, Error> {
        let limit = self.limit;
        let Io::Modbus(ctx) = &mut self.io else {
            return self.identify_raw().await;
        };
        let id = answered(limit, self.map, ctx.read_device_identification(ReadCode::Regular, 0)).await?;
        Ok(Identity {
            objects: id
                .device_id_objects
                .iter()
                .map(|o| (o.id, String::from_utf8_lossy(&o.value).into_owned()))
                .collect(),
        })
    }

    async fn identify_raw(&mut self) -> Result<Identity, Error> {
        let reply = self.exchange(&[0x2B, 0x0E, 0x02, 0x00]).await?;
        // 2B 0E code conformity more next count, then (id, len, bytes)...
        let mut objects = Vec::new();
        let mut rest = reply.get(7..).unwrap_or_default();
        while let [id, len, tail @ ..] = rest {
            let n = usize::from(*len);
            let Some(value) = tail.get(..n) else { break };
            objects.push((*id, String::from_utf8_lossy(value).into_owned()));
            rest = tail.get(n..).unwrap_or_default();
        }
        Ok(Identity { objects })
    }

    /// Reads `n` registers at `at`.
    pub async fn read(&mut self, at: Address, n: u16) -> Result<Vec<u16>, Error> {
        let (limit, map) = (self.limit, self.map);
        match (&mut self.io, at.sub) {
            (Io::Modbus(ctx), None) => answered(limit, map, ctx.read_holding_registers(at.register, n)).await,
            (_, sub) => {
                let [hi, lo] = at.register.to_be_bytes();
                let [nh, nl] = n.to_be_bytes();
                let reply = self.exchange(&[0x03, hi, lo, sub.unwrap_or(0), nh, nl]).await?;
                let data = reply.get(2..).unwrap_or_default();
                if reply.get(1).copied() != Some(2 * n as u8) || data.len() != 2 * usize::from(n) {
                    return Err(Error::Link(format!("a read of {n} registers answered with {reply:02X?}")));
                }
                Ok(data.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect())
            }
        }
    }

    /// Writes `values` from `at`: one register with 0x06, more with 0x10.
    pub async fn write(&mut self, at: Address, values: &[u16]) -> Result<(), Error> {
        let (limit, map) = (self.limit, self.map);
        match (&mut self.io, at.sub, values) {
            (Io::Modbus(ctx), None, [v]) => answered(limit, map, ctx.write_single_register(at.register, *v)).await,
            (Io::Modbus(ctx), None, _) => answered(limit, map, ctx.write_multiple_registers(at.register, values)).await,
            (_, sub, values) => {
                let [hi, lo] = at.register.to_be_bytes();
                let mut pdu = match values {
                    [_] => vec![0x06, hi, lo, sub.unwrap_or(0)],
                    _ => {
                        let [nh, nl] = (values.len() as u16).to_be_bytes();
                        vec![0x10, hi, lo, sub.unwrap_or(0), nh, nl, 2 * values.len() as u8]
                    }
                };
                for v in values {
                    pdu.extend_from_slice(&v.to_be_bytes());
                }
                self.exchange(&pdu).await.map(|_| ())
            }
        }
    }

    /// Sends `pdu` in a frame of our own and returns the reply's PDU (an exception as an error).
    async fn exchange(&mut self, pdu: &[u8]) -> Result<Vec<u8>, Error> {
        let (limit, slave, map) = (self.limit, self.slave, self.map);
        let baud = match &self.target {
            Target::Serial { baud, .. } => *baud,
            Target::Tcp(_) => 115_200,
        };
        // Sub-indexed requests only: a link to such a map is opened raw (`Link::connect`).
        let Io::Raw(stream) = &mut self.io else {
            return Err(Error::Usage("a sub-indexed address on a map without sub-indices".into()));
        };
        let mut frame = vec![slave];
        frame.extend_from_slice(pdu);
        let crc = drive_core::crc::crc16(&frame);
        frame.extend_from_slice(&crc.to_le_bytes());
        stream.write_all(&frame).await.map_err(|e| Error::Link(e.to_string()))?;
        // The reply is whole when the line falls silent for t3.5 after its first byte.
        let deadline = Instant::now() + limit;
        let mut reply = Vec::new();
        let mut buf = [0u8; 256];
        loop {
            let wait = if reply.is_empty() {
                timeout_at(deadline, stream.read(&mut buf)).await
            } else {
                timeout(t35(baud), stream.read(&mut buf)).await
            };
            match wait {
                Ok(Ok(0)) => return Err(Error::Link("connection closed".into())),
                Ok(Ok(n)) => reply.extend_from_slice(buf.get(..n).unwrap_or_default()),
                Ok(Err(e)) => return Err(Error::Link(e.to_string())),
                Err(_) if reply.is_empty() => return Err(Error::Timeout),
                Err(_) => break,
            }
        }
        if !drive_core::crc::frame_ok(&reply) || reply.first() != Some(&slave) {
            return Err(Error::Link(format!("a malformed reply {reply:02X?}")));
        }
        let body = reply.get(1..reply.len() - 2).unwrap_or_default().to_vec();
        match body.as_slice() {
            [f, code] if f & 0x80 != 0 => Err(Error::Refused { code: *code, meaning: meaning(map, *code) }),
            _ => Ok(body),
        }
    }
}
